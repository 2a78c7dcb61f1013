"""The roll-pitch-pitch leg chain of :mod:`taslel_bench.robot.kinematics`, written once for numpy, torch and Numba.

A robot's four chains are one **chain table** (:func:`chain_table`): a (4, ``N_COLUMNS``) float64 array, one row
per leg (core order), columns named by the constants below and read from the description's
:class:`taslel_bench.robot.description.LegGeometry`. The chain's algebra (:func:`leg_pose`, :func:`foot_jacobian`,
:func:`foot_velocity`, :func:`knee_in_hip`) is arithmetic on ``p[COLUMN]`` plus the ``sin`` and ``cos`` it is
given, so the same text runs on plain floats (``p`` a row, :mod:`math`), on all legs at once (``p`` the table's
columns, numpy or torch arrays) and inside compiled kernels (``p`` a row, ``np.sin``;
:func:`feet_and_jacobians_into`).

The chain (hip frame: trunk axes, origin at the hip (abduction) joint), with joint angles mapped to the chain's
angles ``a1 = s1 q1``, ``a2 = s2 q2 + b2``, ``a23 = a2 + s3 q3 + b3 - b2`` (:func:`chain_angles`; s: joint axis
signs, b: the links' angles from straight down at the zero configuration)::

    knee (leg plane) = (THIGH_X - L2 sin a2, THIGH_Z - L2 cos a2)          (x, z') before the roll
    foot (leg plane) = knee - L3 (sin a23, cos a23)
    point (hip frame) = (x, cos a1 LATERAL - sin a1 z', sin a1 LATERAL + cos a1 z')

Units: angles [rad], rates [rad/s], positions [m], Jacobians [m/rad], velocities [m/s]. Joint vectors in the
core order (legs FL, FR, RL, RR; hip, thigh, calf).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
from numba.extending import register_jitable

from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import LegGeometry, RobotDescription
from taslel_bench.util.jit import kernel

# columns of the chain table
HIP_X, HIP_Y, HIP_Z = 0, 1, 2  # [m] hip (abduction) joint in the trunk frame
THIGH_X, THIGH_Z = 3, 4  # [m] hip joint -> thigh joint along x and z (trunk axes, zero configuration)
LATERAL = 5  # [m] the foot's distance from the hip's roll plane (+ left)
THIGH_LENGTH, CALF_LENGTH = 6, 7  # [m] thigh joint -> calf joint, calf joint -> foot centre, in the leg plane
THIGH_ANGLE, CALF_ANGLE = 8, 9  # [rad] thigh's angle from straight down; calf's angle relative to the thigh
AXIS_HIP, AXIS_THIGH, AXIS_CALF = 10, 11, 12  # [-] +-1: each joint turns about +-x, +-y, +-y
N_COLUMNS = 13


def chain_row(g: LegGeometry) -> tuple[float, ...]:
    """One leg's row of the chain table (module doc; column constants)."""
    return (*g.hip_in_trunk_m, g.hip_to_thigh_m[0], g.hip_to_thigh_m[2], g.lateral_m, g.thigh_length_m,
            g.calf_length_m, g.thigh_angle_rad, g.calf_angle_rad - g.thigh_angle_rad, *g.axis_signs)


@lru_cache(maxsize=16)
def chain_table(robot: RobotDescription) -> np.ndarray:
    """(4, ``N_COLUMNS``) float64, read-only: the robot's four leg chains, core leg order."""
    table = np.array([chain_row(g) for g in robot.legs], dtype=float)
    table.setflags(write=False)
    return table


# ------------------------------------------------------------------ the chain's algebra (one text for every backend)


@register_jitable
def chain_angles(p: Any, q1: Any, q2: Any, q3: Any) -> tuple[Any, Any, Any]:
    """(a1, a2, a23) [rad]: the roll, the thigh's pitch and the calf's pitch (thigh + calf) of the chain for the
    joint angles (q1, q2, q3) [rad] (axis signs applied, the links' zero-configuration angles added)."""
    a2 = p[AXIS_THIGH] * q2 + p[THIGH_ANGLE]
    return p[AXIS_HIP] * q1, a2, a2 + (p[AXIS_CALF] * q3 + p[CALF_ANGLE])


@register_jitable
def _knee_in_leg_plane(p: Any, a2: Any, sin: Any, cos: Any) -> tuple[Any, Any]:
    """(x, z') [m] of the calf joint relative to the hip joint in the leg plane (before the roll)."""
    return p[THIGH_X] - p[THIGH_LENGTH] * sin(a2), p[THIGH_Z] - p[THIGH_LENGTH] * cos(a2)


