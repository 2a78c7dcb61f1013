"""Episode metrics for ``summary.json``: a flat dict, units in the key names, all measured in the plant
(MuJoCo) unless the key says ``filter``. Each function states how its number is measured. Contact metrics:
:mod:`taslel_bench.metrics.contacts`; clearance, trips and barrier values:
:mod:`taslel_bench.metrics.clearance`; the run status: :mod:`taslel_bench.metrics.health`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from taslel_bench.interfaces import OVERESTIMATE_MARGIN, overestimates
from taslel_bench.metrics.clearance import ClearanceStream
from taslel_bench.metrics.contacts import ContactStream, JudgedFeet, stand_part
from taslel_bench.metrics.health import HealthLimits, assess, model_errors
from taslel_bench.metrics.residuals import ResidualStream
from taslel_bench.metrics.sections import RunSummary, Verdict
from taslel_bench.metrics.stream import Reducer
from taslel_bench.metrics.verdict import SafetyLimits, reasons
from taslel_bench.metrics.windows import window_ticks
from taslel_bench.record.result import EpisodeResult
from taslel_bench.record.trace import TICK_PARTS, rpy_from_quat


def _pct(x: np.ndarray, p: float) -> float:
    return float(np.percentile(x, p)) if x.size else math.nan


def _median(x: np.ndarray) -> float:
    return float(np.median(x)) if x.size else math.nan


ONE_MS_US = 1000.0  # [µs] (taslel_bench.qp.reference_check.ONE_MS_US)
DEFAULT_LIMITS = HealthLimits()
DEFAULT_SAFETY = SafetyLimits()


def summarize(res: EpisodeResult, control_dt_s: float, stand_duration_s: float, stance_duration_s: float = 0.2,
              limits: HealthLimits = DEFAULT_LIMITS, safety: SafetyLimits = DEFAULT_SAFETY,
              stream: SummaryStream | None = None) -> dict[str, object]:  # fmt: skip
    """The episode's summary keys (:func:`summary_sections`, flattened)."""
    return summary_sections(res, control_dt_s, stand_duration_s, stance_duration_s, limits, safety,
                            stream).flat()  # fmt: skip


def summary_sections(res: EpisodeResult, control_dt_s: float, stand_duration_s: float,
                     stance_duration_s: float = 0.2, limits: HealthLimits = DEFAULT_LIMITS,
                     safety: SafetyLimits = DEFAULT_SAFETY,
                     stream: SummaryStream | None = None) -> RunSummary:  # fmt: skip
    """The episode's summary in sections (:class:`taslel_bench.metrics.sections.RunSummary`; the run adds its
    identity, plant and machine). ``stance_duration_s`` [s]: the scheduled stance length (touchdown-slip
    window; trips and touchdowns read the plan recorded in the trace); ``limits``: when the run is
    ``degraded`` instead of ``ok``; ``safety``: when it is not ``safe``. The numbers come from ``stream``
    (the episode's metrics, fed chunk by chunk during the episode) when it was made with these settings,
    else from the whole trace (which must then hold every tick)."""
    settings = (control_dt_s, stand_duration_s, stance_duration_s, limits)
    trace = res.traced()
    if not isinstance(stream, SummaryStream) or stream.settings != settings:
        if trace.offset:
            raise ValueError("summarize: the trace holds only the last chunk and the episode's metrics were "
                             "made with other settings")
        stream = SummaryStream(*settings)
        stream.feed(trace, trace.n)
    n = trace.n
    outcome: dict[str, object] = {
        "status": res.status, "message": res.message, "fell": bool(res.fell),
        "time_to_fall_s": float(res.time_to_fall_s), "fall_reason": res.fall_reason,
        "ticks": int(n), "sim_time_s": float(n * control_dt_s),
    }  # fmt: skip
    parts = stream.result_sections()
    summary = RunSummary(outcome, Verdict(res.status, "", []), **parts)
    summary.timing = {**_episode_timing(res, n * control_dt_s), **parts["timing"]}
    sketched = stream.sketched_keys()
    if sketched:  # a long episode: these percentiles are read from a histogram (metrics/stream.py, rel. error 1e-3)
        summary.timing["percentiles_from_histogram"] = ",".join(sketched)
    if "residuals_error" in res.extras:
        summary.model["residuals_error"] = str(res.extras["residuals_error"])
    flat = summary.flat()
    status, degraded = assess(flat, limits)
    summary.outcome["status"] = status
    summary.verdict = Verdict(status, degraded, reasons({**flat, "status": status}, safety),
                              model_errors(flat, limits))
    return summary


