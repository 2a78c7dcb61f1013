"""Sweep report: ``python -m taslel_bench.report <sweep folder>`` (also run by the sweep callback).

Writes ``report.md``, ``table.csv``, ``table.tex`` and PNG figures into the sweep folder: per scenario x
solver x estimator (runs pooled over seeds) the fall rate with counts, violations, intervention, GRF error,
QP timings with the shifted geometric mean relative to the best backend (as qpbenchmark reports it), and
the machine and package versions. Every number says how it was measured.
"""

from __future__ import annotations

import argparse
import datetime as dt
import errno
import re
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd

from taslel_bench.record import run_files
from taslel_bench.sweep import table_set
from taslel_bench.sweep.aggregate import SUMMARY_TABLE, aggregate, collect, override_keys, run_folders
from taslel_bench.sweep.claims import _unsafe, paper_claims
from taslel_bench.sweep.policy_table import policy_section
from taslel_bench.sweep.solver_verdict import _overall, machine_busy_line, solve_time_figure, solver_verdict
from taslel_bench.sweep.solver_verdict import _sentence as _solver_sentence
from taslel_bench.sweep.stills import MAX_STRIPS, still_strips
from taslel_bench.sweep.terrain_table import terrain_section, urdf_plant_runs
from taslel_bench.sweep.verdict_table import verdict_section
from taslel_bench.util.log import console_logging
from taslel_bench.util.machine import machine_info
from taslel_bench.util.stats import SHGEOM_SHIFT_US, shifted_geometric_mean
from taslel_bench.util.tables import markdown_table

GROUP = ["scenario", "solver", "filter_formulation", "filter_contact_velocity_gain", "estimator"]
OPTIONAL_GROUP = ("filter_formulation", "filter_contact_velocity_gain")  # columns only when the sweep varies them


def override_columns(frame: pd.DataFrame) -> list[str]:
    """Columns of overridden config keys (``scenario.friction``, ...; :func:`sweep.expand_overrides`)."""
    return override_keys(frame)


def group_columns(frame: pd.DataFrame) -> list[str]:
    """The columns that tell the rows of a sweep apart: scenario, solver, estimator, and every setting the
    sweep varies (optional columns and overridden keys only when they take more than one value). In a summary
    column "none" is a run without the setting (filter off) and does not count as a value; in an overridden key
    it is a value the sweep chose (``+mismatch_plant=none,lossy``: the URDF plant and the lossy one)."""
    def varies(c: str, none_counts: bool = False) -> bool:
        values = frame[c] if none_counts else frame.loc[frame[c] != "none", c]
        return values.astype(str).nunique() > 1

    cols = [c for c in GROUP if c in frame.columns and (c not in OPTIONAL_GROUP or varies(c))]
    return cols + [c for c in override_columns(frame) if varies(c, none_counts=True)]


def solver_label(row: pd.Series | dict, frame: pd.DataFrame) -> str:
    """The backend, with the filter formulation when the sweep compares formulations (they hand the
    backend different QPs, so their solve times are separate distributions)."""
    solver = str(row.get("solver", ""))
    if "filter_formulation" in group_columns(frame) and isinstance(row.get("filter_formulation"), str):
        return f"{solver} ({row['filter_formulation']})"
    return solver


FINISHED = ("ok", "degraded")  # runs that simulated to their end or to a fall


def _finished(frame: pd.DataFrame) -> pd.DataFrame:
    return frame[frame["status"].isin(FINISHED)] if "status" in frame else frame.iloc[0:0]


def _fall_rate(frame: pd.DataFrame) -> str:
    ok = _finished(frame)
    return f"{int(ok['fell'].astype(bool).sum())}/{len(ok)}" if len(ok) else "—"


def _mean(frame: pd.DataFrame, col: str) -> float:
    return float(frame[col].astype(float).mean()) if col in frame and frame[col].notna().any() else float("nan")


