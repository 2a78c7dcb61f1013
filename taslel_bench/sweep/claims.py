"""The paper's claims against a sweep's runs: a table with the paper's selection (stance feet) and every
loaded contact side by side, and one generated sentence per claim saying whether it holds, by which
measurement. Runs are the finished ones (``ok`` or ``degraded``); numbers are mean (min–max, runs).

Filter-on runs are never pooled over filter settings: every override that changes the filter
(:func:`filter_setting_columns`: the ECBF on/off, the formulation, the barriers, robust margins, the stance
source, the contact gain, the estimator, ...) that varies in the sweep splits the claims into one section per
setting, each against the same nominal (filter-off) runs. Each claim also states the runs' verdicts
(``safe``, :mod:`taslel_bench.metrics.verdict`): how many nominal and filtered runs were unsafe, and why.

The verdict rules are written here, next to the sentences, so a reader can check them:
* GRF prediction holds where our MAE <= the paper's;
* "sliding eliminated" holds if, with the filter, at most 1 % of loaded contacts are at the cone edge and
  the sliding distance is at most 10 % of the nominal one; "reduced" if both are lower than nominal;
* "swing foot kept clear" holds if the filtered clearance-violation rate is <= 0.1 % of swing ticks;
  "reduced" if it is lower than nominal;
* on physical obstacles the claim holds if every filtered run is safe (no fall, no trip, ...);
* "no falls" per scenario is read from the verdicts (unsafe runs and their reasons).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import pandas as pd

from taslel_bench.metrics.verdict import reason_tags
from taslel_bench.util.tables import markdown_table

PAPER_GRF_MAE_N = {"z": 3.051, "xy": 1.847}  # [N] the paper's GRF prediction error, flat ground, filter on
Runs = Callable[[str, bool], pd.DataFrame]


def _values(runs: pd.DataFrame, col: str) -> pd.Series:
    return runs[col].astype(float).dropna() if col in runs else pd.Series(dtype=float)


def _stat(runs: pd.DataFrame, col: str) -> str:
    v = _values(runs, col)
    return f"{v.mean():.3g} ({v.min():.3g}–{v.max():.3g}, n={len(v)})" if len(v) else "—"


def _mean(runs: pd.DataFrame, col: str) -> float:
    v = _values(runs, col)
    return float(v.mean()) if len(v) else math.nan


def _falls(runs: pd.DataFrame) -> str:
    return f"{int(runs['fell'].astype(bool).sum())}/{len(runs)}" if len(runs) else "—"


FILTER_SETTING_COLUMNS = ("filter_formulation", "filter_contact_velocity_gain", "estimator", "filter_variant")
NOT_FILTER_SETTINGS = ("filter.enabled", "filter_enabled")


def filter_setting_columns(frame: pd.DataFrame) -> list[str]:
    """Columns of settings that change the filter and vary among the filter-on runs: the summary's filter
    columns, the estimator, and every overridden ``filter.*`` key except ``filter.enabled``."""
    on = frame[frame["filter_enabled"]]
    cols = [c for c in frame.columns if (c in FILTER_SETTING_COLUMNS or c.startswith("filter."))
            and c not in NOT_FILTER_SETTINGS]
    return [c for c in cols if on[c].astype(str).nunique() > 1]


def paper_claims(finished: pd.DataFrame) -> str:
    """Markdown section (empty when the sweep has no filter on/off comparison)."""
    if "filter_enabled" not in finished or "scenario" not in finished or finished.empty:
        return ""
    frame = finished.copy()
    frame["filter_enabled"] = frame["filter_enabled"].fillna(False).astype(bool)
    split = filter_setting_columns(frame)
    nominal = frame[~frame["filter_enabled"]]
    on_all = frame[frame["filter_enabled"]]
    settings = on_all.groupby([on_all[c].astype(str) for c in split], dropna=False) if split else [((), on_all)]
    sections = []
    for keys, on_runs in settings:
        keys = keys if isinstance(keys, tuple) else (keys,)
        label = ", ".join(f"`{c}={v}`" for c, v in zip(split, keys, strict=True))
        body = _claims(pd.concat([nominal, on_runs]), level=4 if split else 3)
        if body:
            sections.append((f"### Filter setting {label}\n\n" if split else "") + body)
    if not sections:
        return ""
    note = (f"Filter-on runs split by {', '.join(f'`{c}`' for c in split)} (never pooled); each setting against "
            "the same nominal runs. " if split else "")
    return ("## Paper vs this harness\n\n" + note + "Mean (min–max, runs) over finished runs. *Loaded* = every "
            "foot contact with a normal force >= 1 N in its contact frame, or a filter lambda >= 1 N along the "
            "terrain normal (the headline); *stance* = the filter's stance set (the paper's selection). "
            "*unsafe* counts runs whose verdict is `safe: false`.\n\n" + "\n".join(sections))


def _claims(frame: pd.DataFrame, level: int = 3) -> str:
    """Table and sentences of one filter setting (its filter-on runs and the nominal runs); one backend only
    (:func:`_one_backend`: solvers are not seeds)."""
    frame, backend_note = _one_backend(frame)

    def runs(scenario: str, on: bool) -> pd.DataFrame:
        return frame[(frame["scenario"] == scenario) & (frame["filter_enabled"] == on)]

    rows: list[tuple[str, str, str, str]] = []
    sentences: list[str] = []
    for claim in (_grf, _friction, _clearance, _logs, _intervention_and_falls, _verdicts):
        claim(runs, rows, sentences)
    if not rows:
        return ""
    table = pd.DataFrame(rows, columns=["quantity", "paper", "nominal only", "filter on"])
    return ((backend_note + "\n\n" if backend_note else "") + markdown_table(table, fmt=str) + f"\n{'#' * level} Claim "
                                                                                               f"by claim\n\n"
            + "\n".join(f"- {s}" for s in sentences) + "\n")


def _unsafe(runs: pd.DataFrame) -> str:
    """``k/n`` unsafe runs (of the judged ones), with the reasons' counts."""
    if "safe" not in runs or runs["safe"].isna().all():
        return "—"
    judged = runs[runs["safe"].notna()]
    bad = judged[~judged["safe"].astype(bool)]
    counts: dict[str, int] = {}
    for text in bad.get("unsafe_reasons", []):
        for tag in reason_tags(text):
            counts[tag] = counts.get(tag, 0) + 1
    why = ", ".join(f"{tag} {k}" for tag, k in counts.items())
    return f"{len(bad)}/{len(judged)}" + (f" ({why})" if why else "")


