"""Swing-foot clearance metrics: the virtual phase profile z(s), physical obstacles (trips), and the
filter's own barrier values.

Swing ticks are the walking ticks of a foot outside the filter's stance set. A swing tick whose foot still
carries load in the plant (normal force >= 1 N: lift-off lag, or an early touchdown) is *loaded*; the
clearance of the virtual profile is judged on the unloaded ones (``clearance_*``) and the loaded ones are
reported separately (``clearance_*_loaded``): a foot standing on the floor under a virtual profile is not a
trip. Physical obstacles are judged by MuJoCo's contacts (a swing foot or a lower leg touching an obstacle:
a trip) and by the geometric distance of the foot sphere to the nearest obstacle.
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.metrics.contacts import MIN_NORMAL_FORCE_N
from taslel_bench.record.trace import EpisodeTrace

CLEARANCE_TOLERANCE_M = 0.001  # [m] below the profile by more than this = a violation


def _onsets(mask: np.ndarray) -> int:
    """Number of False -> True transitions along axis 0 (a run under way at the first row counts)."""
    prev = np.concatenate([np.zeros((1, *mask.shape[1:]), bool), mask[:-1]])
    return int((mask & ~prev).sum())


def _depths(x: np.ndarray, prefix: str) -> dict[str, float]:
    """Distribution of violation depths [m] (positive numbers); nan when there is none."""
    if x.size == 0:
        return {f"{prefix}_p50_m": math.nan, f"{prefix}_p95_m": math.nan, f"{prefix}_max_m": math.nan}
    return {f"{prefix}_p50_m": float(np.median(x)), f"{prefix}_p95_m": float(np.percentile(x, 95)),
            f"{prefix}_max_m": float(x.max())}  # fmt: skip


def clearance_metrics(tr: EpisodeTrace, k0: int) -> dict[str, float]:
    """Virtual-profile clearance, physical-obstacle trips, and the filter's barrier values over the walking
    ticks ``k0:n``. Keys are nan when the run has no profile / no obstacles / no filter."""
    w = slice(k0, tr.n)
    swing = ~tr.in_stance[w]
    loaded = tr.in_contact[w] & (tr.grf_plant_w[w, :, 2] >= MIN_NORMAL_FORCE_N)
    out: dict[str, float] = {}
    c = tr.clearance_m[w]
    has_profile = bool(np.isfinite(c).any())
    for name, sel in (("", swing & ~loaded), ("_loaded", swing & loaded)):
        v = c[sel & np.isfinite(c)] if has_profile else np.zeros(0)
        out[f"clearance_violation_rate{name}"] = float(np.mean(v < -CLEARANCE_TOLERANCE_M)) if v.size else math.nan
        out[f"clearance_min_m{name}"] = float(v.min()) if v.size else math.nan
    out["clearance_loaded_swing_rate"] = float(np.mean(loaded[swing])) if has_profile and swing.any() else math.nan
    below = c[swing & ~loaded & np.isfinite(c)] if has_profile else np.zeros(0)
    out.update(_depths(-below[below < -CLEARANCE_TOLERANCE_M], "clearance_violation_depth"))
    out.update(_obstacle_metrics(tr, w, swing))
    out.update(_barrier_metrics(tr, w, swing))
    return out


def _obstacle_metrics(tr: EpisodeTrace, w: slice, swing: np.ndarray) -> dict[str, float]:
    """Physical obstacles: trips = onsets of a swing foot touching an obstacle plus onsets of a lower leg
    touching one (MuJoCo contacts, distance <= 0); the geometric clearance of swing feet; lower legs on the
    floor (``shin_floor_contact_rate``, not a fall)."""
    out: dict[str, float] = {"shin_floor_contact_rate": float(np.mean(tr.shin_floor_contact[w]))
                             if tr.n > w.start else math.nan}  # fmt: skip
    d = tr.obstacle_clearance_m[w]
    if not np.isfinite(d).any():
        return out
    touch = tr.obstacle_contact[w] & swing
    foot_trips, shin_trips = _onsets(touch), _onsets(tr.nonfoot_obstacle_contact[w])
    ds = d[swing]
    out.update({
        "trips": foot_trips + shin_trips,
        "foot_trips": foot_trips,
        "shin_trips": shin_trips,
        "obstacle_touch_swing_rate": float(np.mean(touch[swing])) if swing.any() else math.nan,
        "obstacle_clearance_min_m": float(ds.min()) if ds.size else math.nan,
    })  # fmt: skip
    out.update(_depths(-d[touch & (d < 0)], "obstacle_penetration"))
    return out


def _barrier_metrics(tr: EpisodeTrace, w: slice, swing: np.ndarray) -> dict[str, float]:
    """The filter's own barrier values h (its model's foot positions): the share of swing ticks with
    h < -tolerance on a tick whose QP was solved — the filter reports success while its own safety
    condition does not hold (a wrong model, an infeasible recovery, or a profile it cannot follow)."""
    if not tr.filter_on:
        return {"barrier_negative_rate": math.nan}
    h = tr.barrier_h_min(w)  # the smallest over the barrier families
    judged = swing & np.isfinite(h)
    if not judged.any():
        return {"barrier_negative_rate": math.nan}
    solved = (tr.qp_status[w] == 0)[:, None]
    negative = judged & solved & (h < -CLEARANCE_TOLERANCE_M)
    return {"barrier_negative_rate": float(negative.sum() / judged.sum())}