def read_steps(path: Path, columns: list[str] | None = None) -> pd.DataFrame | None:
    """A run's steps.parquet (``columns`` of it), None when it is absent or unreadable (truncated, another
    file): the report of a sweep never fails on one bad run; its row says so (:func:`sweep.aggregate.collect`)."""
    if not path.is_file():
        return None
    try:
        return pd.read_parquet(path, columns=columns)
    except Exception:  # ArrowInvalid, OSError, a missing column
        return None


def solve_times(sweep_dir: Path, frame: pd.DataFrame) -> dict[str, np.ndarray]:
    """Per solver: every tick's solve time [µs] from the runs' steps.parquet."""
    out: dict[str, list[np.ndarray]] = {}
    for _, row in frame.iterrows():
        if row.get("solver") in (None, "none") or not isinstance(row.get("run_dir"), str):
            continue
        steps = read_steps(sweep_dir / row["run_dir"] / run_files.STEPS, ["qp_solve_us"])
        if steps is not None:
            t = steps["qp_solve_us"].to_numpy()
            out.setdefault(solver_label(row, frame), []).append(t[np.isfinite(t)])
    return {k: np.concatenate(v) for k, v in out.items() if v}


COUNT_COLUMNS = ("runs", "errors", "degraded", "fall_rate")
# report column -> summary key, per table; every number is the mean over the row's runs
SAFETY_COLUMNS = {
    "speed_mps": "mean_speed_mps",
    "intervention_nm": "intervention_nm_mean",
    "u_nom_nm": "u_nom_nm_mean",
    "qp_failed_rate": "qp_failed_rate",
    "grf_mae_z_n": "grf_mae_z_n",
    "grf_mae_z_n_stance": "grf_mae_z_n_stance",
    "grf_mae_xy_n": "grf_mae_xy_n",
    "cone_edge_rate": "friction_cone_edge_rate",
    "cone_edge_rate_worst_0.5s": "friction_cone_edge_rate_worst_window",
    "demand_beyond_cone_rate": "filter_demand_beyond_cone_rate",
    "slip_mps_mean": "slip_mps_mean",
    "sliding_distance_m": "sliding_distance_m",
    "touchdown_slip_mps": "touchdown_slip_mps_mean",
    "clearance_violation_rate": "clearance_violation_rate",
    "clearance_depth_p95_m": "clearance_violation_depth_p95_m",
    "trips": "trips",
    "stance_strikes": "stance_flank_strikes",
    "barrier_negative_rate": "barrier_negative_rate",
    "residual_joint_nm": "residual_joint_nm_rms",
    "residual_trunk_force_n": "residual_trunk_force_n_rms",
    "residual_alarm_rate": "residual_alarm_rate",
}
COST_COLUMNS = {
    "qp_solve_us_median": "qp_solve_us_median",
    "qp_solve_us_p99": "qp_solve_us_p99",
    "estimator_mae": "estimator_mae",
    "estimator_overestimate_rate": "estimator_overestimate_rate",
    "estimator_low_overestimate_rate": "estimator_low_overestimate_rate",
    "estimator_useful_rate": "estimator_useful_rate",
    "estimator_startup_overestimate_rate": "estimator_startup_overestimate_rate",
    "estimator_time_to_safe_s": "estimator_time_to_safe_s",
    "estimator_settle_s": "estimator_settle_s",
    "real_time_factor": "real_time_factor",
}


def summary_table(sweep_dir: Path, frame: pd.DataFrame) -> pd.DataFrame:
    """One row per group of runs (:func:`group_columns`; seeds pooled): counts, fall rate, and the mean of
    each metric over the row's runs that finished (``ok`` or ``degraded``; errors are counted apart)."""
    times = solve_times(sweep_dir, frame)
    shgeom = {s: shifted_geometric_mean(t) for s, t in times.items()}
    best = min(shgeom.values()) if shgeom else float("nan")
    rows = []
    cols = group_columns(frame)
    groups = frame.groupby(cols, dropna=False) if cols else [((), frame)]
    status = frame["status"] if "status" in frame else pd.Series("error", index=frame.index)
    for keys, g in groups:
        keys = keys if isinstance(keys, tuple) else (keys,)
        row = dict(zip(cols, keys, strict=True))
        solver = solver_label(row, frame)
        done = _finished(g)
        row.update({
            "runs": len(g),
            "errors": int((status[g.index] == "error").sum()),
            "degraded": int((status[g.index] == "degraded").sum()),
            "fall_rate": _fall_rate(g),
        })  # fmt: skip
        row.update({name: _mean(done, key) for name, key in {**SAFETY_COLUMNS, **COST_COLUMNS}.items()})
        row["qp_shgeom_rel_best"] = shgeom.get(solver, float("nan")) / best if solver in shgeom else float("nan")
        rows.append(row)
    return pd.DataFrame(rows)


