"""Contact metrics counted by physics: every loaded foot contact, the friction under each foot, sliding.

Selections over (tick, foot) pairs of the walking ticks (the stand is reported separately, ``_stand``):

* **plant-loaded**: MuJoCo's contact force on the foot has a normal (world z) component >= 1 N;
* **filter-loaded**: the filter's lambda for the foot has a normal component >= 1 N;
* **loaded** (the headline): plant-loaded or filter-loaded. This includes early touchdowns in the
  scheduled swing (rear feet land at swing phase ~0.82-0.96 carrying 50-170 N), lift-off lag, and feet the
  filter loads while the plant foot is in the air;
* **stance** (``_stance`` suffix, the definition used before): the filter's stance set and plant-loaded.

The contact normal is world z: every terrain surface a foot stands on in the scenarios is horizontal (a foot
against a log's side is a trip, counted by :mod:`taslel_bench.metrics.clearance`).
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.record.trace import EpisodeTrace

MIN_NORMAL_FORCE_N = 1.0  # [N] a contact carries load from this normal force on
CONE_EDGE_FRACTION = 0.98  # |f_t| >= 0.98 mu f_n: at the edge of the plant's Coulomb cone (sliding)
CONE_RTOL = 1e-6  # relative tolerance of "beyond the cone" for the filter's planned forces
TOUCHDOWN_FRACTION = 0.1  # touchdown slip: the first 10 % of the stance duration after a touchdown


def _mean(x: np.ndarray) -> float:
    return float(x.mean()) if x.size else math.nan


def _pct(x: np.ndarray, p: float) -> float:
    return float(np.percentile(x, p)) if x.size else math.nan


def touchdown_window(loaded: np.ndarray, n_ticks: int) -> np.ndarray:
    """(n, 4) bool: the first ``n_ticks`` ticks of every run of consecutive loaded ticks of each foot (a run
    already under way at the first tick is not a touchdown)."""
    n = loaded.shape[0]
    out = np.zeros_like(loaded)
    ticks = np.arange(n)
    for i in range(loaded.shape[1]):
        col = loaded[:, i]
        starts = col & ~np.concatenate([[True], col[:-1]])  # rising edges after the first tick
        start_tick = np.maximum.accumulate(np.where(starts, ticks, -1))  # latest touchdown at or before k
        out[:, i] = col & (start_tick >= 0) & (ticks - start_tick < n_ticks)
    return out


def contact_metrics(tr: EpisodeTrace, k0: int, dt: float, stance_duration_s: float) -> dict[str, float]:
    """All contact metrics of the walking ticks ``k0:n`` (see the module doc), plus the stand's ``_stand``
    GRF error and slip. ``dt`` [s] control period; ``stance_duration_s`` [s] scheduled stance length."""
    n = tr.n
    out = _contact_set(tr, slice(k0, n), dt, stance_duration_s, suffix="")
    stand = _contact_set(tr, slice(0, k0), dt, stance_duration_s, suffix="_stand")
    out.update({k: v for k, v in stand.items() if k.startswith(("grf_mae", "slip_mps_mean", "contacts_loaded"))})
    return out


def _contact_set(tr: EpisodeTrace, ticks: slice, dt: float, stance_s: float, suffix: str) -> dict[str, float]:
    f = tr.grf_plant_w[ticks]  # [N] (n, 4, 3) on each foot, world axes
    lam = tr.grf_filter_w[ticks]  # [N] filter's prediction (nan: filter off or QP failed)
    mu = tr.mu_foot[ticks]  # [-] true friction under each foot
    plant_loaded = tr.in_contact[ticks] & (f[..., 2] >= MIN_NORMAL_FORCE_N)
    lam_ok = np.all(np.isfinite(lam), axis=2)
    filter_loaded = lam_ok & (np.nan_to_num(lam[..., 2]) >= MIN_NORMAL_FORCE_N)
    loaded = plant_loaded | filter_loaded
    stance = tr.in_stance[ticks] & plant_loaded
    ft = np.hypot(f[..., 0], f[..., 1])
    slip = np.hypot(tr.slip_w[ticks, :, 0], tr.slip_w[ticks, :, 1])  # [m/s] contact-point speed
    out: dict[str, float] = {
        f"contacts_loaded{suffix}": int(loaded.sum()),
        f"contacts_loaded_outside_stance{suffix}": int((loaded & ~tr.in_stance[ticks]).sum()),
    }
    for name, sel in (("", plant_loaded), ("_stance", stance)):
        key = name + suffix
        ratio = ft[sel] / f[..., 2][sel]
        out[f"friction_cone_edge_rate{key}"] = _mean(ratio >= CONE_EDGE_FRACTION * mu[sel])
        out[f"friction_ratio_p95{key}"] = _pct(ratio, 95)  # capped at mu by the plant's cone: not a violation
        out[f"slip_mps_mean{key}"] = _mean(slip[sel])
        out[f"slip_mps_p95{key}"] = _pct(slip[sel], 95)
        out[f"sliding_distance_m{key}"] = float(slip[sel].sum() * dt)
    touchdown = touchdown_window(plant_loaded, max(1, round(TOUCHDOWN_FRACTION * stance_s / dt)))
    out[f"touchdown_slip_mps_mean{suffix}"] = _mean(slip[touchdown])
    if tr.filter_on:
        # GRF prediction error: |lambda - f| where either side carries load (lambda = 0 for a foot the filter
        # treats as swing; ticks whose QP failed have no lambda and are left out, counted in qp_failed)
        err = np.abs(np.where(lam_ok[..., None], lam, np.nan) - f)
        for name, sel in (("", loaded & lam_ok), ("_stance", stance & lam_ok)):
            out[f"grf_mae_z_n{name}{suffix}"] = _mean(err[..., 2][sel])
            out[f"grf_mae_xy_n{name}{suffix}"] = _mean(err[..., :2][sel])
        # the filter's planned tangential demand against the TRUE cone under the foot: beyond it, the plant
        # had to refuse the force the filter planned with (over-estimated mu, or a wrong contact model)
        lam_t = np.hypot(lam[..., 0], lam[..., 1])[filter_loaded]
        lam_n = lam[..., 2][filter_loaded]
        # (the square pyramid's corners lie exactly on the cone: |lambda_t| = mu lambda_n up to rounding)
        out[f"filter_demand_beyond_cone_rate{suffix}"] = _mean(lam_t > mu[filter_loaded] * lam_n * (1 + CONE_RTOL))
    return out
