"""Leg kinematics for the estimators and the slip detector: the robot package's chain
(:mod:`taslel_bench.robot.leg_chain`) of the robot the estimators were trained on, and the contact forces the
joint torques imply, all four legs at once.

Joint vectors in the core order (legs FL, FR, RL, RR; hip, thigh, calf); angles [rad]; positions [m] relative
to the trunk origin in trunk axes; torques [N·m]; forces [N].
"""

from __future__ import annotations

import numpy as np

from taslel_bench import api
from taslel_bench.api import RobotDescription, leg_chain

# the shipped estimator checkpoints were trained on A1 data: the estimators' kinematics default to the A1's chain
TRAINED_ROBOT = "a1"


def chain_table(robot: RobotDescription | None = None) -> np.ndarray:
    """(4, ``leg_chain.N_COLUMNS``) the chain table of ``robot`` (None: :data:`TRAINED_ROBOT`)."""
    return leg_chain.chain_table(robot if robot is not None else api.load_robot(TRAINED_ROBOT))


def feet_and_jacobians(q_joints: np.ndarray, robot: RobotDescription | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(p (4, 3) [m], J (4, 3, 3) [m/rad]) for the 12 joint angles: each foot-sphere centre relative to the
    trunk origin and d p / d q_leg, both in trunk axes (``J[i] @ qd_leg`` = foot i's velocity relative to the
    trunk [m/s]); :func:`taslel_bench.robot.leg_chain.feet_and_jacobians` on ``robot``'s chain (None: the A1)."""
    return leg_chain.feet_and_jacobians(chain_table(robot), q_joints)


def foot_forces_from_torques(jac: np.ndarray, tau_joints: np.ndarray) -> np.ndarray:
    """(4, 3) [N] the ground reaction on each foot, trunk axes, that the joint torques ``tau_joints`` [N·m]
    (12,) balance in a quasi-static leg (tau_leg = -J' f; the leg's own weight and inertia neglected: the calf
    and thigh are ~1.2 kg of the 12 kg robot). A swing leg's value is meaningless."""
    tau = np.asarray(tau_joints, float).reshape(4, 3)
    return -np.linalg.solve(np.transpose(jac, (0, 2, 1)), tau[..., None])[..., 0]
