"""Analytic leg kinematics of any roll-pitch-pitch quadruped leg, built from a robot's description.

In the hip frame (trunk axes, origin at the hip (abduction) joint), with the leg's
:class:`taslel_bench.robot.description.LegGeometry` (offsets read from the URDF):

    foot centre = Rx(q1') [d_hip_thigh + Ry(q2') (0, 0, -L2) + Ry(q2' + q3') (0, 0, -L3)],  y terms summed in
    ``lateral_m``, where q1' = s1 q1, q2' = s2 q2 + b2, q3' = s3 q3 + b3 - b2 (s: joint axis signs, b: the links'
    angles from straight down at the zero configuration).

For the A1 and the Go1 (offsets only along y and -z, axes +x, +y, +y) this is the classic chain: hip roll, lateral
offset, thigh pitch, thigh along -z, calf pitch, calf along -z to the foot-sphere centre. The inverse keeps the
knee on the robot's side (``knee_sign``: -1 bends backwards, calf angle negative, as the A1). Angles [rad],
positions [m]. The forward chain is :mod:`taslel_bench.robot.leg_chain`'s, which also gives it for all four legs at
once (numpy, torch, compiled) with the foot Jacobians: the controller, the foothold search, the estimators'
features and the slip signal all use that one chain.
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import LegGeometry, RobotDescription
from taslel_bench.robot.leg_chain import chain_row, knee_in_hip, leg_pose


class LegKinematics:
    """Forward and inverse kinematics of the four legs of one robot (core leg order)."""

    def __init__(self, robot: RobotDescription) -> None:
        self.robot = robot
        self.legs: tuple[_Leg, ...] = tuple(_Leg(g) for g in robot.legs)

    def leg_fk(self, leg: int, q_leg: np.ndarray | list[float]) -> np.ndarray:
        """Foot-sphere centre [m] in the hip frame of leg ``leg`` for joint angles ``(q1, q2, q3)``."""
        return np.array(self.legs[leg].fk(float(q_leg[0]), float(q_leg[1]), float(q_leg[2])))

    def leg_ik(self, leg: int, foot_in_hip: np.ndarray | list[float]) -> np.ndarray:
        """Joint angles (hip, thigh, calf) [rad] putting leg ``leg``'s foot centre at ``foot_in_hip`` [m];
        unreachable targets are clipped to the workspace boundary."""
        return np.array(self.legs[leg].ik(float(foot_in_hip[0]), float(foot_in_hip[1]), float(foot_in_hip[2])))

    def knee_and_foot(self, leg: int, x: float, y: float, z: float
                      ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(knee, foot centre) [m] in the hip frame for the foot target (x, y, z) [m] (through :meth:`leg_ik`:
        the foot is the target, or the workspace boundary's point nearest it). The knee is the calf joint."""
        return self.legs[leg].knee_and_foot(x, y, z)

    def legs_ik(self, feet_in_hip: np.ndarray | list[list[float]]) -> np.ndarray:
        """(12,) joint angles [rad], core order, for (4, 3) foot targets [m] in their hip frames."""
        rows = feet_in_hip.tolist() if isinstance(feet_in_hip, np.ndarray) else feet_in_hip
        return np.array(self.legs_ik_list(rows))

    def legs_ik_list(self, rows: list[list[float]]) -> list[float]:
        """:meth:`legs_ik` on plain lists (the control-tick fast path: scalar math is ~20x cheaper than numpy
        on 3-vectors)."""
        out: list[float] = []
        for i in range(quad.N_LEGS):
            x, y, z = rows[i]
            out.extend(self.legs[i].ik(x, y, z))
        return out

    def lateral_offsets_m(self) -> np.ndarray:
        """(4,) [m] each foot's signed distance from its hip's roll plane (+ left)."""
        return np.array([g.lateral_m for g in self.robot.legs])


class _Leg:
    """One leg's chain as plain floats (see the module doc)."""

    def __init__(self, g: LegGeometry) -> None:
        self.y0 = g.lateral_m
        self.dx, self.dz = g.hip_to_thigh_m[0], g.hip_to_thigh_m[2]
        self.l2, self.l3 = g.thigh_length_m, g.calf_length_m
        self.b2, self.b32 = g.thigh_angle_rad, g.calf_angle_rad - g.thigh_angle_rad
        self.s1, self.s2, self.s3 = g.axis_signs
        self.knee = g.knee_sign
        self.row = chain_row(g)  # the forward chain's numbers (leg_chain)

    def fk(self, q1: float, q2: float, q3: float) -> tuple[float, float, float]:
        return leg_pose(self.row, q1, q2, q3, math.sin, math.cos)[:3]

    def ik(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        y0, l2, l3 = self.y0, self.l2, self.l3
        zp = -math.sqrt(max(y * y + z * z - y0 * y0, 1e-9))  # the foot's z in the rolled hip frame
        q1 = math.atan2(z, y) - math.atan2(zp, y0)
        q1 = (q1 + math.pi) % (2 * math.pi) - math.pi
        x, zp = x - self.dx, zp - self.dz  # relative to the thigh joint
        c3 = min(1.0, max(-1.0, (x * x + zp * zp - l2 * l2 - l3 * l3) / (2 * l2 * l3)))
        q3 = self.knee * math.acos(c3)
        q2 = math.atan2(-x, -zp) - math.atan2(l3 * math.sin(q3), l2 + l3 * math.cos(q3))
        return self.s1 * q1, self.s2 * (q2 - self.b2), self.s3 * (q3 - self.b32)

    def knee_and_foot(self, x: float, y: float, z: float
                      ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        q = self.ik(x, y, z)
        return knee_in_hip(self.row, *q, math.sin, math.cos), self.fk(*q)