def _figures(sweep_dir: Path, frame: pd.DataFrame, table: pd.DataFrame) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    made = solve_time_figure(sweep_dir, frame, group_columns(frame), plt)  # every tick (sweep.solver_verdict)
    if "scenario" in table and len(table) and _fall_rate_figure(sweep_dir, frame, plt):
        made.append("fall_rates.png")
    if "run_dir" in frame:
        made += _episode_figures(sweep_dir, frame, plt)
    return made


def _fall_rate_figure(sweep_dir: Path, frame: pd.DataFrame, plt) -> bool:
    """``fall_rates.png``: one horizontal bar per group of the summary table (only seeds pooled), falls/runs
    beside each bar, the columns that vary as labels and the constant ones in the title. False (no file) when
    nothing fell: no empty axis."""
    ok = _finished(frame)
    by = [c for c in group_columns(frame) if c in ok]
    if not len(ok) or not by:
        return False
    fell = ok.groupby(by, dropna=False)["fell"]
    rates = fell.mean()
    if not len(rates) or rates.max() <= 0:
        return False
    keys = rates.index.to_frame(index=False).map(lambda v: "—" if pd.isna(v) else str(v))  # NaN: no setting
    shown = [c for c in keys if keys[c].nunique() > 1] or list(keys.columns[:1])
    fixed = [f"{c} {keys[c].iloc[0]}" for c in keys if c not in shown]
    fig, ax = plt.subplots(figsize=(7, max(2.5, 0.22 * len(rates) + 1.2)))
    bars = ax.barh([" · ".join(row) for row in keys[shown].itertuples(index=False)], rates.to_numpy())
    ax.bar_label(bars, [f"{int(k)}/{n}" for k, n in zip(fell.sum(), fell.size(), strict=True)], fontsize=6, padding=2)
    ax.invert_yaxis()  # the table's order, top to bottom
    ax.set_xlim(0, 1.1)
    ax.set_xlabel("fall rate (seeds pooled; falls/runs beside each bar)")
    ax.tick_params(axis="y", labelsize=7)
    title = f"Fall rate per {' · '.join(map(str, shown))}" + (f" ({', '.join(fixed)})" if fixed else "")
    ax.set_title(textwrap.fill(title, 70), fontsize=8)
    fig.tight_layout()
    fig.savefig(sweep_dir / "fall_rates.png", dpi=120)
    plt.close(fig)
    return True


def _first_run(frame: pd.DataFrame, scenario: str | None, filter_on: bool) -> pd.Series | None:
    if "filter_enabled" not in frame or "scenario" not in frame:
        return None
    done = _finished(frame)
    sel = done[(done["scenario"] == scenario) & (done["filter_enabled"] == filter_on)]
    return sel.sort_values("seed").iloc[0] if len(sel) else None


def _steps(sweep_dir: Path, row: pd.Series | None) -> pd.DataFrame | None:
    if row is None:
        return None
    return read_steps(sweep_dir / str(row["run_dir"]) / run_files.STEPS)


