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


@dataclass(frozen=True)
class TrotScaling:
    """How the trot's values follow a robot of mass m [kg] and leg length L [m] (thigh + calf): the speed with sqrt(L)
    (equal Froude number), the swing height with L, the PD gains with m L (the torques that hold the robot up) and
    its square root. The coefficients are ``controller.scaling``
    (:class:`taslel_bench.config.schema.TrotScalingConfig`)."""

    speed_per_sqrt_leg: float  # [m^0.5/s] speed = this x sqrt(L)
    swing_per_leg: float  # [-] swing height = this x L
    kp_per_mass_leg: float  # [N·m/rad per kg·m] kp = this x m L
    kd_per_sqrt_mass_leg: float  # [N·m·s/rad per sqrt(kg·m)] kd = this x sqrt(m L)

    def values(self, mass_kg: float, leg_length_m: float, stand_height_m: float) -> dict[str, float]:
        """speed [m/s], swing_height [m], stand_height [m], kp [N·m/rad], kd [N·m·s/rad] of the robot (rounded to
        1 mm/s, 0.1 mm, 0.1 N·m/rad and 0.01 N·m·s/rad)."""
        load = mass_kg * leg_length_m  # [kg·m]
        return {
            "speed": round(self.speed_per_sqrt_leg * math.sqrt(leg_length_m), 3),
            "swing_height": round(self.swing_per_leg * leg_length_m, 4),
            "stand_height": stand_height_m,
            "kp": round(self.kp_per_mass_leg * load, 1),
            "kd": round(self.kd_per_sqrt_mass_leg * math.sqrt(load), 2),
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
