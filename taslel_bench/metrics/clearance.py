"""Swing-foot clearance metrics: the virtual phase profile z(s), trips and touchdowns from the plant's contacts and
the controller's contact plan, and the filter's own barrier values.

Swing ticks are the walking ticks of a foot outside the filter's stance set. The clearance headline
(``clearance_*``) is judged on **every** swing tick; beside it, the swing ticks whose foot still carries load in
the plant (a contact with normal force >= 1 N) are reported as lift-off lag (first half of the swing) and early
touchdown (second half), ``clearance_*_lift_off_lag`` / ``clearance_*_early_touchdown`` and ``_unloaded``
for the rest: they are in the headline, not removed from it.

**Trips** are judged from contact onsets (MuJoCo contacts at distance <= 0,
:mod:`taslel_bench.plant.contact_frames`) and the contact plan the controller produced, as the trace recorded it
(the plan's stance set ``scheduled_stance`` and swing phase ``swing_phase``; a controller without a gait clock
records an estimated phase there): never the gait's configuration. One rule for every controller and every
surface (the floor, a heightfield, a step, a log, a slope), while a foot is in the air by the plan and by the
filter's stance set (a foot the plan has put down but the filter still holds as swing, a late touchdown, is
landing where the plan means it to):

* (a) the onset of a foot contact whose normal is more than 45 deg from vertical (a riser, a log's flank), at any
  swing phase, is a trip (``foot_trips_flank``, a strike), also when the foot already touches something else
  (``foot_trips_flank_in_contact``: e.g. a foot that landed on the rough heightfield and whose contact normal
  then tilts past 45 deg while its plan still says swing);
* (b) the onset of a foot contact on a walkable surface (normal within 45 deg of vertical) in the first half of
  the swing (swing phase < 0.5) is a trip (``foot_trips_top``: a scuff or a strike while lifting);
* (c) the onset of a foot contact on a walkable surface at swing phase >= 0.5 is a **touchdown**, never a trip
  (``touchdowns_early``: a landing before the plan's touchdown, on a top as on the floor);
* the onset of a leg link's contact (calf, thigh, hip; beside its foot or not) with an obstacle is a trip
  (``shin_trips``; ``shin_trips_off_foot`` those farther than
  :data:`taslel_bench.plant.contact_frames.FOOT_NEIGHBOURHOOD_M` from the leg's foot centre).

An onset is the start of a foot's contact (any surface; for (a), a contact with a flank) after at least
:data:`TRIP_REARM_S` without one: a contact continuing from stance through lift-off, or the same contact
flickering, is not new. A foot's new contact is classified by its contacts of that tick: a flank among them
makes it (a). ``trips`` (the verdict's count) is ``foot_trips + shin_trips``, ``foot_trips`` is
``foot_trips_flank + foot_trips_top``; ``foot_trips_floor`` / ``touchdowns_early_floor`` are the part of them
on the ground that is not an obstacle geom (the flat floor). ``touchdowns_early_beyond_20ms`` are the early
touchdowns more than :data:`REPORT_TOUCHDOWN_TOLERANCE_S` before the plan's touchdown, read from the trace in
whole ticks ((1 - swing phase) / the phase's per-tick step, rounded), so a landing exactly 20 ms early is not
beyond. In stance, ``stance_flank_strikes`` counts the onsets of flank contacts (a log's flank against a stance
foot) and ``stance_obstacle_contacts`` every new obstacle contact. ``foot_contacts_dropped`` and
``contacts_not_logged`` count the contacts of the walk the trace could not keep (beyond
:data:`taslel_bench.plant.contact_frames.MAX_CONTACTS_PER_FOOT` per foot or
:data:`taslel_bench.plant.contact_frames.MAX_CONTACTS_LOGGED` per tick): 0 unless the slots are too few;
``foot_contacts_max`` is the most contacts one foot had on one tick. ``foot_drag_rate_early_swing`` is the share of
the feet's first-half swing ticks (in the air by the plan and the filter) on which the foot touches terrain: a
foot dragged along the ground from lift-off is one contact, no trip, however long it drags; this rate measures it.
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
TRIP_REARM_S = 0.01  # [s] a contact starting within this of the foot's (or link's) last one continues it
REPORT_TOUCHDOWN_TOLERANCE_S = 0.02  # [s] touchdowns_early_beyond_20ms: 10 % of the default 0.2 s swing
LATE_SWING_PHASE = 0.5  # [-] a walkable landing from this swing phase on is a touchdown, earlier a trip


def onsets(mask: np.ndarray, rearm_ticks: int = 1) -> np.ndarray:
    """Bool array like ``mask`` (ticks on axis 0): True where ``mask`` turns on after at least ``rearm_ticks``
    ticks off (a run under way at the first row is not an onset: it continues from before)."""
    return Onsets(rearm_ticks)(mask)


def ticks_before_touchdown(phase: np.ndarray, step: float) -> np.ndarray:
    """Whole ticks from swing phase ``phase`` to the plan's touchdown (phase 1) when the phase grows by ``step``
    per tick: (1 - phase) / step rounded to the nearest tick, so a boundary in time is compared in integers (nan
    where the step is unknown)."""
    if not step > 0.0:
        return np.full(np.shape(phase), np.nan)
    return np.rint((1.0 - np.asarray(phase, float)) / step)


def _depths(acc: Reducer, x: np.ndarray, prefix: str) -> None:
    """Distribution of violation depths [m] (positive numbers); nan when there is none."""
    acc.median(f"{prefix}_p50_m", x)
    acc.pct(f"{prefix}_p95_m", x, 95)
    acc.max(f"{prefix}_max_m", x)


class TripRule:
    """The module doc's rule over consecutive chunks of ticks (the onsets carried across them): the summary's
    counts and the viewer's trip marks (:mod:`taslel_bench.view.recording`) are this one rule."""

    def __init__(self, dt: float) -> None:
        rearm = max(1, round(TRIP_REARM_S / dt))
        self.flank, self.foot, self.link = Onsets(rearm), Onsets(rearm), Onsets(rearm)

    def __call__(self, touching: np.ndarray, flank: np.ndarray, air: np.ndarray, phase: np.ndarray,
                 link: np.ndarray) -> dict[str, np.ndarray]:  # fmt: skip
        """Masks (ticks, 4) from per-foot ``touching`` (a contact with any terrain at distance <= 0), ``flank``
        (one of them with its normal more than 45 deg from vertical), ``air`` (in the air by the plan and the
        filter's stance set), ``phase`` (the plan's swing phase) and per-leg ``link`` (a leg link touching an
        obstacle): ``strike`` (a), ``lift`` (b), ``landing`` (c, a touchdown), ``link`` (a leg link's trip),
        ``new_flank`` (every flank onset, in the air or not) and ``new`` (every new contact of a foot)."""
        new_flank, new = self.flank(flank), self.foot(touching)
        walkable = new & ~flank & air  # a new contact whose contacts of that tick are all within 45 deg of vertical
        return {"strike": new_flank & air, "lift": walkable & (phase < LATE_SWING_PHASE),
                "landing": walkable & (phase >= LATE_SWING_PHASE), "link": self.link(link), "new_flank": new_flank,
                "new": new}


