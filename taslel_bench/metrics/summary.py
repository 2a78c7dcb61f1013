"""Episode metrics for ``summary.json``: a flat dict, units in the key names, all measured in the plant
(MuJoCo) unless the key says ``filter``. Each function states how its number is measured. Contact metrics:
:mod:`taslel_bench.metrics.contacts`; clearance, trips and barrier values:
:mod:`taslel_bench.metrics.clearance`; the run status: :mod:`taslel_bench.metrics.health`."""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.interfaces import OVERESTIMATE_MARGIN, overestimates
from taslel_bench.metrics.clearance import clearance_metrics
from taslel_bench.metrics.contacts import contact_metrics
from taslel_bench.metrics.health import HealthLimits, assess
from taslel_bench.metrics.residuals import residual_metrics
from taslel_bench.metrics.verdict import SafetyLimits, judge
from taslel_bench.metrics.windows import window_ticks, worst_window_rate
from taslel_bench.record.result import EpisodeResult
from taslel_bench.record.trace import TICK_PARTS


def _pct(x: np.ndarray, p: float) -> float:
    return float(np.percentile(x, p)) if x.size else math.nan


def _median(x: np.ndarray) -> float:
    return float(np.median(x)) if x.size else math.nan


DEFAULT_LIMITS = HealthLimits()
DEFAULT_SAFETY = SafetyLimits()


def summarize(res: EpisodeResult, control_dt_s: float, stand_duration_s: float, stance_duration_s: float = 0.2,
              limits: HealthLimits = DEFAULT_LIMITS, safety: SafetyLimits = DEFAULT_SAFETY) -> dict[str, object]:  # fmt: skip
    """The run's summary. ``stance_duration_s`` [s]: the scheduled stance length (touchdown-slip window);
    ``limits``: when the run is ``degraded`` instead of ``ok``; ``safety``: when it is not ``safe``."""
    tr, n = res.trace, res.trace.n
    out: dict[str, object] = {
        "status": res.status,
        "message": res.message,
        "fell": bool(res.fell),
        "time_to_fall_s": float(res.time_to_fall_s),
        "fall_reason": res.fall_reason,
        "ticks": int(n),
        "sim_time_s": float(n * control_dt_s),
        "wall_time_s": float(res.wall_time_s),
        # compiled kernels loaded (or compiled) before the episode clock starts; not in wall_time_s
        "warmup_s": float(res.extras.get("warmup_s", math.nan)),
        "real_time_factor": float(n * control_dt_s / res.wall_time_s) if res.wall_time_s > 0 else math.nan,
        "tick_us_median": _median(tr.tick_us[:n]),
        "tick_us_p99": _pct(tr.tick_us[:n], 99),
    }
    for j, part in enumerate(TICK_PARTS):  # where the tick's time goes, measured inside the loop
        out[f"tick_{part}_us_median"] = _median(tr.tick_parts_us[:n, j])
    k0 = min(round(stand_duration_s / control_dt_s), n)  # first walking tick
    out.update(locomotion_metrics(res, control_dt_s, stand_duration_s))
    out.update(filter_metrics(res, k0, control_dt_s))
    out.update(contact_metrics(tr, k0, control_dt_s, stance_duration_s))
    out.update(clearance_metrics(tr, k0, control_dt_s))
    out.update(residual_metrics(tr, k0, limits))
    out["residuals_s"] = float(res.extras.get("residuals_s", math.nan))
    if "residuals_error" in res.extras:
        out["residuals_error"] = str(res.extras["residuals_error"])
    out.update(estimator_metrics(res))
    out["status"], out["degraded_reasons"] = assess(out, limits)
    out["safe"], out["unsafe_reasons"] = judge(out, safety)
    return out