def _episode_timing(res: EpisodeResult, sim_time_s: float) -> dict[str, float]:
    """[s] the loop's wall time, the kernels' warm-up and the model residuals (both off the loop's clock)
    and the real-time factor (simulated / wall time)."""
    wall = float(res.wall_time_s)
    return {
        "wall_time_s": wall,
        # compiled kernels loaded (or compiled) before the episode clock starts; not in wall_time_s
        "warmup_s": float(res.extras.get("warmup_s", math.nan)),
        "real_time_factor": float(sim_time_s / wall) if wall > 0 else math.nan,
        "residuals_s": float(res.extras.get("residuals_s", math.nan)),
    }


class SummaryStream:
    """Every metric of :func:`summarize` fed chunk by chunk: :meth:`feed` after each chunk of the episode
    (its derived quantities and residuals computed), :meth:`result_sections` at the end. Memory: a few numbers per
    key; a percentile key keeps at most :data:`taslel_bench.metrics.stream.EXACT_QUANTILE_VALUES` values,
    then a fixed-size histogram; the reference-checked ticks' u errors are kept whole (8 bytes per check)."""

    def __init__(self, dt: float, stand_s: float, stance_s: float = 0.2,
                 limits: HealthLimits = DEFAULT_LIMITS) -> None:
        self.settings = (dt, stand_s, stance_s, limits)
        self.dt, self.k_walk = dt, round(stand_s / dt)  # first walking tick
        self.acc, self.n, self.filter_on = Reducer(), 0, False
        self.walk_contacts = ContactStream(dt, stance_s, "")
        self.stand_contacts = ContactStream(dt, stance_s, "_stand")
        self.clearance = ClearanceStream(dt)
        self.residuals = ResidualStream(limits)
        self.estimator = EstimatorStream()
        self.ends: dict[str, np.ndarray] = {}  # trunk position and yaw of the first walking and the last tick
        self.fed = {"walk": False, "stand": False}
        self.reference = Reducer()  # deadline rates for taslel_bench.qp.reference_check
        self._u_errors: list[np.ndarray] = []

    def feed(self, tr, n: int) -> None:
        """The trace's rows up to episode tick ``n`` (every row of its current chunk that is processed)."""
        k0, rows = tr.offset, n - tr.offset
        self.filter_on = tr.filter_on
        self.n = n
        acc = self.acc
        acc.median("tick_us_median", tr.tick_us[:rows])
        acc.pct("tick_us_p99", tr.tick_us[:rows], 99)
        for j, part in enumerate(TICK_PARTS):  # where the tick's time goes, measured inside the loop
            acc.median(f"tick_{part}_us_median", tr.tick_parts_us[:rows, j])
        split = min(max(self.k_walk - k0, 0), rows)  # local row of the first walking tick
        stand, walk = slice(0, split), slice(split, rows)
        self._locomotion(tr, rows, walk)
        self._filter(tr, rows, walk)
        if split > 0 or not self.fed["stand"]:
            self.stand_contacts.feed(tr, stand)
            self.fed["stand"] = True
        if rows > split or not self.fed["walk"]:
            self.walk_contacts.feed(tr, walk)
            self.clearance.feed(tr, walk)
            self.fed["walk"] = True
        if tr.model_residual.shape[0] >= rows:
            self.residuals.feed(tr, walk)
        self.estimator.feed(tr, rows, self._judged_feet(tr, rows, stand, walk))
        err = np.asarray(tr.qp_u_error_nm[:rows])
        self._u_errors.append(err[np.isfinite(err)])  # the reference-checked ticks only (record.reference_every)

    def _judged_feet(self, tr, rows: int, stand: slice, walk: slice) -> JudgedFeet:
        """The feet the contact streams judged on this chunk's rows (stand and walk rows joined; rows a stream
        was not fed stay unloaded)."""
        shape = (rows, tr.mu_hat_foot.shape[1])
        loaded, beyond = np.zeros(shape, bool), np.zeros(shape, bool)
        for part, stream in ((stand, self.stand_contacts), (walk, self.walk_contacts)):
            if stream.last.loaded.shape[0] == part.stop - part.start and part.stop > part.start:
                loaded[part], beyond[part] = stream.last.loaded, stream.last.beyond_cone
        return JudgedFeet(loaded, beyond)

    def _locomotion(self, tr, rows: int, walk: slice) -> None:
        if rows == 0:
            return
        rpy = rpy_from_quat(tr.base_quat_wxyz[:rows])
        if walk.stop > walk.start and "walk" not in self.ends:
            self.ends["walk"] = np.array([*tr.base_pos_w[walk.start], rpy[walk.start, 2]])
        self.ends["last"] = np.array([*tr.base_pos_w[rows - 1], rpy[rows - 1, 2]])
        self.acc.mean("trunk_height_mean_m", tr.base_pos_w[walk, 2])

    def _filter(self, tr, rows: int, walk: slice) -> None:
        """See :func:`filter_metrics`."""
        acc = self.acc
        du = np.linalg.norm(tr.u[walk] - tr.u_nom[walk], axis=1)
        acc.mean("intervention_nm_mean", du)
        acc.mean("u_nom_nm_mean", np.linalg.norm(tr.u_nom[walk], axis=1))
        if not tr.filter_on:
            return
        solve = tr.qp_solve_us[:rows]
        solve = solve[np.isfinite(solve)]
        build = tr.qp_build_us[:rows]
        filtered = tr.qp_status[:rows] >= 0  # ticks the filter ran (filter.start_time may delay it)
        fallback = tr.qp_fallback[:rows]
        acc.count("qp_solves", filtered.sum())
        acc.count("qp_failed", fallback.sum())
        acc.ratio("qp_failed_rate", (fallback & filtered).sum(), filtered.sum())
        acc.window("qp_failed_rate_worst_window", fallback & filtered, filtered, window_ticks(self.dt))
        acc.median("qp_solve_us_median", solve)
        acc.pct("qp_solve_us_p99", solve, 99)
        acc.max("qp_solve_us_max", solve)
        acc.median("qp_build_us_median", build[np.isfinite(build)])
        acc.max("intervention_nm_max", du)
        it = tr.qp_iterations[:rows]
        acc.median("qp_iterations_median", it[it >= 0])
        self.reference.mean("qp_deadline_miss_rate", solve > self.dt * 1e6)
        self.reference.mean("qp_solve_over_1ms_rate", solve > ONE_MS_US)

    def result_sections(self) -> dict[str, dict[str, Any]]:
        """The metrics by summary section: timing (the tick's parts), locomotion, filter, contacts (walking,
        stand, clearance, trips), model (residuals), estimator."""
        acc = self.acc.result()
        loco = self._locomotion_result(acc.get("trunk_height_mean_m", math.nan))
        filt: dict[str, float | None] = {k: acc[k] for k in ("intervention_nm_mean", "u_nom_nm_mean") if k in acc}
        if not self.filter_on:
            filt.update(qp_solves=0, qp_failed_rate=math.nan)
        else:
            for key in ("qp_solves", "qp_failed", "qp_failed_rate", "qp_failed_rate_worst_window",
                        "qp_solve_us_median", "qp_solve_us_p99", "qp_solve_us_max", "qp_build_us_median",
                        "intervention_nm_max"):
                filt[key] = acc.get(key)
            iterations = acc.get("qp_iterations_median", math.nan)
            if not math.isnan(iterations):
                filt["qp_iterations_median"] = iterations
        contacts = {**self.walk_contacts.result(), **stand_part(self.stand_contacts.result()),
                    **self.clearance.result()}
        return {"timing": {k: v for k, v in acc.items() if k.startswith("tick_")}, "locomotion": loco, "filter": filt,
                "contacts": contacts, "model": self.residuals.result(), "estimator": self.estimator.result(self.n)}

    def sketched_keys(self) -> list[str]:
        """The percentile keys of this episode read from a histogram
        (:class:`taslel_bench.metrics.stream.Quantiles`)."""
        parts = (self.acc, self.walk_contacts.acc, self.stand_contacts.acc, self.clearance.acc, self.residuals.acc,
                 self.estimator.acc)
        return [k for acc in parts for k in acc.sketched_keys()]

    def _locomotion_result(self, trunk_height: float) -> dict[str, float]:
        """See :func:`locomotion_metrics` (an episode that never walked: the last tick is its first walking one)."""
        if self.n == 0:
            return {"distance_m": math.nan, "mean_speed_mps": math.nan, "lateral_drift_m": math.nan}
        last = self.ends["last"]
        first = self.ends.get("walk", last)
        k0 = min(self.k_walk, self.n - 1)
        walk_time = (self.n - 1 - k0) * self.dt
        dx = last[0] - first[0]
        return {
            "distance_m": float(dx),
            "mean_speed_mps": float(dx / walk_time) if walk_time > 0 else math.nan,
            "lateral_drift_m": float(abs(last[1] - first[1])),
            "yaw_change_deg": float(np.degrees(last[3] - first[3])),
            "trunk_height_mean_m": trunk_height if "walk" in self.ends else float(last[2]),
        }

    def alarm_events(self) -> list[dict[str, object]]:
        """The first onsets of a residual alarm (:func:`taslel_bench.metrics.residuals.alarm_events`)."""
        return list(self.residuals.events)

    def u_errors(self) -> np.ndarray:
        """[N·m] |u - u_ref| of every reference-checked tick (:mod:`taslel_bench.qp.reference_check`)."""
        return np.concatenate(self._u_errors) if self._u_errors else np.zeros(0)