@register_jitable
def _rolled(p: Any, sin_a1: Any, cos_a1: Any, z_plane: Any) -> tuple[Any, Any]:
    """(y, z) [m] in the hip frame of the leg-plane point (``LATERAL``, ``z_plane``) after the roll a1."""
    return cos_a1 * p[LATERAL] - sin_a1 * z_plane, sin_a1 * p[LATERAL] + cos_a1 * z_plane


@register_jitable
def leg_pose(p: Any, q1: Any, q2: Any, q3: Any, sin: Any, cos: Any) -> tuple[Any, ...]:
    """The chain at joint angles (q1, q2, q3) [rad]: ``(x, y, z, z', sin a1, cos a1, sin a23, cos a23)``, the
    foot-sphere centre [m] in the hip frame (trunk axes, origin at the hip joint), its z' [m] in the leg plane
    before the roll, and the sines and cosines :func:`foot_jacobian` and :func:`foot_velocity` need."""
    a1, a2, a23 = chain_angles(p, q1, q2, q3)
    sin_a1, cos_a1, sin_a23, cos_a23 = sin(a1), cos(a1), sin(a23), cos(a23)
    x_knee, z_knee = _knee_in_leg_plane(p, a2, sin, cos)
    x, z_plane = x_knee - p[CALF_LENGTH] * sin_a23, z_knee - p[CALF_LENGTH] * cos_a23
    y, z = _rolled(p, sin_a1, cos_a1, z_plane)
    return x, y, z, z_plane, sin_a1, cos_a1, sin_a23, cos_a23


@register_jitable
def _plane_partials(p: Any, pose: tuple[Any, ...]) -> tuple[Any, Any, Any, Any]:
    """(dx/dq2, dz'/dq2, dx/dq3, dz'/dq3) [m/rad] of the foot in the leg plane (before the roll) at ``pose``."""
    x, _, _, z_plane, _, _, sin_a23, cos_a23 = pose
    s2, s3, l3 = p[AXIS_THIGH], p[AXIS_CALF], p[CALF_LENGTH]
    return s2 * (z_plane - p[THIGH_Z]), -s2 * (x - p[THIGH_X]), -s3 * l3 * cos_a23, s3 * l3 * sin_a23


@register_jitable
def foot_jacobian(p: Any, pose: tuple[Any, ...]) -> tuple[tuple[Any, Any, Any], ...]:
    """J = d p_foot / d (q1, q2, q3) [m/rad] at the :func:`leg_pose` ``pose``, trunk axes, as three rows (x, y, z)
    of three entries; J's (x, q1) entry is 0.0 (the roll does not move the foot along x)."""
    _, y, z, _, sin_a1, cos_a1, _, _ = pose
    x_q2, z_q2, x_q3, z_q3 = _plane_partials(p, pose)
    k = p[AXIS_HIP]
    return (0.0, x_q2, x_q3), (-k * z, -sin_a1 * z_q2, -sin_a1 * z_q3), (k * y, cos_a1 * z_q2, cos_a1 * z_q3)


@register_jitable
def foot_velocity(p: Any, pose: tuple[Any, ...], dq1: Any, dq2: Any, dq3: Any) -> tuple[Any, Any, Any]:
    """(vx, vy, vz) [m/s] = J(q) dq: the foot-sphere centre's velocity relative to the trunk, trunk axes, for the
    joint rates (dq1, dq2, dq3) [rad/s] at the :func:`leg_pose` ``pose`` (in the leg plane, then rolled)."""
    _, y, z, _, sin_a1, cos_a1, _, _ = pose
    x_q2, z_q2, x_q3, z_q3 = _plane_partials(p, pose)
    v_plane = z_q2 * dq2 + z_q3 * dq3
    k = p[AXIS_HIP]
    return x_q2 * dq2 + x_q3 * dq3, -k * z * dq1 - sin_a1 * v_plane, k * y * dq1 + cos_a1 * v_plane