def locomotion_metrics(res: EpisodeResult, dt: float, stand_s: float) -> dict[str, float]:
    """Distance = world-x displacement of the trunk origin from the start of walking to the last tick;
    mean speed = that distance / walking time; drift = |y| displacement; yaw change in degrees."""
    tr, n = res.trace, res.trace.n
    k0 = min(round(stand_s / dt), max(n - 1, 0))
    if n == 0:
        return {"distance_m": math.nan, "mean_speed_mps": math.nan, "lateral_drift_m": math.nan}
    walk_time = (n - 1 - k0) * dt
    dx = tr.base_pos_w[n - 1, 0] - tr.base_pos_w[k0, 0]
    yaw = tr.base_rpy()[:, 2]
    return {
        "distance_m": float(dx),
        "mean_speed_mps": float(dx / walk_time) if walk_time > 0 else math.nan,
        "lateral_drift_m": float(abs(tr.base_pos_w[n - 1, 1] - tr.base_pos_w[k0, 1])),
        "yaw_change_deg": float(np.degrees(yaw[-1] - yaw[k0])),
        "trunk_height_mean_m": float(np.mean(tr.base_pos_w[k0:n, 2])),
    }


def filter_metrics(res: EpisodeResult, k0: int = 0, dt: float = 0.001) -> dict[str, float]:
    """Intervention = mean over the walking ticks ``k0:n`` of ||u - u_nom||_2 [N·m], beside its reference
    magnitude ``u_nom_nm_mean`` = mean ||u_nom||_2 over the same ticks (what the nominal controller asks for);
    QP counts and timings from the backend's own timer (solve) and the filter's (build), every filtered tick;
    ``qp_failed_rate_worst_window``: the failed share over the worst 0.5 s window (``dt`` [s] control period)."""
    tr, n = res.trace, res.trace.n
    du = np.linalg.norm(tr.u[k0:n] - tr.u_nom[k0:n], axis=1)
    u_nom = np.linalg.norm(tr.u_nom[k0:n], axis=1)
    out: dict[str, float] = {
        "intervention_nm_mean": float(du.mean()) if du.size else math.nan,
        "u_nom_nm_mean": float(u_nom.mean()) if du.size else math.nan,
    }
    if not tr.filter_on:
        out.update(qp_solves=0, qp_failed_rate=math.nan)
        return out
    solve = tr.qp_solve_us[:n]
    solve = solve[np.isfinite(solve)]
    build = tr.qp_build_us[:n]
    filtered = tr.qp_status[:n] >= 0  # ticks the filter ran (filter.start_time may delay it)
    out.update(
        qp_solves=int(filtered.sum()),
        qp_failed=int(tr.qp_fallback[:n].sum()),
        qp_failed_rate=float(tr.qp_fallback[:n][filtered].mean()) if filtered.any() else math.nan,
        qp_failed_rate_worst_window=worst_window_rate(tr.qp_fallback[:n] & filtered, filtered, window_ticks(dt)),
        qp_solve_us_median=_median(solve),
        qp_solve_us_p99=_pct(solve, 99),
        qp_solve_us_max=float(solve.max()) if solve.size else math.nan,
        qp_build_us_median=_median(build[np.isfinite(build)]),
        intervention_nm_max=float(du.max()) if du.size else math.nan,
    )
    it = tr.qp_iterations[:n]
    if np.any(it >= 0):
        out["qp_iterations_median"] = float(np.median(it[it >= 0]))
    return out


def estimator_metrics(res: EpisodeResult) -> dict[str, float]:
    """mu_hat (what the filter used) vs the true friction under the trunk, every tick."""
    tr, n = res.trace, res.trace.n
    err = tr.mu_hat[:n] - tr.mu_true[:n]
    if n == 0:
        return {}
    out = {
        "estimator_mae": float(np.abs(err).mean()),
        "estimator_bias": float(err.mean()),
        "estimator_overestimate_rate": float(np.mean(overestimates(tr.mu_hat[:n], tr.mu_true[:n]))),
    }
    out["estimator_settle_s"] = settle_time(tr.t_s[:n], tr.mu_true[:n], tr.mu_hat[:n])
    out.update(estimator_safety_metrics(tr.t_s[:n], tr.mu_true[:n], tr.mu_hat[:n], tr.mu_hat_ready[:n]))
    return out


SETTLE_BAND = OVERESTIMATE_MARGIN  # [-] |mu_hat - mu| band for the settle time


def settle_time(t: np.ndarray, mu_true: np.ndarray, mu_hat: np.ndarray, band: float = SETTLE_BAND) -> float:
    """Time [s] from the first change of the true friction under the trunk until mu_hat enters
    |mu_hat - mu| <= band and stays there to the end of the episode. NaN without a change; inf if it never
    settles."""
    changes = np.flatnonzero(np.diff(mu_true) != 0.0)
    if changes.size == 0:
        return math.nan
    k0 = int(changes[0]) + 1
    return _time_until_clear(t, k0, np.abs(mu_hat[k0:] - mu_true[k0:]) > band)


