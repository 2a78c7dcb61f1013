"""Analytic leg kinematics of the A1 in the hip frame (trunk axes, origin at the hip joint).

Chain per leg: hip roll ``q1`` about x, lateral offset ``side * HIP_OFFSET_Y_M``, thigh pitch ``q2`` about
y, thigh ``THIGH_LENGTH_M`` along -z, calf pitch ``q3`` about y, calf ``CALF_LENGTH_M`` along -z to the
foot-sphere centre. Angles [rad], positions [m].
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.robot import a1

L1, L2, L3 = a1.HIP_OFFSET_Y_M, a1.THIGH_LENGTH_M, a1.CALF_LENGTH_M


def leg_fk(q_leg: np.ndarray, side: float) -> np.ndarray:
    """Foot-sphere centre [m] in the hip frame for joint angles ``(q1, q2, q3)``."""
    q1, q2, q3 = q_leg
    x = -L2 * np.sin(q2) - L3 * np.sin(q2 + q3)
    zp = -L2 * np.cos(q2) - L3 * np.cos(q2 + q3)
    y0 = side * L1
    c, s = np.cos(q1), np.sin(q1)
    return np.array([x, c * y0 - s * zp, s * y0 + c * zp])


def leg_ik(foot_in_hip: np.ndarray, side: float) -> np.ndarray:
    """Joint angles (hip, thigh, calf) [rad] putting the foot centre at ``foot_in_hip`` (knee backwards,
    calf angle negative as on the A1). Unreachable targets are clipped to the workspace boundary."""
    return np.array(_leg_ik_scalar(float(foot_in_hip[0]), float(foot_in_hip[1]), float(foot_in_hip[2]), side))


def _leg_ik_scalar(x: float, y: float, z: float, side: float) -> tuple[float, float, float]:
    # Scalar math: ~20x cheaper than numpy on 3-vectors, and this runs several times per control tick.
    y0 = side * L1
    zp = -math.sqrt(max(y * y + z * z - y0 * y0, 1e-9))
    q1 = math.atan2(z, y) - math.atan2(zp, y0)
    q1 = (q1 + math.pi) % (2 * math.pi) - math.pi
    c3 = min(1.0, max(-1.0, (x * x + zp * zp - L2 * L2 - L3 * L3) / (2 * L2 * L3)))
    q3 = -math.acos(c3)
    q2 = math.atan2(-x, -zp) - math.atan2(L3 * math.sin(q3), L2 + L3 * math.cos(q3))
    return q1, q2, q3


def leg_knee_and_foot(x: float, y: float, z: float, side: float) -> tuple[tuple[float, float, float],
                                                                       tuple[float, float, float]]:
    """(knee, foot centre) [m] in the hip frame for the foot target (x, y, z) [m] (through :func:`leg_ik`: the
    foot is the target, or the workspace boundary's point nearest it). The knee is the calf joint."""
    q1, q2, q3 = _leg_ik_scalar(x, y, z, side)
    y0 = side * L1
    c, s = math.cos(q1), math.sin(q1)
    out = []
    for xs, zp in ((-L2 * math.sin(q2), -L2 * math.cos(q2)),
                   (-L2 * math.sin(q2) - L3 * math.sin(q2 + q3), -L2 * math.cos(q2) - L3 * math.cos(q2 + q3))):
        out.append((xs, c * y0 - s * zp, s * y0 + c * zp))
    return out[0], out[1]


def legs_ik(feet_in_hip: np.ndarray | list[list[float]]) -> np.ndarray:
    """(12,) joint angles [rad] for (4, 3) foot targets [m] in :data:`a1.LEGS` order."""
    return np.array(legs_ik_list(feet_in_hip.tolist() if isinstance(feet_in_hip, np.ndarray) else feet_in_hip))


def legs_ik_list(rows: list[list[float]]) -> list[float]:
    """:func:`legs_ik` on plain lists (the control-tick fast path)."""
    out: list[float] = []
    for i in range(a1.N_LEGS):
        x, y, z = rows[i]
        out.extend(_leg_ik_scalar(x, y, z, _SIDES[i]))
    return out


_SIDES = [float(s) for s in a1.LEG_SIDE]