def locomotion_metrics(res: EpisodeResult, dt: float, stand_s: float) -> dict[str, object]:
    """Distance = world-x displacement of the trunk origin from the start of walking to the last tick;
    mean speed = that distance / walking time; drift = |y| displacement; yaw change in degrees."""
    keys = ("distance_m", "mean_speed_mps", "lateral_drift_m", "yaw_change_deg", "trunk_height_mean_m")
    full = summarize(res, dt, stand_s)
    return {k: full[k] for k in keys if k in full}


def filter_metrics(res: EpisodeResult, k0: int = 0, dt: float = 0.001) -> dict[str, object]:
    """Intervention = mean over the walking ticks ``k0:n`` of ||u - u_nom||_2 [N·m], beside its reference
    magnitude ``u_nom_nm_mean`` = mean ||u_nom||_2 over the same ticks (what the nominal controller asks for);
    QP counts and timings from the backend's own timer (solve) and the filter's (build), every filtered tick;
    ``qp_failed_rate_worst_window``: the failed share over the worst 0.5 s window (``dt`` [s] control period)."""
    full = summarize(res, dt, k0 * dt)
    keys = ("intervention_nm_mean", "u_nom_nm_mean", "qp_solves", "qp_failed", "qp_failed_rate",
            "qp_failed_rate_worst_window", "qp_solve_us_median", "qp_solve_us_p99", "qp_solve_us_max",
            "qp_build_us_median", "intervention_nm_max", "qp_iterations_median")
    return {k: full[k] for k in keys if k in full}