def _episode_figures(sweep_dir: Path, frame: pd.DataFrame, plt) -> list[str]:
    """The paper's figures where the sweep has the runs: lateral GRF of one stance foot without and with
    the filter (low_friction, else the first scenario); swing-foot bottom height vs the obstacle profile."""
    made = []
    leg = "FL"
    scenarios = list(dict.fromkeys(frame.get("scenario", pd.Series(dtype=str)).dropna()))
    grf_scenario = "low_friction" if "low_friction" in scenarios else (scenarios[0] if scenarios else None)
    runs = {on: _steps(sweep_dir, _first_run(frame, grf_scenario, on)) for on in (False, True)}
    if any(r is not None for r in runs.values()):
        fig, ax = plt.subplots(figsize=(8, 3.2))
        for on, steps in runs.items():
            if steps is None:
                continue
            window = steps[(steps["t_s"] >= 3.0) & (steps["t_s"] <= 5.0)]
            label = "filter on" if on else "nominal only"
            ax.plot(window["t_s"], window[f"{leg}_grf_plant_y_w_n"], label=f"{label}: MuJoCo contact force")
            if on:
                ax.plot(window["t_s"], window[f"{leg}_grf_filter_y_w_n"], ":", label="filter on: predicted lambda")
        ax.set_xlabel("t [s]")
        ax.set_ylabel(f"{leg} lateral force y [N]")
        ax.set_title(f"{leg} lateral ground reaction force, {grf_scenario}")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(sweep_dir / "grf_lateral.png", dpi=120)
        plt.close(fig)
        made.append("grf_lateral.png")
    logs_figure = _logs_figure(sweep_dir, frame, plt)
    made += [logs_figure] if logs_figure else []
    clearance = {on: _steps(sweep_dir, _first_run(frame, "obstacle", on)) for on in (False, True)}
    if any(r is not None for r in clearance.values()):
        fig, ax = plt.subplots(figsize=(8, 3.2))
        for on, steps in clearance.items():
            if steps is None:
                continue
            window = steps[(steps["t_s"] >= 3.0) & (steps["t_s"] <= 4.0)]
            bottom = window[f"{leg}_foot_z_w_m"] - 0.02
            ax.plot(window["t_s"], bottom, label=("ECBF on" if on else "nominal only") + ": foot-sphere bottom")
            if on:
                swing = window[f"{leg}_clearance_m"].notna()
                ax.plot(window["t_s"][swing], (bottom - window[f"{leg}_clearance_m"])[swing], "k.", ms=1.5,
                        label="obstacle profile z(s)")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("height [m]")
        ax.set_title(f"{leg} swing-foot height vs obstacle profile")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(sweep_dir / "clearance.png", dpi=120)
        plt.close(fig)
        made.append("clearance.png")
    return made


def _run_obstacles(sweep_dir: Path, row: pd.Series | None) -> tuple:
    """The physical obstacles of a run, rebuilt from its config.yaml (Hydra builds the scenario)."""
    path = sweep_dir / str(row["run_dir"]) / "config.yaml" if row is not None else None
    if path is None or not path.is_file():
        return ()
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    try:
        return instantiate(OmegaConf.load(path).scenario).terrain.logs()
    except Exception:  # a corrupt config.yaml: the figure is drawn without the logs
        return ()


