"""Trot schedule and open-loop foot trajectories in the hip frames (the paper's nominal controller).

A *hip frame* has the trunk's axes and its origin at the leg's hip joint; foot targets are the
foot-sphere centre in that frame [m]. Diagonal pairs (FL, RR) and (FR, RL) alternate. The gait phase
``phi`` = (t mod T) / T in [0, 1) as in the paper; each leg's *swing phase* ``s`` in [0, 1] is the
progress of its current swing (the ECBF's phase variable), advancing at ``1 / (T (1 - duty))`` per second.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from taslel_bench.control.plan import ContactPlan

TROT_OFFSETS = np.array([0.0, 0.5, 0.5, 0.0])  # LEGS order: FL, FR, RL, RR
TROT_OFFSETS_LIST = TROT_OFFSETS.tolist()  # plain floats for the control tick


@dataclass(frozen=True)
class GaitParams:
    period_s: float = 0.4  # [s] gait period T
    duty: float = 0.5  # [-] stance fraction of the period
    swing_height_m: float = 0.06  # [m] apex of the nominal swing above the stance height
    stand_height_m: float = 0.27  # [m] hip joint -> foot-sphere centre, vertical, during stance
    speed_mps: float = 0.4  # [m/s] commanded forward speed (trunk x)


# The trot's values where the controller config leaves them null, scaled from the A1's tuned ones (mass 13.741 kg,
# thigh + calf 0.4 m): speed and swing height with the leg length (speed as the square root: equal Froude number),
# the joint gains with m g L (the torques that hold the robot up) and its square root (damping).
REFERENCE_MASS_KG = 13.741  # [kg]
REFERENCE_LEG_M = 0.4  # [m]
REFERENCE_TROT = {"speed": 0.4, "swing_height": 0.06, "kp": 100.0, "kd": 3.0}


def trot_defaults(mass_kg: float, leg_length_m: float, stand_height_m: float) -> dict[str, float]:
    """Speed [m/s], swing height [m], stand height [m], kp [N·m/rad], kd [N·m·s/rad] of a robot of this mass and
    leg length (rounded: the A1 gets the tuned values exactly)."""
    length = leg_length_m / REFERENCE_LEG_M
    load = mass_kg * leg_length_m / (REFERENCE_MASS_KG * REFERENCE_LEG_M)
    return {
        "speed": round(REFERENCE_TROT["speed"] * math.sqrt(length), 3),
        "swing_height": round(REFERENCE_TROT["swing_height"] * length, 4),
        "stand_height": stand_height_m,
        "kp": round(REFERENCE_TROT["kp"] * load, 1),
        "kd": round(REFERENCE_TROT["kd"] * math.sqrt(load), 2),
    }


class TrotGait:
    """Gait clock + foot targets. ``t`` is time since walking started [s]; t < 0 means standing."""

    def __init__(self, params: GaitParams, lateral_m: np.ndarray) -> None:
        """``lateral_m`` (4,) [m]: each foot's nominal y in its hip frame (the leg's lateral offset, + left)."""
        self.p = params
        self.nominal_foot_in_hip = np.stack(
            [np.zeros(4), np.asarray(lateral_m, dtype=float), -params.stand_height_m * np.ones(4)], axis=1
        )
        self._nominal_rows = self.nominal_foot_in_hip.tolist()

    @property
    def step_length_m(self) -> float:
        """Foot travel during stance relative to the hip [m]: speed x stance duration."""
        return self.p.speed_mps * self.p.period_s * self.p.duty

    def state(self, t: float) -> ContactPlan:
        p = self.p
        if t < 0.0:
            return ContactPlan(0.0, 0.0, np.ones(4, bool), np.zeros(4), 0.0)
        phi = (t % p.period_s) / p.period_s
        stance, swing = [], []
        for offset in TROT_OFFSETS_LIST:  # scalar loop: cheaper than numpy on 4 legs, once per control tick
            lp = (phi + offset) % 1.0  # [0, duty) stance, [duty, 1) swing
            stance.append(lp < p.duty)
            swing.append(0.0 if lp < p.duty else (lp - p.duty) / (1.0 - p.duty))
        return ContactPlan(phi, 1.0 / p.period_s, np.array(stance), np.array(swing),
                         1.0 / (p.period_s * (1.0 - p.duty)))

    def foot_targets_in_hip(self, t: float) -> np.ndarray:
        """(4, 3) foot-sphere centre targets [m] in each hip frame at time ``t``."""
        return np.array(self.foot_targets_list(t))

    def foot_targets_list(self, t: float) -> list[list[float]]:
        """Same as :meth:`foot_targets_in_hip` as nested lists (plain floats: cheap in the control tick)."""
        p = self.p
        out = [list(row) for row in self._nominal_rows]
        if t < 0.0:
            return out
        phi = (t % p.period_s) / p.period_s
        half = 0.5 * self.step_length_m
        for i, offset in enumerate(TROT_OFFSETS_LIST):
            lp = (phi + offset) % 1.0
            if lp < p.duty:  # stance: move back from +L/2 to -L/2 at constant speed
                out[i][0] = half - 2.0 * half * (lp / p.duty)
            else:  # swing: forward with a cosine-eased x profile and a half-sine lift in z
                s = (lp - p.duty) / (1.0 - p.duty)
                out[i][0] = -half + half * (1.0 - math.cos(math.pi * s))
                out[i][2] += p.swing_height_m * math.sin(math.pi * s)
        return out
