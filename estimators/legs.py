"""Leg kinematics of the A1 in numpy for the slip detector: foot positions, foot Jacobians and the contact
forces the joint torques imply, all four legs at once.

Chain per leg (as :mod:`taslel_bench.robot.kinematics` and :func:`estimators.models.foot_kinematics`): hip
roll ``q1`` about x, lateral offset ``side * HIP_OFFSET_Y_M``, thigh pitch ``q2`` about y, thigh
``THIGH_LENGTH_M`` along -z, calf pitch ``q3`` about y, calf ``CALF_LENGTH_M`` along -z to the foot-sphere
centre. Joint vectors in the core order (legs FL, FR, RL, RR; hip, thigh, calf); angles [rad]; positions
[m] relative to the trunk origin in trunk axes.
"""

from __future__ import annotations

import numpy as np

from taslel_bench import api
from taslel_bench.interfaces import quad

# the shipped estimators were trained on the A1: its chain, from its description (conf/robot/a1.yaml + URDF)
_A1 = api.load_robot("a1")
L1, L2, L3 = abs(_A1.legs[0].lateral_m), _A1.legs[0].thigh_length_m, _A1.legs[0].calf_length_m
HIPS_IN_TRUNK = _A1.hip_positions_in_trunk  # (4, 3) [m]
SIDES = np.asarray(quad.LEG_SIDE, float)  # (4,) +1 left, -1 right


def feet_and_jacobians(q_joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p (4, 3) [m], J (4, 3, 3) [m/rad]) for the 12 joint angles: each foot-sphere centre relative to the
    trunk origin and d p / d q_leg, both in trunk axes (``J[i] @ qd_leg`` = foot i's velocity relative to the
    trunk [m/s])."""
    q = np.asarray(q_joints, float).reshape(4, 3)
    q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2]
    s1, c1, s2, c2 = np.sin(q1), np.cos(q1), np.sin(q2), np.cos(q2)
    s23, c23 = np.sin(q2 + q3), np.cos(q2 + q3)
    y0 = SIDES * L1
    px = -L2 * s2 - L3 * s23
    zp = -L2 * c2 - L3 * c23
    py = c1 * y0 - s1 * zp
    pz = s1 * y0 + c1 * zp
    p = np.stack([px, py, pz], -1) + HIPS_IN_TRUNK
    jac = np.zeros((4, 3, 3))
    # d/dq1: rotation about x of (y0, zp)
    jac[:, 1, 0], jac[:, 2, 0] = -pz, py
    # d/dq2 and d/dq3 in the thigh plane (x, zp), then rotated by q1
    dx2, dzp2 = zp, -px
    dx3, dzp3 = -L3 * c23, L3 * s23
    jac[:, 0, 1], jac[:, 1, 1], jac[:, 2, 1] = dx2, -s1 * dzp2, c1 * dzp2
    jac[:, 0, 2], jac[:, 1, 2], jac[:, 2, 2] = dx3, -s1 * dzp3, c1 * dzp3
    return p, jac


def foot_forces_from_torques(jac: np.ndarray, tau_joints: np.ndarray) -> np.ndarray:
    """(4, 3) [N] the ground reaction on each foot, trunk axes, that the joint torques ``tau_joints`` [N·m]
    (12,) balance in a quasi-static leg (tau_leg = -J' f; the leg's own weight and inertia neglected: the calf
    and thigh are ~1.2 kg of the 12 kg robot). A swing leg's value is meaningless."""
    tau = np.asarray(tau_joints, float).reshape(4, 3)
    return -np.linalg.solve(np.transpose(jac, (0, 2, 1)), tau[..., None])[..., 0]