def _logs_figure(sweep_dir: Path, frame: pd.DataFrame, plt) -> str | None:
    """FL foot-sphere centre path (world x-z) over the logs, nominal vs filtered (first seed of each), with
    the logs and the trunk's progress."""
    rows = {on: _first_run(frame, "logs", on) for on in (False, True)}
    runs = {on: _steps(sweep_dir, row) for on, row in rows.items()}
    if all(r is None for r in runs.values()):
        return None
    fig, (ax, ax_x) = plt.subplots(2, 1, figsize=(8, 5.2), gridspec_kw={"height_ratios": [2, 1]})
    for ob in _run_obstacles(sweep_dir, rows[True] if rows[True] is not None else rows[False]):
        x = np.linspace(ob.x_m - ob.radius_m, ob.x_m + ob.radius_m, 101)
        top = ob.z_m + np.sqrt(np.maximum(ob.radius_m**2 - (x - ob.x_m) ** 2, 0.0))  # the log's upper outline
        ax.fill_between(x, 0.0, np.maximum(top, 0.0), color="saddlebrown", alpha=0.5, lw=0)
    for on, steps in runs.items():
        if steps is None:
            continue
        label = "ECBF on" if on else "nominal only"
        ax.plot(steps["FL_foot_x_w_m"], steps["FL_foot_z_w_m"] - 0.02, lw=0.7, label=f"{label}: FL foot bottom")
        touch = steps["FL_obstacle_contact"].to_numpy(bool)
        ax.plot(steps["FL_foot_x_w_m"][touch], steps["FL_foot_z_w_m"][touch] - 0.02, "x", ms=3,
                label=f"{label}: foot on or against a log")
        ax_x.plot(steps["t_s"], steps["base_x_w_m"], label=label)
    reach = max(float(r["FL_foot_x_w_m"].max()) for r in runs.values() if r is not None)
    ax.set_xlim(0.1, reach + 0.3)
    ax.set_ylim(-0.005, 0.16)
    ax.set_xlabel("world x [m]")
    ax.set_ylabel("z [m] (not to scale)")
    ax.set_title("FL foot path over the logs (brown: the logs; x: foot in contact with one)")
    ax.legend(fontsize=7)
    ax_x.set_xlabel("t [s]")
    ax_x.set_ylabel("trunk x [m]")
    ax_x.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(sweep_dir / "logs.png", dpi=120)
    plt.close(fig)
    return "logs.png"


HOW_MEASURED = """
How each column is measured (all plant quantities in MuJoCo, per run over the walking time, then averaged
over the row's finished runs, `ok` or `degraded`; `fall_rate` counts falls over those runs; `degraded` runs
crossed a health limit and are listed below):
- `speed_mps`: world-x displacement of the trunk from the start of walking / walking time.
- `intervention_nm`: mean over walking ticks of ||u - u_nom||₂; `u_nom_nm`: mean ||u_nom||₂, its reference size.
- Contacts are judged in MuJoCo's own contact frame (its normal and friction), every contact of a foot with
  any terrain geom: a *loaded contact* has a normal force f_n >= 1 N (a foot on a log's flank included).
  *Loaded* feet (GRF headline): a loaded plant contact or a filter lambda >= 1 N along the terrain normal
  (early touchdowns and lift-off lag included); `_stance`: the filter's stance set (the paper's selection).
- `grf_mae_*`: |filter lambda - MuJoCo contact force| (world axes) over loaded feet (lambda = 0 where the
  filter treats the foot as swing): `z` the vertical error, `xy` the magnitude of the lateral error vector.
- `cone_edge_rate`: share of loaded contacts with |f_t| >= 0.98 mu f_n in the contact frame, mu = that
  contact's friction: sliding or about to; `_worst_0.5s`: the same over the worst 0.5 s window.
  `demand_beyond_cone_rate`: share of filter-loaded feet whose planned lambda leaves the true cone about
  the terrain normal under the foot (what the plant had to refuse).
- `slip_mps_mean`: mean tangential speed of the contact point (relative to the terrain, normal component
  removed) over loaded contacts; `sliding_distance_m`: its integral over time for each foot's most loaded
  contact, summed over the feet; `touchdown_slip_mps`: the mean over the first 10 % of the stance duration
  after each touchdown.
- `clearance_violation_rate`: every swing tick (loaded ones included: lift-off lag, early touchdown) with
  the foot-sphere bottom more than 1 mm below the virtual profile z(s); `clearance_depth_p95_m`: 95th
  percentile of how far below.
- `trips`: the verdict's count, one rule for every controller and surface, read from the plant's contacts
  (MuJoCo, distance <= 0) and the contact plan the controller recorded, for a foot in the air by the plan and
  the filter's stance set: a new foot contact (after >= 10 ms without one) whose normal is more than 45 deg
  from vertical (a riser, a log's flank), at any swing phase (`foot_trips_flank`); a new contact on a walkable
  surface (normal within 45 deg) in the first half of the swing (`foot_trips_top`); plus every new contact
  of a leg link (calf, thigh, hip) with an obstacle (`shin_trips`; `shin_trips_off_foot` those beyond 4 cm of
  the leg's own foot centre). `foot_trips_floor`: the foot trips on the floor (not an obstacle geom).
- `touchdowns_early`: new contacts on a walkable surface in the second half of the swing, on a top as on the
  floor: landings before the plan's touchdown, not trips (`touchdowns_early_beyond_20ms`: more than 20 ms
  before it, in whole ticks). `stance_flank_strikes`: new flank contacts of a foot in stance.
- `barrier_negative_rate`: share of swing ticks whose QP was solved while the filter's own barrier h < 0.
- `residual_*`: RMS over walking ticks of the controller model's residual against what the plant did,
  |M vdot + h - S u - J'f| (the plant's acceleration and foot forces, the model's M, h, J): joint rows
  [N·m] and trunk-force rows [N]; 0 up to rounding when the model is the plant. `residual_alarm_rate`:
  share of ticks beyond `health.residual_trunk_force_n_max` / `health.residual_joint_nm_max`.
- `qp_solve_us_*`: the backend's own timer around the solver call (matrix building excluded), per tick.
- `qp_shgeom_rel_best`: shifted geometric mean (shift {shift} µs) of all ticks' solve times of the
  solver, divided by the best solver's; 1.0 = fastest.
- `estimator_*`: the friction the filter used (mu_hat) vs the true friction under the trunk, every tick:
  mean |error|, fraction with mu_hat > mu + 0.05 (over-estimation: the dangerous side), the same where
  mu < 0.5 (`low_`), the share of ticks after the startup window with mu_hat >= min(mu, 0.5) - 0.1
  (`useful`), over-estimation while the estimator still used its prior (`startup_`), the time from a
  friction drop until mu_hat <= mu + 0.05 (`time_to_safe_s`), and the time from the first friction change
  until mu_hat stays within 0.05 (`settle_s`; inf: never; — : no change in the run).
- `real_time_factor`: simulated time / wall time of the whole episode (jobs ran in parallel, so they
  competed for the cores).
"""


