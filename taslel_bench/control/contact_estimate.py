"""Per-foot contact estimate for the safety filter's stance set (``filter.stance_source: estimate``, preset
``filter=terrain``): the gait schedule as prior, fused with a foot-force signal, Cheetah-3 style (Bledt et
al. 2018: the phase-based contact expectation combined with measured foot force; here as a deterministic
rule set, not their Kalman filter).

Rules per foot, every control tick:

* scheduled stance -> stance (the schedule also ends every stance: a **scheduled lift-off is swing**, whatever
  the foot still carries, so a loaded foot can always lift off -- the stall of ``stance_source: contact``);
* scheduled swing, swing phase >= ``min_swing_phase`` and the foot's contact force above
  ``force_threshold_n`` *and* pointing up (its world-z part at least ``min_force_vertical_share`` of its norm:
  a toe stubbed against a step's riser or a log's side is pushed back, not up, and must not become a stance
  foot held against the riser) -> stance (an **early touchdown**), latched until the schedule's stance ends;
* otherwise swing (a late touchdown stays in the schedule's stance: the stance rows then hold the foot where
  it is, the paper's behaviour).

Signals: the gait phase (the controller's own clock) and the norm of the contact force on each foot. In the
plant that is MuJoCo's net contact force on the foot sphere (the feet's contact sensors); a real Unitree A1
reports a force per foot from the pressure sensors in its foot pads (``footForce`` in the SDK's low-level
state), uncalibrated and noisy, so a threshold of tens of newtons (the trot loads a stance foot with
~35-70 N) is what it supports; a kinematic signal (foot height over an estimated terrain) is not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taslel_bench.robot import a1
from taslel_bench.util.jit import kernel


@dataclass(frozen=True)
class ContactEstimateSettings:
    force_threshold_n: float = 20.0  # [N] contact force norm above which a late-swing foot has touched down
    min_swing_phase: float = 0.5  # [-] earlier in the swing a force is a scuff, not a touchdown
    min_force_vertical_share: float = 0.7  # [-] f_z / |f| of a touchdown (a stub on a riser pushes sideways)


class ContactEstimate:
    """Stance set per tick from the schedule and the feet's contact forces (module doc); one per episode."""

    def __init__(self, settings: ContactEstimateSettings | None = None) -> None:
        self.s = settings or ContactEstimateSettings()
        self.in_stance = np.zeros(a1.N_LEGS, bool)
        self.early = np.zeros(a1.N_LEGS, bool)  # latched early touchdown (cleared when the schedule swings again)
        self._prev_scheduled = np.ones(a1.N_LEGS, bool)
        self.early_touchdowns = 0  # count of early touchdowns taken as stance in the episode

    def reset(self) -> None:
        self.in_stance[:] = False
        self.early[:] = False
        self._prev_scheduled[:] = True
        self.early_touchdowns = 0

    def update(self, scheduled_stance: np.ndarray, swing_phase: np.ndarray,
               foot_force_in_world: np.ndarray) -> np.ndarray:  # fmt: skip
        """The stance set (4,) bool for this tick from the schedule (``scheduled_stance``, ``swing_phase``)
        and the contact force on each foot (4, 3) [N]."""
        self.early_touchdowns += _update(np.asarray(scheduled_stance), np.asarray(swing_phase, float),
                                         np.asarray(foot_force_in_world, float), self.s.force_threshold_n,
                                         self.s.min_swing_phase, self.s.min_force_vertical_share, self.early,
                                         self._prev_scheduled, self.in_stance)  # fmt: skip
        return self.in_stance.copy()


@kernel
def _update(scheduled, swing_phase, force, threshold, min_phase, min_vertical, early, prev_scheduled, in_stance):
    """The rules of the module doc, per foot, in place (``early``, ``prev_scheduled``, ``in_stance``); returns
    the number of new early touchdowns."""
    n_new = 0
    for i in range(scheduled.shape[0]):
        sched = scheduled[i]
        if sched or (prev_scheduled[i] and not sched):  # stance takes over the latch; a lift-off clears it
            early[i] = False
        fx, fy, fz = force[i, 0], force[i, 1], force[i, 2]
        norm = np.sqrt(fx * fx + fy * fy + fz * fz)
        loaded = norm > threshold and fz >= min_vertical * norm
        if not sched and not early[i] and loaded and swing_phase[i] >= min_phase:
            early[i] = True
            n_new += 1
        prev_scheduled[i] = sched
        in_stance[i] = sched or early[i]
    return n_new
