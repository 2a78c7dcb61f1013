"""Swing-foot clearance metrics: the virtual phase profile z(s), physical obstacles (trips and stance strikes),
and the filter's own barrier values.

Swing ticks are the walking ticks of a foot outside the filter's stance set. The clearance headline
(``clearance_*``) is judged on **every** swing tick; beside it, the swing ticks whose foot still carries load in
the plant (a contact with normal force >= 1 N) are reported as lift-off lag (first half of the swing) and early
touchdown (second half), ``clearance_*_lift_off_lag`` / ``clearance_*_early_touchdown`` and ``_unloaded``
for the rest: they are in the headline, not removed from it.

Physical obstacles are judged from contact onsets (MuJoCo contacts at distance <= 0,
:mod:`taslel_bench.plant.contact_frames`):

* a **foot trip** is the onset of a foot's contact with an obstacle while the foot is in the air by both the
  gait schedule and the filter's stance set, unless the foot was touching an obstacle within the last
  :data:`TRIP_REARM_S` (a contact continuing from stance through lift-off, or the same contact flickering, is
  not new). A foot whose scheduled stance has begun but that the contact estimate still holds as swing (a
  late touchdown, ``filter.contact_estimate.late_touchdown_max_s``) is landing where the gait means it to:
  its onset is a stance contact (``stance_obstacle_contacts``), not a trip. With the schedule or the contact
  estimate without late touchdowns the filter's stance set contains the schedule's, and this is the onset of
  a foot outside the filter's set (``filter.stance_source=contact``, the plant's contact flags, is the one
  source whose set can miss a scheduled stance foot: its onsets there are landings too);
* a **leg-link trip** is the onset of a non-foot link of a leg (calf, thigh, hip) touching an obstacle;
* a **stance strike** is the onset (after the same re-arm gap), during the foot's stance, of a foot contact
  whose normal is more than 45 deg from vertical (a log's flank); ``stance_obstacle_contacts`` counts every
  new obstacle contact in stance.

``trips`` (the verdict's count) is ``foot_trips + shin_trips``. Two of its parts are events that on the floor
are not trips at all, and are counted apart so a report can show them (``trips`` itself is unchanged):
``foot_trips_top_late_swing`` (a swing foot landing on an obstacle's top in the second half of its swing: an
early touchdown, as the floor's are) and the leg-link onsets within
:data:`taslel_bench.plant.contact_frames.FOOT_NEIGHBOURHOOD_M` of the leg's own foot centre (the URDF calf
box grazing the log the foot stands on). ``trips_strikes`` is what is left: flank hits, top hits in the first
half of the swing and leg-link contacts away from the foot (``shin_trips_off_foot``).
``foot_trips_top_near_touchdown`` are the late-swing top landings at most ``touchdown_tolerance_s`` before the
scheduled touchdown ((1 - swing phase) x the swing's duration), and ``trips_beyond_touchdown_tolerance`` is
``trips`` without them (equal to ``trips`` when the tolerance is 0): the count the verdict reads when
``safety.trip_touchdown_tolerance_s`` > 0. ``trips_beyond_touchdown_20ms`` is the same count at a fixed
:data:`REPORT_TOUCHDOWN_TOLERANCE_S`, whatever the verdict's tolerance: the reports' third reading of the trips,
between ``trips`` and ``trips_strikes``.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np

from taslel_bench.metrics.contacts import FLANK_COS, MIN_NORMAL_FORCE_N
from taslel_bench.metrics.stream import Onsets, Reducer
from taslel_bench.metrics.windows import window_ticks
from taslel_bench.record.trace import EpisodeTrace

CLEARANCE_TOLERANCE_M = 0.001  # [m] below the profile by more than this = a violation
TRIP_REARM_S = 0.01  # [s] an obstacle contact starting within this of the foot's last one continues it
REPORT_TOUCHDOWN_TOLERANCE_S = 0.02  # [s] trips_beyond_touchdown_20ms: 10 % of the default 0.2 s swing


def onsets(mask: np.ndarray, rearm_ticks: int = 1) -> np.ndarray:
    """Bool array like ``mask`` (ticks on axis 0): True where ``mask`` turns on after at least ``rearm_ticks``
    ticks off (a run under way at the first row is not an onset: it continues from before)."""
    return Onsets(rearm_ticks)(mask)


def _near_touchdown_phase(tolerance_s: float, swing_s: float) -> float:
    """Swing phase from which a late-swing top landing is at most ``tolerance_s`` [s] before the scheduled
    touchdown (> 1, none is, when the tolerance is 0)."""
    return 1.0 - tolerance_s / swing_s if tolerance_s > 0.0 else 2.0


def _depths(acc: Reducer, x: np.ndarray, prefix: str) -> None:
    """Distribution of violation depths [m] (positive numbers); nan when there is none."""
    acc.median(f"{prefix}_p50_m", x)
    acc.pct(f"{prefix}_p95_m", x, 95)
    acc.max(f"{prefix}_max_m", x)


def clearance_metrics(tr: EpisodeTrace, k0: int, dt: float = 0.001, swing_s: float = 0.2,
                      touchdown_tolerance_s: float = 0.0) -> dict[str, float]:  # fmt: skip
    """Virtual-profile clearance, physical-obstacle trips and strikes, and the filter's barrier values over the
    walking ticks ``k0:n`` (``dt`` [s] control period, ``swing_s`` [s] the scheduled swing's duration,
    ``touchdown_tolerance_s`` [s] see the module doc). Keys are nan when the run has no profile / no obstacles
    / no filter."""
    stream = ClearanceStream(dt, swing_s, touchdown_tolerance_s)
    stream.feed(tr, slice(k0, tr.n))
    return stream.result()


class ClearanceStream:
    """:func:`clearance_metrics` fed chunk by chunk (rows of the trace's current chunk); contact onsets
    carried across chunks."""

    def __init__(self, dt: float, swing_s: float = 0.2, touchdown_tolerance_s: float = 0.0) -> None:
        self.dt, self.acc = dt, Reducer()
        self.near_touchdown_phase = _near_touchdown_phase(touchdown_tolerance_s, swing_s)
        self.near_touchdown_phase_report = _near_touchdown_phase(REPORT_TOUCHDOWN_TOLERANCE_S, swing_s)
        rearm = max(1, round(TRIP_REARM_S / dt))
        self.flank, self.foot, self.link = Onsets(rearm), Onsets(rearm), Onsets(rearm)
        self.link_off_foot = Onsets(rearm)

    def result(self) -> dict[str, float]:
        return self.acc.result()

    def feed(self, tr: EpisodeTrace, w: slice) -> None:
        acc, dt = self.acc, self.dt
        swing = ~tr.in_stance[w]
        # (n, 4); cast: numpy's stub types a reduction over an axis as bool | array
        loaded = cast(np.ndarray, (tr.contact_fn_n[w] >= MIN_NORMAL_FORCE_N).any(axis=2))
        early = tr.swing_phase[w] >= 0.5
        c = tr.clearance_m[w]
        judged = swing & np.isfinite(c)  # without a profile c is nan: nothing is judged
        violated = judged & (c < -CLEARANCE_TOLERANCE_M)
        parts = (("", judged), ("_unloaded", judged & ~loaded), ("_lift_off_lag", judged & loaded & ~early),
                 ("_early_touchdown", judged & loaded & early))
        for name, sel in parts:
            v = c[sel]
            acc.mean(f"clearance_violation_rate{name}", v < -CLEARANCE_TOLERANCE_M)
            acc.min(f"clearance_min_m{name}", v)
        acc.mean("clearance_loaded_swing_rate", loaded[judged])
        acc.window("clearance_violation_rate_worst_window", violated, judged, window_ticks(dt))
        _depths(acc, -c[violated], "clearance_violation_depth")
        self._obstacles(tr, w, swing & ~tr.scheduled_stance[w])  # in the air by the filter and by the schedule
        _barrier_metrics(acc, tr, w, swing, dt)

    def _obstacles(self, tr: EpisodeTrace, w: slice, swing: np.ndarray) -> None:
        """Trips and stance strikes from contact onsets (see the module doc), the geometric clearance of swing
        feet, lower legs on the floor (``shin_floor_contact_rate``, not a fall); ``swing`` (ticks, 4): the feet
        in the air by the schedule and the filter's stance set."""
        acc = self.acc
        acc.mean("shin_floor_contact_rate", tr.shin_floor_contact[w])
        flank = tr.contact_touching[w] & (tr.contact_normal_w[w][..., 2] < FLANK_COS)
        flank_feet = cast(np.ndarray, flank.any(axis=2))  # (n, 4) (numpy's stub: bool | array)
        acc.count("stance_flank_strikes", (self.flank(flank_feet) & ~swing).sum())
        d = tr.obstacle_clearance_m[w]
        if not np.isfinite(d).any():  # no obstacles in the terrain (nan distances): no obstacle keys
            return
        on_obstacle = cast(np.ndarray, tr.contact_on_obstacle[w].any(axis=2))  # (n, 4) foot touches an obstacle
        new = self.foot(on_obstacle)
        link_new = self.link(tr.leg_link_obstacle_contact[w])
        foot_trips = new & swing
        trip_ticks = np.flatnonzero(foot_trips.any(axis=1) | link_new.any(axis=1))
        touch = on_obstacle & swing
        n_foot, n_link = foot_trips.sum(), link_new.sum()
        acc.count("trips", n_foot + n_link)
        acc.count("foot_trips", n_foot)
        # the same split by where the foot met the obstacle: on a flank (normal > 45 deg from vertical: a riser,
        # a log's side) or on a top (a swing foot landing early on a step's top); they add up to foot_trips
        on_flank = flank.any(axis=2)
        acc.count("foot_trips_flank", (foot_trips & on_flank).sum())
        acc.count("foot_trips_top", (foot_trips & ~on_flank).sum())
        acc.count("shin_trips", n_link)  # leg links: calf, thigh, hip (the name kept from the lower-leg count)
        phase = tr.swing_phase[w]
        late_top = foot_trips & ~on_flank & (phase >= 0.5)
        off_foot = self.link_off_foot(tr.leg_link_obstacle_contact_off_foot[w]).sum()
        acc.count("foot_trips_top_late_swing", late_top.sum())
        acc.count("shin_trips_off_foot", off_foot)
        acc.count("trips_strikes", n_foot - late_top.sum() + off_foot)
        near = (late_top & (phase >= self.near_touchdown_phase)).sum()
        acc.count("foot_trips_top_near_touchdown", near)
        acc.count("trips_beyond_touchdown_tolerance", n_foot + n_link - near)
        near_report = (late_top & (phase >= self.near_touchdown_phase_report)).sum()
        acc.count("trips_beyond_touchdown_20ms", n_foot + n_link - near_report)
        acc.count("stance_obstacle_contacts", (new & ~swing).sum())
        # [s] episode time of the first trip (the report's still strips start there); nan without one
        acc.first("first_trip_s", float(tr.t_s[w][trip_ticks[0]]) if trip_ticks.size else math.nan)
        acc.mean("obstacle_touch_swing_rate", touch[swing])
        acc.min("obstacle_clearance_min_m", d[swing])
        _depths(acc, -d[touch & (d < 0)], "obstacle_penetration")


def _barrier_metrics(acc: Reducer, tr: EpisodeTrace, w: slice, swing: np.ndarray, dt: float) -> None:
    """The filter's own barrier values h (its model's foot positions): the share of swing ticks with
    h < -tolerance on a tick whose QP was solved — the filter reports success while its own safety
    condition does not hold (a wrong model, an infeasible recovery, or a profile it cannot follow); and the
    same over the worst 0.5 s window (nan without a filter or a judged tick)."""
    if not tr.filter_on:
        acc.first("barrier_negative_rate", math.nan)
        acc.first("barrier_negative_rate_worst_window", math.nan)
        return
    h = tr.barrier_h_min(w)  # the smallest over the barrier families
    judged = swing & np.isfinite(h)
    solved = (tr.qp_status[w] == 0)[:, None]
    negative = judged & solved & (h < -CLEARANCE_TOLERANCE_M)
    acc.ratio("barrier_negative_rate", negative.sum(), judged.sum())
    acc.window("barrier_negative_rate_worst_window", negative, judged, window_ticks(dt))
