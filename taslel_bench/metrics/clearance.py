"""Swing-foot clearance metrics: the virtual phase profile z(s), physical obstacles (trips and stance strikes),
and the filter's own barrier values.

Swing ticks are the walking ticks of a foot outside the filter's stance set. The clearance headline
(``clearance_*``) is judged on **every** swing tick; beside it, the swing ticks whose foot still carries load in
the plant (a contact with normal force >= 1 N) are reported as lift-off lag (first half of the swing) and early
touchdown (second half), ``clearance_*_lift_off_lag`` / ``clearance_*_early_touchdown`` and ``_unloaded``
for the rest: they are in the headline, not removed from it.

Physical obstacles are judged from contact onsets (MuJoCo contacts at distance <= 0,
:mod:`taslel_bench.plant.contact_frames`):

* a **foot trip** is the onset of a swing foot's contact with an obstacle, unless the foot was touching an
  obstacle within the last :data:`TRIP_REARM_S` (a contact continuing from stance through lift-off, or the
  same contact flickering, is not new);
* a **leg-link trip** is the onset of a non-foot link of a leg (calf, thigh, hip) touching an obstacle;
* a **stance strike** is the onset (after the same re-arm gap), during the foot's stance, of a foot contact
  whose normal is more than 45 deg from vertical (a log's flank); ``stance_obstacle_contacts`` counts every
  new obstacle contact in stance.
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.metrics.contacts import FLANK_COS, MIN_NORMAL_FORCE_N
from taslel_bench.metrics.windows import window_ticks, worst_window_rate
from taslel_bench.record.trace import EpisodeTrace

CLEARANCE_TOLERANCE_M = 0.001  # [m] below the profile by more than this = a violation
TRIP_REARM_S = 0.01  # [s] an obstacle contact starting within this of the foot's last one continues it


def onsets(mask: np.ndarray, rearm_ticks: int = 1) -> np.ndarray:
    """Bool array like ``mask`` (ticks on axis 0): True where ``mask`` turns on after at least ``rearm_ticks``
    ticks off (a run under way at the first row is not an onset: it continues from before)."""
    n = mask.shape[0]
    out = np.zeros_like(mask)
    if n == 0:
        return out
    ticks = np.arange(n).reshape(-1, *([1] * (mask.ndim - 1)))
    last_on = np.where(mask, ticks, -(10**9))
    last_on = np.maximum.accumulate(last_on, axis=0)
    prev_on = np.concatenate([np.zeros((1, *mask.shape[1:]), int), last_on[:-1]])  # row 0 continues
    out[1:] = mask[1:] & (ticks[1:] - prev_on[1:] > rearm_ticks)
    return out


def _depths(x: np.ndarray, prefix: str) -> dict[str, float]:
    """Distribution of violation depths [m] (positive numbers); nan when there is none."""
    if x.size == 0:
        return {f"{prefix}_p50_m": math.nan, f"{prefix}_p95_m": math.nan, f"{prefix}_max_m": math.nan}
    return {f"{prefix}_p50_m": float(np.median(x)), f"{prefix}_p95_m": float(np.percentile(x, 95)),
            f"{prefix}_max_m": float(x.max())}  # fmt: skip


def clearance_metrics(tr: EpisodeTrace, k0: int, dt: float = 0.001) -> dict[str, float]:
    """Virtual-profile clearance, physical-obstacle trips and strikes, and the filter's barrier values over the
    walking ticks ``k0:n`` (``dt`` [s] control period). Keys are nan when the run has no profile / no
    obstacles / no filter."""
    w = slice(k0, tr.n)
    swing = ~tr.in_stance[w]
    loaded = (tr.contact_fn_n[w] >= MIN_NORMAL_FORCE_N).any(axis=2)
    early = tr.swing_phase[w] >= 0.5
    c = tr.clearance_m[w]
    has_profile = bool(np.isfinite(c).any())
    judged = swing & np.isfinite(c)
    violated = judged & (c < -CLEARANCE_TOLERANCE_M)
    out: dict[str, float] = {}
    parts = (("", judged), ("_unloaded", judged & ~loaded), ("_lift_off_lag", judged & loaded & ~early),
             ("_early_touchdown", judged & loaded & early))
    for name, sel in parts:
        v = c[sel] if has_profile else np.zeros(0)
        out[f"clearance_violation_rate{name}"] = float(np.mean(v < -CLEARANCE_TOLERANCE_M)) if v.size else math.nan
        out[f"clearance_min_m{name}"] = float(v.min()) if v.size else math.nan
    out["clearance_loaded_swing_rate"] = float(np.mean(loaded[judged])) if has_profile and judged.any() else math.nan
    out["clearance_violation_rate_worst_window"] = (worst_window_rate(violated, judged, window_ticks(dt))
                                                    if has_profile else math.nan)
    out.update(_depths(-c[violated], "clearance_violation_depth"))
    out.update(_obstacle_metrics(tr, w, swing, dt))
    out.update(_barrier_metrics(tr, w, swing, dt))
    return out


def _obstacle_metrics(tr: EpisodeTrace, w: slice, swing: np.ndarray, dt: float) -> dict[str, float]:
    """Trips and stance strikes from contact onsets (see the module doc), the geometric clearance of swing
    feet, lower legs on the floor (``shin_floor_contact_rate``, not a fall)."""
    out: dict[str, float] = {"shin_floor_contact_rate": float(np.mean(tr.shin_floor_contact[w]))
                             if tr.n > w.start else math.nan}  # fmt: skip
    rearm = max(1, round(TRIP_REARM_S / dt))
    flank = tr.contact_touching[w] & (tr.contact_normal_w[w][..., 2] < FLANK_COS)
    out["stance_flank_strikes"] = int((onsets(flank.any(axis=2), rearm) & ~swing).sum())
    d = tr.obstacle_clearance_m[w]
    if not np.isfinite(d).any():
        return out
    on_obstacle = tr.contact_on_obstacle[w].any(axis=2)  # (n, 4) foot touches an obstacle
    new = onsets(on_obstacle, rearm)
    link_new = onsets(tr.leg_link_obstacle_contact[w], rearm)
    foot_trips = int((new & swing).sum())
    link_trips = int(link_new.sum())
    trip_ticks = np.flatnonzero((new & swing).any(axis=1) | link_new.any(axis=1))
    touch = on_obstacle & swing
    ds = d[swing]
    out.update({
        "trips": foot_trips + link_trips,
        "foot_trips": foot_trips,
        "shin_trips": link_trips,  # leg links: calf, thigh, hip (the name kept from the lower-leg count)
        "stance_obstacle_contacts": int((new & ~swing).sum()),
        # [s] episode time of the first trip (the report's still strips start there); nan without one
        "first_trip_s": float(tr.t_s[w.start + trip_ticks[0]]) if trip_ticks.size else math.nan,
        "obstacle_touch_swing_rate": float(np.mean(touch[swing])) if swing.any() else math.nan,
        "obstacle_clearance_min_m": float(ds.min()) if ds.size else math.nan,
    })  # fmt: skip
    out.update(_depths(-d[touch & (d < 0)], "obstacle_penetration"))
    return out


def _barrier_metrics(tr: EpisodeTrace, w: slice, swing: np.ndarray, dt: float) -> dict[str, float]:
    """The filter's own barrier values h (its model's foot positions): the share of swing ticks with
    h < -tolerance on a tick whose QP was solved — the filter reports success while its own safety
    condition does not hold (a wrong model, an infeasible recovery, or a profile it cannot follow); and the
    same over the worst 0.5 s window."""
    none = {"barrier_negative_rate": math.nan, "barrier_negative_rate_worst_window": math.nan}
    if not tr.filter_on:
        return none
    h = tr.barrier_h_min(w)  # the smallest over the barrier families
    judged = swing & np.isfinite(h)
    if not judged.any():
        return none
    solved = (tr.qp_status[w] == 0)[:, None]
    negative = judged & solved & (h < -CLEARANCE_TOLERANCE_M)
    return {"barrier_negative_rate": float(negative.sum() / judged.sum()),
            "barrier_negative_rate_worst_window": worst_window_rate(negative, judged, window_ticks(dt))}
