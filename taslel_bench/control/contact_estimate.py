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
* scheduled stance before the foot has touched down (no force above the threshold yet in this stance) ->
  swing, a **late touchdown**, for at most ``late_touchdown_max_s`` after the stance began (then stance
  anyway); 0 turns this off (the stance rows then hold a foot that has not landed where it is in the air,
  the paper's behaviour);
* otherwise swing.

Signals: the gait phase (the controller's own clock) and the norm of the contact force on each foot. In the
plant that is MuJoCo's net contact force on the foot sphere (the feet's contact sensors); a real robot
reports a force per foot from the pressure sensors in its foot pads (``footForce`` in the SDK's low-level
state), uncalibrated and noisy, so a threshold of tens of newtons (the trot loads a stance foot with
~35-70 N) is what it supports; a kinematic signal (foot height over an estimated terrain) is not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.jit import kernel


@dataclass(frozen=True)
class ContactEstimateSettings:
    force_threshold_n: float = 20.0  # [N] contact force norm above which a late-swing foot has touched down
    min_swing_phase: float = 0.5  # [-] earlier in the swing a force is a scuff, not a touchdown
    min_force_vertical_share: float = 0.7  # [-] f_z / |f| of a touchdown (a stub on a riser pushes sideways)
    late_touchdown_max_s: float = 0.0  # [s] a scheduled stance foot not yet loaded stays swing this long (0: off)
    control_dt_s: float = 0.001  # [s]


class ContactEstimate:
    """Stance set per tick from the schedule and the feet's contact forces (module doc); one per episode."""

    def __init__(self, settings: ContactEstimateSettings | None = None) -> None:
        self.s = settings or ContactEstimateSettings()
        self.in_stance = np.zeros(quad.N_LEGS, bool)
        self.early = np.zeros(quad.N_LEGS, bool)  # latched early touchdown (cleared when the schedule swings again)
        self._prev_scheduled = np.ones(quad.N_LEGS, bool)
        self.touched = np.ones(quad.N_LEGS, bool)  # the foot has carried load since its scheduled stance began
        self.ticks_in_stance = np.zeros(quad.N_LEGS, np.int64)  # control ticks since the scheduled stance began
        self.early_touchdowns = 0  # count of early touchdowns taken as stance in the episode
        self.late_touchdown_ticks = 0  # foot-ticks of scheduled stance treated as swing (not landed yet)
        self._late_ticks = round(self.s.late_touchdown_max_s / self.s.control_dt_s)  # (the settings are frozen)
        self._late: np.ndarray | None = None  # this tick's feet in a late touchdown (None: none)

    def reset(self) -> None:
        self.in_stance[:] = False
        self.early[:] = False
        self._prev_scheduled[:] = True
        self.touched[:] = True
        self.ticks_in_stance[:] = 0
        self.early_touchdowns = 0
        self.late_touchdown_ticks = 0
        self._late = None

    def update(self, scheduled_stance: np.ndarray, swing_phase: np.ndarray,
               foot_force_in_world: np.ndarray) -> np.ndarray:  # fmt: skip
        """The stance set (4,) bool for this tick from the schedule (``scheduled_stance``, ``swing_phase``)
        and the contact force on each foot (4, 3) [N]."""
        new, late = _update(np.asarray(scheduled_stance), np.asarray(swing_phase, float),
                            np.asarray(foot_force_in_world, float), self.s.force_threshold_n, self.s.min_swing_phase,
                            self.s.min_force_vertical_share, self._late_ticks, self.early, self._prev_scheduled,
                            self.touched, self.ticks_in_stance, self.in_stance)  # fmt: skip
        self.early_touchdowns += new
        self.late_touchdown_ticks += late  # = the feet scheduled in stance and not in the stance set now
        self._late = np.asarray(scheduled_stance, bool) & ~self.in_stance if late else None
        return self.in_stance.copy()

    def swing_phase(self, scheduled_phase: np.ndarray) -> np.ndarray:
        """The swing phase the filter's barriers should see: the schedule's, and 1 (the end of the swing) for a
        foot in a late touchdown (scheduled stance, phase 0 in the schedule, not landed)."""
        late = self._late
        if late is None:  # no late touchdown this tick
            return scheduled_phase
        phase = np.array(scheduled_phase, float)
        phase[late] = 1.0
        return phase


@kernel
def _update(scheduled, swing_phase, force, threshold, min_phase, min_vertical, late_ticks, early, prev_scheduled,
            touched, ticks_in_stance, in_stance):  # fmt: skip
    """The rules of the module doc, per foot, in place (``early``, ``prev_scheduled``, ``touched``,
    ``ticks_in_stance``, ``in_stance``); returns (new early touchdowns, foot-ticks taken as late touchdown)."""
    n_new = n_late = 0
    for i in range(scheduled.shape[0]):
        sched = scheduled[i]
        early_before = early[i]
        if sched or (prev_scheduled[i] and not sched):  # stance takes over the latch; a lift-off clears it
            early[i] = False
        fx, fy, fz = force[i, 0], force[i, 1], force[i, 2]
        norm = np.sqrt(fx * fx + fy * fy + fz * fz)
        loaded = norm > threshold and fz >= min_vertical * norm
        if sched and not prev_scheduled[i]:  # a scheduled stance begins: landed already if it touched down early
            touched[i] = early_before
            ticks_in_stance[i] = 0
        if not sched and not early[i] and loaded and swing_phase[i] >= min_phase:
            early[i] = True
            n_new += 1
        if sched:
            ticks_in_stance[i] += 1
            if loaded or ticks_in_stance[i] > late_ticks:
                touched[i] = True
        prev_scheduled[i] = sched
        stance = early[i] or (sched and touched[i])
        if sched and not stance:
            n_late += 1
        in_stance[i] = stance
    return n_new, n_late