def _run_list(frame: pd.DataFrame, status: str, detail: str, title: str) -> list[str]:
    if frame.empty or "status" not in frame:
        return []
    sel = frame[frame["status"] == status]
    if sel.empty:
        return []
    return [f"## {title}\n"] + [f"- `{r.get('run_dir')}`: {r.get(detail)}\n" for _, r in sel.iterrows()]


def _run_commits(frame: pd.DataFrame) -> str:
    """The code versions the runs' summaries name (``git_commit``, ``git_dirty``), with their run counts."""
    if "git_commit" not in frame.columns or frame.empty:
        return "an unrecorded code version"
    dirty = frame["git_dirty"] if "git_dirty" in frame.columns else pd.Series(False, index=frame.index)
    labels = [
        f"{str(c)[:12]}{' (uncommitted changes)' if d is True else ''}"
        for c, d in zip(frame["git_commit"], dirty, strict=True)
    ]
    counts = pd.Series(labels).value_counts()
    return ", ".join(f"commit {label} ({n} runs)" for label, n in counts.items())


def anchor(heading: str) -> str:
    """The link anchor GitHub and MkDocs give a markdown heading (lower case, punctuation dropped, spaces as -)."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower().replace("`", ""))
    return text.replace(" ", "-")


def contents(sections: list[str]) -> str:
    """A contents list of the ``## `` headings in ``sections`` (each item a markdown string), linked."""
    heads = [line[3:].strip() for text in sections for line in str(text).splitlines() if line.startswith("## ")]
    return "## Contents\n\n" + "".join(f"- [{h}](#{anchor(h)})\n" for h in heads) + "\n"


def _unsafe_lines(frame: pd.DataFrame) -> list[str]:
    """One line per group of runs with an unsafe run: ``k/n`` of its judged runs and the reasons' counts."""
    if "safe" not in frame or frame.empty:
        return []
    keys = [c for c in group_columns(frame) if c in frame]
    out = []
    groups = frame.groupby([frame[c].astype(str) for c in keys], sort=True) if keys else [((), frame)]
    for values, runs in groups:
        judged = runs[runs["safe"].notna()]
        if judged.empty or judged["safe"].astype(bool).all():
            continue
        values = values if isinstance(values, tuple) else (values,)
        label = ", ".join(f"{c}={v}" for c, v in zip(keys, values, strict=True)) or "all runs"
        out.append(f"- {label}: {_unsafe(judged)} unsafe\n")
    return out