class EstimatorStream:
    """The estimate against the truth, fed chunk by chunk: means from sums and counts; the first friction
    change, the first drop and the first ready tick found once; the last tick outside the band carried.

    Over-estimation is judged per foot (:func:`foot_overestimates`) on the feet that carry load (plant-loaded or
    filter-loaded: :class:`taslel_bench.metrics.contacts.JudgedFeet`), and so is ``estimator_time_to_safe_foot_s``
    (:class:`FootTimeToSafe`); the error, bias, usefulness, settle time and time to safe read the estimate's ``mu``
    (its lowest foot's) against the friction under the trunk."""

    def __init__(self) -> None:
        self.acc, self.k, self.t01 = Reducer(), 0, []
        self.prev_mu: float | None = None
        self.first_ready: int | None = None
        self.settle = _UntilClear(lambda mu, prev: mu != prev, lambda hat, mu: np.abs(hat - mu) > SETTLE_BAND)
        self.foot_safe = FootTimeToSafe()
        self.safe = _UntilClear(lambda mu, prev: mu < prev, lambda hat, mu: hat > mu + SETTLE_BAND)

    def feed(self, tr, rows: int, feet: JudgedFeet) -> None:
        """The trace's first ``rows`` rows; ``feet``: their judged feet ((rows, 4) each)."""
        if rows == 0:
            return
        t, mu, hat, ready = tr.t_s[:rows], tr.mu_true[:rows], tr.mu_hat[:rows], tr.mu_hat_ready[:rows]
        acc, k = self.acc, self.k
        self.t01 = [*self.t01, *t[: 2 - len(self.t01)]][:2]
        err = hat - mu
        acc.mean("estimator_mae", np.abs(err))
        acc.mean("estimator_bias", err)
        # [share] loaded foot-ticks whose estimate exceeds the friction under that foot by more than 0.05, or whose
        # planned force the filter put beyond the true cone there (whatever the estimate)
        over = foot_overestimates(tr.mu_hat_foot[:rows], tr.mu_foot[:rows], feet.beyond_cone)
        judged = feet.loaded
        self.foot_safe.feed(tr.mu_foot[:rows], judged, over, k)
        acc.mean("estimator_overestimate_rate", over[judged])
        acc.mean("estimator_overestimate_rate_trunk", overestimates(hat, mu))  # [share] ticks: mu vs under the trunk
        prev = mu[0] if self.prev_mu is None else self.prev_mu
        self.settle.feed(t, mu, hat, prev, k)
        self.safe.feed(t, mu, hat, prev, k)
        acc.mean("estimator_low_overestimate_rate", over[judged & (tr.mu_foot[:rows] < LOW_FRICTION)])
        if self.first_ready is None and ready.any():
            self.first_ready = k + int(np.argmax(ready))
        start = rows if self.first_ready is None else max(self.first_ready - k, 0)
        acc.mean("estimator_startup_overestimate_rate", over[:start][judged[:start]])
        after = slice(start, rows)
        acc.mean("estimator_ready_overestimate_rate", over[after][judged[after]])
        acc.count("notready_after", (~ready[after]).sum())
        useful = hat[after] >= np.minimum(mu[after], USEFUL_CAP) - USEFUL_SLACK
        capped = np.abs(np.minimum(hat[after], CAPPED_MAE_CAP) - np.minimum(mu[after], CAPPED_MAE_CAP))
        acc.mean("estimator_useful_rate", useful)
        acc.mean("estimator_capped_mae", capped)
        self.prev_mu, self.k = float(mu[-1]), k + rows

    def result(self, n: int) -> dict[str, float]:
        if self.k == 0:
            return {}
        a = self.acc.result()
        dt = float(self.t01[1] - self.t01[0]) if len(self.t01) > 1 else 0.0
        first_ready = self.first_ready if self.first_ready is not None else self.k
        return {
            "estimator_mae": a["estimator_mae"], "estimator_bias": a["estimator_bias"],
            "estimator_overestimate_rate": a["estimator_overestimate_rate"],
            "estimator_overestimate_rate_trunk": a["estimator_overestimate_rate_trunk"],
            "estimator_settle_s": self.settle.value(),
            "estimator_low_overestimate_rate": a["estimator_low_overestimate_rate"],
            "estimator_startup_s": float(first_ready * dt),
            "estimator_startup_overestimate_rate": (a["estimator_startup_overestimate_rate"] if first_ready
                                                    else math.nan),
            "estimator_ready_overestimate_rate": a["estimator_ready_overestimate_rate"],
            "estimator_notready_after_startup_s": float(a["notready_after"] * dt),
            "estimator_useful_rate": a["estimator_useful_rate"],
            "estimator_capped_mae": a["estimator_capped_mae"],
            "estimator_time_to_safe_s": self.safe.value(),
            # [s] the slowest foot: from its first loaded tick on a surface other than its first to its first loaded
            # tick not over-estimated there (0: at once; inf: never; nan: no foot met another surface)
            "estimator_time_to_safe_foot_s": self.foot_safe.value(dt),
        }  # fmt: skip