LOW_FRICTION = 0.5  # [-] the one-sided over-estimation target conditions on mu below this
USEFUL_CAP, USEFUL_SLACK = 0.5, 0.1  # [-] useful tick: mu_hat >= min(mu, USEFUL_CAP) - USEFUL_SLACK
CAPPED_MAE_CAP = 0.6  # [-] capped MAE: estimate and truth capped here


def estimator_safety_metrics(t: np.ndarray, mu_true: np.ndarray, mu_hat: np.ndarray,
                             ready: np.ndarray) -> dict[str, float]:
    """One-sided estimator metrics over control ticks (issue 19); over = :func:`overestimates`.

    * ``estimator_low_overestimate_rate``: over-estimation over the ticks with mu < 0.5 (every tick, the
      startup window and friction drops included; nan without such ticks);
    * ``estimator_startup_s``: time until the estimator first reports ``ready`` (its window is full; 0 for
      estimators that are always ready); ``estimator_startup_overestimate_rate``: over-estimation in that
      window (nan if empty);
    * ``estimator_ready_overestimate_rate``: over-estimation after it;
    * ``estimator_useful_rate``: fraction of ticks after the startup window with
      mu_hat >= min(mu, 0.5) - 0.1 (the gait is not starved); ``estimator_capped_mae``: mean
      |min(mu_hat, 0.6) - min(mu, 0.6)| over the same ticks;
    * ``estimator_notready_after_startup_s``: time the estimator reported not ready after the startup window
      (e.g. reset to its prior by a change detector);
    * ``estimator_time_to_safe_s``: :func:`time_to_safe` after the first friction drop."""
    n = len(t)
    if n == 0:
        return {}
    over = overestimates(mu_hat, mu_true)
    low = mu_true < LOW_FRICTION
    first_ready = int(np.argmax(ready)) if ready.any() else n
    dt = float(t[1] - t[0]) if n > 1 else 0.0
    after = slice(first_ready, n)
    out = {
        "estimator_low_overestimate_rate": float(over[low].mean()) if low.any() else math.nan,
        "estimator_startup_s": float(first_ready * dt),
        "estimator_startup_overestimate_rate": float(over[:first_ready].mean()) if first_ready else math.nan,
        "estimator_ready_overestimate_rate": float(over[after].mean()) if first_ready < n else math.nan,
        "estimator_notready_after_startup_s": float((~ready[after]).sum() * dt),
    }
    if first_ready < n:
        useful = mu_hat[after] >= np.minimum(mu_true[after], USEFUL_CAP) - USEFUL_SLACK
        capped = np.abs(np.minimum(mu_hat[after], CAPPED_MAE_CAP) - np.minimum(mu_true[after], CAPPED_MAE_CAP))
        out.update(estimator_useful_rate=float(useful.mean()), estimator_capped_mae=float(capped.mean()))
    else:
        out.update(estimator_useful_rate=math.nan, estimator_capped_mae=math.nan)
    out["estimator_time_to_safe_s"] = time_to_safe(t, mu_true, mu_hat)
    return out


def time_to_safe(t: np.ndarray, mu_true: np.ndarray, mu_hat: np.ndarray, band: float = SETTLE_BAND) -> float:
    """Time [s] from the first drop of the true friction under the trunk until mu_hat <= mu + band holds
    from then on to the end of the episode (0: never over after the drop). NaN without a drop; inf if
    mu_hat is over at the end."""
    drops = np.flatnonzero(np.diff(mu_true) < 0.0)
    if drops.size == 0:
        return math.nan
    k0 = int(drops[0]) + 1
    return _time_until_clear(t, k0, mu_hat[k0:] > mu_true[k0:] + band)  # = overestimates() at the default band


def _time_until_clear(t: np.ndarray, k0: int, bad: np.ndarray) -> float:
    """Time [s] from tick ``k0`` until ``bad`` (per tick from k0 on) stays False to the end: 0 if never bad,
    inf if still bad at the end."""
    if not bad.any():
        return 0.0
    last = int(np.flatnonzero(bad)[-1])
    if last == len(bad) - 1:
        return math.inf
    return float(t[k0 + last + 1] - t[k0])