def answers_section(frame: pd.DataFrame, solver_rows: pd.DataFrame | None) -> str:
    """The report's answers before its tables: which backend to ship (the solver verdict's sentences) and
    which runs were unsafe, and why (the verdict's reason tags)."""
    if frame.empty:
        return "## Verdicts\n\n_no runs found_\n"
    parts = ["## Verdicts\n"]
    if solver_rows is not None and not solver_rows.empty:
        overall = _overall(solver_rows).strip().replace("**Over the sweep** ", "over the sweep ")
        parts.append(f"**Which solver to ship**: {overall} Per world:\n")
        parts += [f"- {_solver_sentence(str(w), g)}" for w, g in solver_rows.groupby("scenario", sort=True)]
        parts.append("\nDetails: [Solver verdict](#solver-verdict-which-backend-to-ship).\n")
    unsafe = _unsafe_lines(frame)
    judged = int(frame["safe"].notna().sum()) if "safe" in frame else 0
    bad = int((frame["safe"].notna() & ~frame["safe"].fillna(True).astype(bool)).sum()) if "safe" in frame else 0
    parts.append(f"**Unsafe runs.** {bad} of {judged} judged runs are unsafe"
                 + (" (a fall, a trip, sustained sliding, the clearance profile or the friction cone crossed):"
                    if unsafe else ".") + "\n")
    parts += unsafe
    if unsafe:
        parts.append("")
    errors = int((frame["status"] == "error").sum()) if "status" in frame else 0
    degraded = int((frame["status"] == "degraded").sum()) if "status" in frame else 0
    parts.append(f"**Health.** {errors} run(s) ended in an error, {degraded} degraded (listed at the end).\n")
    return "\n".join(parts) + "\n"


def _guarded(make, what: str) -> tuple[list, str]:
    """(``make()``, "") or ([], a note naming the error): one bad run's files cost a figure, not the report."""
    try:
        return make(), ""
    except Exception as exc:  # any error costs the figure, not the report
        return [], f"{what} skipped: {type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}"