class FootTimeToSafe:
    """Per foot, fed chunk by chunk: the first loaded tick on friction other than the foot's at tick 0 (a new
    surface), then the first loaded tick from there on that is not over-estimated (:func:`foot_overestimates`)."""

    def __init__(self) -> None:
        self.mu0: np.ndarray | None = None  # [-] friction under each foot at tick 0
        self.k_new: np.ndarray | None = None  # episode tick of each foot's first loaded tick on a new surface (-1)
        self.k_safe: np.ndarray | None = None  # ... and of its first loaded tick not over-estimated from there (-1)

    def feed(self, mu_foot: np.ndarray, loaded: np.ndarray, over: np.ndarray, k: int) -> None:
        """Rows of episode ticks ``k`` .. ``k + len(mu_foot) - 1``: (rows, 4) each."""
        if self.mu0 is None:
            self.mu0 = mu_foot[0].copy()
            self.k_new, self.k_safe = np.full(mu_foot.shape[1], -1), np.full(mu_foot.shape[1], -1)
        mu0 = self.mu0
        assert mu0 is not None and self.k_new is not None and self.k_safe is not None  # set on the first chunk
        for leg in range(mu_foot.shape[1]):
            if self.k_new[leg] < 0:
                hit = np.flatnonzero(loaded[:, leg] & (np.abs(mu_foot[:, leg] - mu0[leg]) > 1e-9))
                if not len(hit):
                    continue
                self.k_new[leg] = k + int(hit[0])
            if self.k_safe[leg] < 0:
                start = max(self.k_new[leg] - k, 0)
                ok = np.flatnonzero(loaded[start:, leg] & ~over[start:, leg])
                if len(ok):
                    self.k_safe[leg] = k + start + int(ok[0])

    def per_foot(self, dt: float) -> np.ndarray:
        """[s] each foot's time to safe (nan: it met no new surface; inf: never safe there)."""
        if self.k_new is None or self.k_safe is None:
            return np.full(0, math.nan)
        out = np.where(self.k_safe >= 0, (self.k_safe - self.k_new) * dt, math.inf)
        return np.where(self.k_new >= 0, out, math.nan)

    def value(self, dt: float) -> float:
        """[s] the largest over the feet that met a new surface (inf if one never became safe; nan if none met
        one)."""
        times = self.per_foot(dt)
        return float(np.nanmax(times)) if (~np.isnan(times)).any() else math.nan


