"""Policy training: the batched environment, one PPO iteration, the exported ONNX against the torch actor."""

from __future__ import annotations

import numpy as np
import onnxruntime as ort
import pytest
import torch

from taslel_bench.learn.config import TrainingConfig
from taslel_bench.learn.env import WalkingEnv
from taslel_bench.learn.export import deterministic_actions, export_onnx, load_torch_actor
from taslel_bench.learn.train import main as train_main


def _small(**changes) -> TrainingConfig:
    cfg = TrainingConfig(n_envs=8, nthread=1, iterations=1, name="test_walk")
    cfg.ppo.num_steps_per_env = 4
    for key, value in changes.items():
        setattr(cfg, key, value)
    return cfg


def test_environment_steps_observes_and_resets():
    env = WalkingEnv(_small())
    obs = env.get_observations()["policy"]
    assert obs.shape == (8, env.contract.obs_size) and obs.dtype == torch.float32
    assert env.decimation == 4 and env.dt == pytest.approx(0.02)
    friction = env.geom_friction[:, env._floor, 0]
    assert ((friction >= 0.6) & (friction <= 1.25)).all() and np.unique(friction).size == 8
    for _ in range(5):
        obs, reward, done, extras = env.step(torch.zeros(8, 12))
    assert torch.isfinite(reward).all() and not done.any()
    assert set(extras) == {"time_outs", "log"}
    # a robot thrown on its back ends its episode as a fall, and starts a fresh one
    env.qpos[0, env._quat] = (0.0, 1.0, 0.0, 0.0)
    obs, reward, done, extras = env.step(torch.zeros(8, 12))
    assert done[0] and not extras["time_outs"][0]
    assert env.episode_length_buf[0] == 0 and env.qpos[0, env._quat][0] == pytest.approx(1.0)


def test_observations_are_the_contracts(tmp_path):
    """The training's observation vector is the one the benchmark's controller builds (the same builder), here
    checked term by term on a standing robot without noise."""
    env = WalkingEnv(_small(noise={}))
    env.step(torch.zeros(8, 12))
    obs = env.get_observations()["policy"].numpy()
    layout = dict(env.contract.layout())
    v, w, g = env._trunk_state()
    np.testing.assert_allclose(obs[:, layout["base_lin_vel"]], 2.0 * v, atol=1e-5)
    np.testing.assert_allclose(obs[:, layout["projected_gravity"]], g, atol=1e-6)
    q = env.qpos[:, env._jq] - np.asarray(env.contract.default_pose)
    np.testing.assert_allclose(obs[:, layout["joint_pos"]], q, atol=1e-6)


def test_one_iteration_trains_exports_and_the_onnx_matches_torch(tmp_path):
    out, conf = tmp_path / "out", tmp_path / "conf"
    code = train_main(["--robot", "a1", "--name", "test_walk", "--iterations", "1", "--out", str(out), "--conf-dir",
                       str(conf), "--set", "n_envs=8", "--set", "nthread=1", "--set", "ppo.num_steps_per_env=4"])
    assert code == 0
    for name in ("policy.onnx", "policy_torch.pt", "training.yaml", "learning_curve.csv", "learning_curve.png",
                 "README.md"):
        assert (out / name).is_file(), name
    assert (conf / "test_walk.yaml").is_file()
    actor = load_torch_actor(out, 48)
    obs = torch.randn(256, 48) * 2.0
    reference = deterministic_actions(actor, obs).numpy()
    onnx = ort.InferenceSession(str(out / "policy.onnx")).run(None, {"obs": obs.numpy()})[0]
    assert np.abs(onnx - reference).max() <= 1e-5


def test_export_of_a_fresh_actor_agrees(tmp_path):
    from taslel_bench.learn.export import actor_model

    actor = actor_model(TrainingConfig().ppo, 48).eval()
    export_onnx(actor, tmp_path / "a.onnx")
    obs = torch.randn(64, 48)
    onnx = ort.InferenceSession(str(tmp_path / "a.onnx")).run(None, {"obs": obs.numpy()})[0]
    assert np.abs(onnx - deterministic_actions(actor, obs).numpy()).max() <= 1e-5