def _nominal_vs_filtered(off: pd.DataFrame, on: pd.DataFrame, what=None) -> str:
    """``<off> nominal vs <on> filtered`` of ``what`` (default: the unsafe count), leaving out a side with no
    runs (never "— nominal")."""
    what = what or _unsafe
    said = [f"{what(r)} {label}" for r, label in ((off, "nominal"), (on, "filtered")) if what(r) != "—"]
    return " vs ".join(said) if said else "no judged runs"


def _verdicts(runs: Runs, rows: list, sentences: list) -> None:
    parts = []
    for scenario in ("flat", "low_friction", "obstacle", "logs"):
        off, on = runs(scenario, False), runs(scenario, True)
        if off.empty and on.empty:
            continue
        rows.append((f"unsafe runs, {scenario}", "safe", _unsafe(off), _unsafe(on)))
        parts.append(f"{scenario}: {_nominal_vs_filtered(off, on)}")
    if parts:
        sentences.append("**Safe runs** (the verdict: no fall, no trip, no sustained sliding, clearance and "
                         "friction cone kept; the same rules with the filter on or off), unsafe runs of the judged "
                         "ones: "
                         + "; ".join(parts) + ".")


def _one_backend(frame: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """Backends and formulations are not seeds: when the filter-on runs have several, keep the paper's full
    formulation and the backend with the most runs (then by name); the note says which."""
    on, note = frame["filter_enabled"], ""
    for col, prefer in (("filter_formulation", "full"), ("solver", None)):
        if col not in frame:
            continue
        values = frame.loc[on, col].astype(str)
        if values.nunique() <= 1:
            continue
        counts = values.value_counts()
        keep = prefer if prefer in counts else min(counts.index, key=lambda v: (-counts[v], v))
        frame = frame[~on | (frame[col].astype(str) == keep)]
        on = frame["filter_enabled"]
        note += f"Filter-on runs: `{col}={keep}` only (not pooled with the others as if they were seeds). "
    return frame, note


def _grf(runs: Runs, rows: list, sentences: list) -> None:
    on = runs("flat", True)
    if on.empty:
        return
    for ax, label in (("z", "vertical"), ("xy", "lateral")):
        rows.append(
            (f"GRF MAE {label} [N], flat, stance", f"{PAPER_GRF_MAE_N[ax]}", "—", _stat(on, f"grf_mae_{ax}_n_stance"))
        )
        rows.append((f"GRF MAE {label} [N], flat, loaded", "—", "—", _stat(on, f"grf_mae_{ax}_n")))
    stance, loaded = _mean(on, "grf_mae_z_n_stance"), _mean(on, "grf_mae_z_n")
    outside = _mean(on, "contacts_loaded_outside_stance")
    verdict = "holds" if stance <= PAPER_GRF_MAE_N["z"] else "does not hold"
    sentences.append(
        f"**GRF prediction** (paper: vertical MAE {PAPER_GRF_MAE_N['z']} N on flat ground): {verdict} on the "
        f"paper's selection ({stance:.3g} N over stance feet); over every loaded contact the error is "
        f"{loaded:.3g} N, because {outside:.0f} loaded (tick, foot) pairs per run lie outside the filter's stance "
        "set (early touchdowns and lift-off lag), where the filter predicts no force.")


def _friction(runs: Runs, rows: list, sentences: list) -> None:
    off, on = runs("low_friction", False), runs("low_friction", True)
    if off.empty and on.empty:
        return
    for label, col in (("loaded contacts at the cone edge, mu=0.2", "friction_cone_edge_rate"),
                       ("loaded contacts at the cone edge, worst 0.5 s, mu=0.2",
                        "friction_cone_edge_rate_worst_window"),
                       ("stance contacts at the cone edge, mu=0.2", "friction_cone_edge_rate_stance"),
                       ("slip [m/s], loaded, mu=0.2", "slip_mps_mean"),
                       ("slip [m/s], stance, mu=0.2", "slip_mps_mean_stance"),
                       ("sliding distance [m], loaded, mu=0.2", "sliding_distance_m"),
                       ("touchdown slip [m/s], mu=0.2", "touchdown_slip_mps_mean"),
                       ("filter's planned force beyond the true cone, mu=0.2", "filter_demand_beyond_cone_rate")):
        rows.append((label, "sliding eliminated" if col == "friction_cone_edge_rate" else "—",
                     _stat(off, col), _stat(on, col)))
    edge_off, edge_on = _mean(off, "friction_cone_edge_rate"), _mean(on, "friction_cone_edge_rate")
    dist_off, dist_on = _mean(off, "sliding_distance_m"), _mean(on, "sliding_distance_m")
    if on.empty:
        return
    if edge_on <= 0.01 and (off.empty or dist_on <= 0.1 * dist_off):
        verdict = "holds"
    elif off.empty:
        verdict = "does not hold as stated (no nominal runs in this sweep to compare with)"
    elif edge_on < edge_off and dist_on < dist_off:
        verdict = "does not hold as stated: sliding is reduced, not eliminated"
    else:
        verdict = "does not hold: sliding is not reduced"
    sentences.append(
        f"**Friction constraint** (paper: the filter eliminates sliding on mu = 0.2): {verdict}. Loaded contacts "
        f"at the cone edge {edge_off:.3g} -> {edge_on:.3g}, total sliding distance {dist_off:.3g} -> {dist_on:.3g} m "
        f"per run (nominal -> filter); unsafe runs (verdict) {_nominal_vs_filtered(off, on)}.")


def _clearance(runs: Runs, rows: list, sentences: list) -> None:
    off, on = runs("obstacle", False), runs("obstacle", True)
    if off.empty and on.empty:
        return
    for label, col in (("clearance violation rate (every swing tick)", "clearance_violation_rate"),
                       ("violation rate, worst 0.5 s", "clearance_violation_rate_worst_window"),
                       ("violation depth p95 [m]", "clearance_violation_depth_p95_m"),
                       ("violation depth max [m]", "clearance_violation_depth_max_m"),
                       ("min clearance [m]", "clearance_min_m"),
                       ("swing ticks with the foot loaded (in the rate above)", "clearance_loaded_swing_rate"),
                       ("violation rate, lift-off lag ticks", "clearance_violation_rate_lift_off_lag"),
                       ("violation rate, early touchdown ticks", "clearance_violation_rate_early_touchdown"),
                       ("filter's own barrier h < 0 on swing ticks", "barrier_negative_rate")):
        rows.append((f"{label}, virtual bump", "foot kept clear" if col == "clearance_violation_rate" else "—",
                     _stat(off, col), _stat(on, col)))
    r_off, r_on = _mean(off, "clearance_violation_rate"), _mean(on, "clearance_violation_rate")
    if on.empty:
        return
    if r_on <= 0.001:
        verdict = "holds"
    elif r_on < r_off:
        verdict = "holds in part: violations are reduced, not removed"
    else:
        verdict = "does not hold" + (" (no nominal runs in this sweep to compare with)" if off.empty else "")
    sentences.append(
        f"**ECBF ground clearance, virtual profile** (paper: the swing foot is kept above z(phi)): {verdict}. "
        f"Violation rate {r_off:.3g} -> {r_on:.3g} of swing ticks (loaded ones included), p95 depth "
        f"{_mean(on, 'clearance_violation_depth_p95_m') * 1000:.3g} mm with the ECBF. The profile is virtual: "
        f"no geometry in the plant, so a violation here costs nothing physically (see the logs). Unsafe runs "
        f"(verdict) {_nominal_vs_filtered(off, on)}.")


def _logs(runs: Runs, rows: list, sentences: list) -> None:
    off, on = runs("logs", False), runs("logs", True)
    if off.empty and on.empty:
        return
    for label, col in (("trips per run (foot + leg link)", "trips"), ("foot trips per run", "foot_trips"),
                       ("leg-link trips per run", "shin_trips"),
                       ("stance strikes on a flank per run", "stance_flank_strikes"),
                       ("distance [m]", "distance_m"),
                       ("swing ticks touching a log", "obstacle_touch_swing_rate"),
                       ("filter's own barrier h < 0 on swing ticks", "barrier_negative_rate")):
        rows.append((f"{label}, logs", "—", _stat(off, col), _stat(on, col)))
    if on.empty:
        return
    trips_on = _mean(on, "trips")
    all_safe = "safe" in on and on["safe"].notna().all() and bool(on["safe"].astype(bool).all())
    verdict = "holds" if all_safe else "does not hold"
    sentences.append(
        f"**Clearance on real geometry** (logs across the path, the ECBF on the foot sphere's distance to them): "
        f"{verdict}: unsafe runs {_nominal_vs_filtered(off, on)}. Falls {_falls(off)} nominal vs "
        f"{_falls(on)} filtered; trips per run {_mean(off, 'trips'):.3g} -> "
        f"{trips_on:.3g} (foot {_mean(off, 'foot_trips'):.3g} -> {_mean(on, 'foot_trips'):.3g}, lower leg "
        f"{_mean(off, 'shin_trips'):.3g} -> {_mean(on, 'shin_trips'):.3g}); distance {_mean(off, 'distance_m'):.3g} -> "
        f"{_mean(on, 'distance_m'):.3g} m, i.e. {_per_metre(off)} -> {_per_metre(on)} falls per metre walked. The "
        "barrier protects the foot sphere only; the lower leg is not in it. Stance strikes on a log's flank per run "
        f"{_mean(off, 'stance_flank_strikes'):.3g} -> {_mean(on, 'stance_flank_strikes'):.3g}.")


def _per_metre(runs: pd.DataFrame) -> str:
    """Falls per metre of forward progress, over all the runs (a trot stuck at the first log falls less
    often per run than one that climbs several)."""
    metres = float(runs["distance_m"].astype(float).clip(lower=0).sum()) if len(runs) else 0.0
    return f"{runs['fell'].astype(bool).sum() / metres:.2g}" if metres > 0 else "—"


def _intervention_and_falls(runs: Runs, rows: list, sentences: list) -> None:
    parts = []
    for scenario in ("flat", "low_friction", "obstacle", "logs"):
        on, off = runs(scenario, True), runs(scenario, False)
        if on.empty and off.empty:
            continue
        rows.append((f"intervention [N·m] (reference ||u_nom|| [N·m]), {scenario}",
                     "minimal" if scenario == "obstacle" else "—", "—",
                     f"{_stat(on, 'intervention_nm_mean')} ({_mean(on, 'u_nom_nm_mean'):.3g})"))
        rows.append((f"falls, {scenario}", "no falls", _falls(off), _falls(on)))
        if len(on):
            parts.append(f"{scenario} {_mean(on, 'intervention_nm_mean'):.3g} N·m "
                         f"({100 * _mean(on, 'intervention_nm_mean') / _mean(on, 'u_nom_nm_mean'):.0f} % of "
                         f"||u_nom||), falls {_falls(on)}")
    if parts:
        sentences.append("**Minimal intervention, no falls** (paper): the filter's mean ||u - u_nom|| against the "
                         "nominal torque's size, and its falls: " + "; ".join(parts) + ".")