def write_report(sweep_dir: Path, frame: pd.DataFrame | None = None, keep_stills: bool = False,
                 max_stills: int = MAX_STRIPS) -> Path:
    sweep_dir = Path(sweep_dir)
    if frame is None:
        frame = (
            pd.read_parquet(sweep_dir / SUMMARY_TABLE)
            if (sweep_dir / SUMMARY_TABLE).is_file()
            else aggregate(sweep_dir)
        )
    table = summary_table(sweep_dir, frame) if not frame.empty else pd.DataFrame()
    run_files.atomic_write(sweep_dir / "table.csv", lambda p: table.to_csv(p, index=False))
    run_files.atomic_write(
        sweep_dir / "table.tex", lambda p: p.write_text(table.to_latex(index=False, float_format="%.3g"))
    )
    figures, skipped = _guarded(lambda: _figures(sweep_dir, frame, table) if not frame.empty else [], "figures")
    info = machine_info()
    keys = [c for c in group_columns(frame) if c in table]
    safety = table[[*keys, *COUNT_COLUMNS, *SAFETY_COLUMNS]] if len(table) else table
    cost = table[[*keys, "runs", *COST_COLUMNS, "qp_shgeom_rel_best"]] if len(table) else table
    solver_text, solver_rows = solver_verdict(sweep_dir, frame, group_columns(frame)) if not frame.empty else ("", None)
    head = [
        "# taslel_bench sweep report\n",
        f"Sweep folder: `{sweep_dir}` · {len(frame)} runs · generated "
        f"{dt.datetime.now().isoformat(timespec='seconds')}\n",
        machine_busy_line(frame) if not frame.empty else "",
    ]
    lines = [
        answers_section(frame, solver_rows),
        verdict_section(frame, group_columns(frame)) if not frame.empty else "",
        "## Safety and physics per group of runs (seeds pooled)\n",
        markdown_table(safety) if len(table) else "_no runs found_\n",
        "## Cost per group of runs\n" if len(table) else "",
        markdown_table(cost) if len(table) else "",
        solver_text,
        HOW_MEASURED.format(shift=SHGEOM_SHIFT_US),
        (policy_section(frame) or terrain_section(frame)) if not frame.empty else "",
        paper_claims(_finished(urdf_plant_runs(frame))) if not frame.empty else "",
    ]
    lines += _run_list(frame, "degraded", "degraded_reasons", "Runs that ended degraded (a health limit crossed)")
    lines += _run_list(frame, "error", "message", "Runs that ended in an error")
    strips, strips_skipped = _guarded(lambda: still_strips(sweep_dir, frame, keep_stills, max_stills),
                                               "still strips")
    lines += strips  # falls and trips seen (taslel_bench.sweep.stills)
    lines += [f"_{note}_\n" for note in (skipped, strips_skipped) if note]
    if figures:
        lines.append("## Figures\n")
        lines += [f"![{f}]({f})\n" for f in figures]
    lines.append("## Machine and code\n\n"
                 f"Machine: {info['cpu']}, {info['cores']} cores, {info['os']}, Python {info['python']}  \n"
                 f"Packages: {info['packages']}  \n"
                 f"Report written by {info['code']}; runs produced by {_run_commits(frame)}\n")
    text = "\n".join([*head, contents(lines), *lines])
    path = sweep_dir / "report.md"
    run_files.atomic_write(path, lambda p: p.write_text(text))
    return path


def main(argv: list[str] | None = None) -> None:
    """Exit 0: table and report written, every run ok; 1: a run error or degraded, or the table or report
    could not be written (one line); 2: not a sweep folder."""
    ap = argparse.ArgumentParser(description="Aggregate a sweep folder and write its report.")
    ap.add_argument("sweep_dir", type=Path)
    ap.add_argument("--keep-stills", action="store_true",
                    help="keep still strips and clips newer than their run's files instead of drawing them again")
    ap.add_argument("--max-stills", type=int, default=MAX_STRIPS,
                    help=f"draw still strips and clips for at most this many falls and trips, ~3 s each (default "
                         f"{MAX_STRIPS}; the first of each group first); the others are listed with their replay "
                         f"command")
    args = ap.parse_args(argv)
    console_logging()
    if not args.sweep_dir.is_dir():
        print(f"error: not a folder: {args.sweep_dir}", file=sys.stderr)
        raise SystemExit(2)
    if not run_folders(args.sweep_dir):
        print(f"error: no runs in {args.sweep_dir}: expected run folders holding summary.json or Hydra's "
              ".hydra/ (a sweep folder, outputs/sweeps/<time>/)", file=sys.stderr)
        raise SystemExit(2)
    if problem := table_set.set_problem(args.sweep_dir):  # the set found here was left incomplete
        print(f"note: {problem}; rebuilding it now", file=sys.stderr)
    frame = collect(args.sweep_dir)
    try:
        table_set.begin(args.sweep_dir)  # summary.parquet, table.csv/.tex, report.md: one set (table_set.json)
        aggregate(args.sweep_dir, frame=frame)
        print(write_report(args.sweep_dir, frame, args.keep_stills, args.max_stills))
        table_set.seal(args.sweep_dir, len(frame))
    except OSError as exc:
        what = "disk full" if exc.errno == errno.ENOSPC else type(exc).__name__
        print(f"error: {what}: could not write the table or report in {args.sweep_dir}: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    failed = frame[frame["status"] != "ok"] if "status" in frame else frame
    for _, row in failed.iterrows():
        print(f"  {row.get('status')}: {row.get('run_dir')}: {row.get('message') or row.get('degraded_reasons')}")
    raise SystemExit(1 if len(failed) else 0)


if __name__ == "__main__":
    main()