@register_jitable
def knee_in_hip(p: Any, q1: Any, q2: Any, q3: Any, sin: Any, cos: Any) -> tuple[Any, Any, Any]:
    """(x, y, z) [m] of the calf (knee) joint in the hip frame at joint angles (q1, q2, q3) [rad], with the foot's
    lateral offset (``LATERAL``): the knee above the foot, the shin capsule's end in the foothold checks."""
    a1, a2, _ = chain_angles(p, q1, q2, q3)
    x, z_plane = _knee_in_leg_plane(p, a2, sin, cos)
    y, z = _rolled(p, sin(a1), cos(a1), z_plane)
    return x, y, z


# ----------------------------------------------------------------------------- all four legs at once (numpy, torch)


def _legs(q_joints: Any) -> tuple[Any, Any, Any]:
    """(q1, q2, q3), each (..., 4), of joint vectors (..., 12) in the core order."""
    q = q_joints.reshape(tuple(q_joints.shape[:-1]) + (quad.N_LEGS, 3))
    return q[..., 0], q[..., 1], q[..., 2]


def _in_trunk(columns: Any, pose: tuple[Any, ...], xp: Any) -> Any:
    """(..., 4, 3) [m] foot-sphere centres relative to the trunk origin, trunk axes, from the legs' poses."""
    return xp.stack([pose[0] + columns[HIP_X], pose[1] + columns[HIP_Y], pose[2] + columns[HIP_Z]], -1)


def feet_and_velocities(columns: Any, q_joints: Any, qd_joints: Any, xp: Any = np) -> tuple[Any, Any]:
    """(p (..., 4, 3) [m], v (..., 4, 3) [m/s]): the foot-sphere centres relative to the trunk origin and their
    velocities relative to the trunk (J_leg(q) qd), both in trunk axes, for joint angles ``q_joints`` [rad] and
    rates ``qd_joints`` [rad/s] (..., 12). ``columns``: the chain table's columns (``N_COLUMNS``, 4) as arrays of
    the array module ``xp`` (numpy, or torch in the estimators' features)."""
    q1, q2, q3 = _legs(q_joints)
    dq1, dq2, dq3 = _legs(qd_joints)
    pose = leg_pose(columns, q1, q2, q3, xp.sin, xp.cos)
    return _in_trunk(columns, pose, xp), xp.stack(foot_velocity(columns, pose, dq1, dq2, dq3), -1)


def feet_in_trunk(table: np.ndarray, q_joints: np.ndarray) -> np.ndarray:
    """(..., 4, 3) [m] foot-sphere centres relative to the trunk origin, trunk axes, for joint angles (..., 12)
    [rad]; ``table``: :func:`chain_table`."""
    columns = table.T
    return _in_trunk(columns, leg_pose(columns, *_legs(np.asarray(q_joints, float)), np.sin, np.cos), np)


def feet_and_jacobians(table: np.ndarray, q_joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p (..., 4, 3) [m], J (..., 4, 3, 3) [m/rad]) for joint angles (..., 12) [rad]: each foot-sphere centre
    relative to the trunk origin and d p / d q_leg, both in trunk axes (``J[..., i, :, :] @ qd_leg`` = foot i's
    velocity relative to the trunk [m/s]); ``table``: :func:`chain_table`."""
    columns = table.T
    q1, q2, q3 = _legs(np.asarray(q_joints, float))
    pose = leg_pose(columns, q1, q2, q3, np.sin, np.cos)
    jac = np.empty(q1.shape + (3, 3))
    for r, row in enumerate(foot_jacobian(columns, pose)):
        for c, entry in enumerate(row):
            jac[..., r, c] = entry
    return _in_trunk(columns, pose, np), jac


# ------------------------------------------------------------------------------------ compiled (control tick)


@kernel
def feet_and_jacobians_into(table, q_joints, p_out, jac_out):  # pragma: no cover - compiled
    """:func:`feet_and_jacobians` for one joint vector (12,) [rad], compiled, into preallocated ``p_out`` (4, 3)
    [m] and ``jac_out`` (4, 3, 3) [m/rad] (trunk axes)."""
    for i in range(4):
        row = table[i]
        pose = leg_pose(row, q_joints[3 * i], q_joints[3 * i + 1], q_joints[3 * i + 2], np.sin, np.cos)
        p_out[i, 0], p_out[i, 1], p_out[i, 2] = pose[0] + row[HIP_X], pose[1] + row[HIP_Y], pose[2] + row[HIP_Z]
        jac_x, jac_y, jac_z = foot_jacobian(row, pose)
        for c in range(3):
            jac_out[i, 0, c], jac_out[i, 1, c], jac_out[i, 2, c] = jac_x[c], jac_y[c], jac_z[c]