def clearance_metrics(tr: EpisodeTrace, k0: int, dt: float = 0.001) -> dict[str, float]:
    """Virtual-profile clearance, trips, touchdowns and strikes, and the filter's barrier values over the walking
    ticks ``k0:n`` (``dt`` [s] control period; see the module doc). Keys are nan when the run has no profile /
    no obstacles / no filter."""
    stream = ClearanceStream(dt)
    stream.feed(tr, slice(k0, tr.n))
    return stream.result()


class ClearanceStream:
    """:func:`clearance_metrics` fed chunk by chunk (rows of the trace's current chunk); contact onsets and the
    swing phase's per-tick step carried across chunks."""

    def __init__(self, dt: float) -> None:
        self.dt, self.acc = dt, Reducer()
        self.report_ticks = round(REPORT_TOUCHDOWN_TOLERANCE_S / dt)
        rearm = max(1, round(TRIP_REARM_S / dt))
        self.rule = TripRule(dt)
        self.link_off_foot, self.link_floor, self.obstacle = Onsets(rearm), Onsets(rearm), Onsets(rearm)
        self.phase_step = math.nan  # the plan's swing phase per tick (median over the swing ticks seen last)

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
        air = swing & ~tr.scheduled_stance[w]  # in the air by the filter and by the controller's plan
        self._trips(tr, w, air)
        self._obstacles(tr, w, air)
        _barrier_metrics(acc, tr, w, swing, dt)

    def _step(self, phase: np.ndarray, air: np.ndarray) -> float:
        """The plan's swing phase per tick, from this chunk's consecutive in-the-air ticks (the median of the
        positive steps; the last chunk's where this one has none)."""
        d = np.diff(phase, axis=0)
        d = d[air[1:] & air[:-1] & (d > 0.0)]
        if d.size:
            self.phase_step = float(np.median(d))
        return self.phase_step

    def _trips(self, tr: EpisodeTrace, w: slice, air: np.ndarray) -> None:
        """Trips, early touchdowns and stance strikes from contact onsets (the module doc's rule); ``air``
        (ticks, 4): the feet in the air by the plan and the filter's stance set."""
        acc = self.acc
        touching = tr.contact_touching[w]  # (n, 4, K)
        flank = cast(np.ndarray, (touching & (tr.contact_normal_w[w][..., 2] < FLANK_COS)).any(axis=2))  # (n, 4)
        on_obstacle = cast(np.ndarray, tr.contact_on_obstacle[w].any(axis=2))  # (numpy's stub: bool | array)
        phase = tr.swing_phase[w]
        touching_foot = cast(np.ndarray, touching.any(axis=2))  # (n, 4) (numpy's stub: bool | array)
        r = self.rule(touching_foot, flank, air, phase, tr.leg_link_obstacle_contact[w])
        strike, lift, landing, link_obstacle, new = r["strike"], r["lift"], r["landing"], r["link"], r["new"]
        floor = ~on_obstacle
        link_floor = self.link_floor(tr.leg_link_floor_contact[w])
        n_foot, n_link = int(strike.sum() + lift.sum()), int(link_obstacle.sum())
        acc.count("trips", n_foot + n_link)
        acc.count("foot_trips", n_foot)
        acc.count("foot_trips_flank", strike.sum())
        acc.count("foot_trips_top", lift.sum())
        acc.count("foot_trips_floor", ((strike | lift) & floor).sum())
        acc.count("foot_trips_flank_in_contact", (strike & ~new).sum())  # a flank met by a foot already touching
        acc.count("shin_trips", n_link)  # leg links: calf, thigh, hip (the name kept from the lower-leg count)
        acc.count("shin_trips_off_foot", self.link_off_foot(tr.leg_link_obstacle_contact_off_foot[w]).sum())
        acc.count("leg_link_floor_contacts", link_floor.sum())  # new leg-link contacts with the floor
        # a foot the plan and the filter put in the air that still (or again) touches the ground in the first half
        # of its swing: dragged, not lifted; an event count (trips) sees a drag only when the contact breaks
        acc.mean("foot_drag_rate_early_swing", touching_foot[air & (phase < LATE_SWING_PHASE)])
        acc.count("touchdowns_early", landing.sum())
        acc.count("touchdowns_early_floor", (landing & floor).sum())
        early = ticks_before_touchdown(phase[landing], self._step(phase, air))
        acc.count("touchdowns_early_beyond_20ms", (early > self.report_ticks).sum())
        acc.count("stance_flank_strikes", (r["new_flank"] & ~air).sum())
        # contacts the trace could not keep (0 expected: plant.contact_frames' slots are sized with a margin)
        acc.count("foot_contacts_dropped", tr.foot_contacts_dropped[w].sum())
        acc.count("contacts_not_logged", tr.contacts_not_logged[w].sum())
        acc.max("foot_contacts_max", tr.foot_contacts[w])  # the most terrain contacts of one foot on one tick
        acc.count("stance_obstacle_contacts", (self.obstacle(on_obstacle) & ~air).sum())
        trip_ticks = np.flatnonzero((strike | lift).any(axis=1) | link_obstacle.any(axis=1))
        # [s] episode time of the first trip (the report's still strips start there); nan without one
        acc.first("first_trip_s", float(tr.t_s[w][trip_ticks[0]]) if trip_ticks.size else math.nan)

    def _obstacles(self, tr: EpisodeTrace, w: slice, air: np.ndarray) -> None:
        """The geometric clearance of the feet in the air above obstacles, lower legs on the floor
        (``shin_floor_contact_rate``, not a fall); ``air`` (ticks, 4): the feet in the air by the plan and the
        filter's stance set."""
        acc = self.acc
        acc.mean("shin_floor_contact_rate", tr.shin_floor_contact[w])
        d = tr.obstacle_clearance_m[w]
        if not np.isfinite(d).any():  # no obstacles in the terrain (nan distances): no obstacle keys
            return
        touch = cast(np.ndarray, tr.contact_on_obstacle[w].any(axis=2)) & air
        acc.mean("obstacle_touch_swing_rate", touch[air])
        acc.min("obstacle_clearance_min_m", d[air])
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
