"""Identification of the controller's model from recorded runs, with ``mujoco.sysid`` (MuJoCo's extra
``mujoco[sysid]``: rollout least-squares with confidence intervals and an HTML report).

``python -m taslel_bench.identify RUN_FOLDER... --out FILE`` fits the five quantities the plant perturbations and
the ``model`` group share (:mod:`taslel_bench.plant.perturbation`, :mod:`taslel_bench.robot.model_options`):

* ``joint_damping`` [N·m·s/rad], ``armature`` [kg·m²], ``joint_frictionloss`` [N·m] -- added to the URDF's leg
  joints (one value for the 12 joints, or 12 with ``--per-joint``);
* ``trunk_mass_scale`` [-] -- the URDF trunk link's mass and inertia about its CoM, scaled together;
* ``trunk_com_shift_m`` [m] -- the trunk link's CoM shift, trunk frame.

The model fitted is the run's MuJoCo plant with these five at the URDF's values (:mod:`.runs`); a candidate is
that spec edited by :meth:`taslel_bench.plant.perturbation.PlantPerturbation.apply`, the one implementation of the
plant perturbations, so a fitted value is the same physical quantity as ``scenario.<field>`` and, through the
equivalence checked in ``tests/test_model_options.py``, as ``model.<field>``. Data: each run's ``steps.parquet``
after the stand, cut into short windows; each window is replayed from its recorded state under its recorded
torques (:mod:`.fit`) and the velocities are compared with the recorded ones. The result is a ``model``
override file (``model=identified model.from=<file>``) and its fit report beside it (:mod:`.output`).
"""

from __future__ import annotations

from taslel_bench.identify.fit import FitResult, identify
from taslel_bench.identify.runs import RunData, load_run

__all__ = ["FitResult", "RunData", "identify", "load_run"]