class _UntilClear:
    """:func:`_time_until_clear` from the first tick where ``trigger(mu[k], mu[k-1])`` holds, fed chunk by
    chunk: the trigger's time, the last bad tick and the time of the tick after it carried."""

    def __init__(self, trigger, bad) -> None:
        self.trigger, self.bad = trigger, bad
        self.t0: float | None = None
        self.last_bad: int | None = None
        self.t_after: float | None = None  # time of the tick after the last bad one (None: not seen yet)
        self.end = 0

    def feed(self, t: np.ndarray, mu: np.ndarray, hat: np.ndarray, prev_mu: float, k: int) -> None:
        n = t.shape[0]
        if self.last_bad is not None and self.t_after is None and self.last_bad == k - 1:
            self.t_after = float(t[0])
        start = 0
        if self.t0 is None:
            hits = np.flatnonzero(self.trigger(mu, np.concatenate([[prev_mu], mu[:-1]])))
            hits = hits[(hits + k) > 0]  # tick 0 has no predecessor
            if hits.size == 0:
                self.end = k + n
                return
            start = int(hits[0])
            self.t0 = float(t[start])
        bad = np.flatnonzero(self.bad(hat[start:], mu[start:]))
        if bad.size:
            j = start + int(bad[-1])
            self.last_bad = k + j
            self.t_after = float(t[j + 1]) if j + 1 < n else None
        self.end = k + n

    def value(self) -> float:
        if self.t0 is None:
            return math.nan
        if self.last_bad is None:
            return 0.0
        if self.last_bad == self.end - 1:
            return math.inf
        assert self.t_after is not None  # the tick after the last bad one was fed (last_bad < end - 1)
        return float(self.t_after - self.t0)


SETTLE_BAND = OVERESTIMATE_MARGIN  # [-] |mu_hat - mu| band for the settle time


def foot_overestimates(mu_hat_foot: np.ndarray, mu_foot: np.ndarray, beyond_cone: np.ndarray) -> np.ndarray:
    """(n, 4) over-estimation per foot and tick: the foot's estimate exceeds the friction under it by more than
    the margin (:func:`overestimates`), or the filter planned the foot's force beyond the true cone there
    (``beyond_cone``): a plan the ground cannot hold counts whatever the estimate and its floor."""
    return overestimates(mu_hat_foot, mu_foot) | beyond_cone


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
    """One-sided estimator metrics over control ticks (never claim more friction than there is); over =
    :func:`overestimates`.

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
