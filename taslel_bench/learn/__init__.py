"""Training learned walking policies on the harness's own plant (PPO with ``rsl-rl-lib``, rollouts batched through
``mujoco.batch``): :mod:`.env` (the environments), :mod:`.config` (the training settings), :mod:`.train` (the
command, ``python -m taslel_bench.learn.train``). Needs the ``learn`` extra (torch, rsl-rl-lib, onnx,
onnxruntime)."""
