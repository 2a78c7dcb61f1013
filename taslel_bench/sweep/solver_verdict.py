"""The sweep report's solver verdict: which QP backend should this filter ship with, and why.

One table per world (scenario), one row per backend (with the filter formulation and any other setting the
sweep varies; seeds pooled, backends never pooled): per tick, pooled over the row's finished runs from their
``steps.parquet``:

* ``success_rate``: ticks whose QP the backend solved (else the filter's fallback torque was applied);
* ``wrong_rate``: reference-checked ticks (``record.reference_every``) whose "solved" u is farther than
  ``record.reference_tol_nm`` from the tight reference -- solved but wrong; ``u_err_p99_nm``/``u_err_max_nm``:
  the torque error max_j |u_j - u_ref,j| on those ticks;
* ``solve_p50/p99/max_us``, ``miss_period_rate`` (solves longer than the control period), ``miss_1ms_rate``
  (longer than 1 ms): the deadline figures, from the measurement the machine does not disturb: per solve the
  thread's CPU time over the backend's own timed interval (``timing``: ``thread CPU``,
  :mod:`taslel_bench.sim.solve_clock`). The wall clock also counts the time the thread waited for a CPU
  while other processes ran -- a 90 µs solve reads 8 ms on a busy machine, and a few solves per run do even on
  a quiet one -- so it measures the machine, not the solver; ``wall_p99_us`` and ``wall_miss_period_rate``
  show it beside. Runs recorded before thread CPU times existed are judged on the wall clock (``timing``:
  ``wall``). When a run of the world had a busy machine (``machine_busy``: its loop had a CPU less than
  ``BUSY_CPU_SHARE`` of the time, :mod:`taslel_bench.util.machine`) the sentence says so first. The first
  build of each QP layout of a persistent backend in a run (``qp_setup``: e.g. at the first tick and when
  the stand turns into walking; a controller can build its layouts before its loop starts) is judged apart:
  ``setups`` and ``setup_max_us``, named in the sentence, not in the deadline figures. A rebuild for a
  layout built before (a backend that keeps one solver and switches back) counts like any solve;
* ``iterations``: median iterations per solve; ``rtf``: mean real-time factor of the runs;
* ``route`` (``persistent``: set up once and updated; ``qpsolvers``: set up every call) and ``tolerances``
  (the settings in force whose names are tolerances, and the backend's answer check).

The sentence: per world, the backend to ship is the fastest by solve p99 among those with no failed solve, no
wrong answer and no deadline miss at the control period; over the sweep, the one that qualifies in every world
with the lowest worst-world p99. Figure ``qp_solve_times.png``: every tick's solve time as an ECDF per backend
(one panel per world), p99 (o) and max (x) marked, the control period as a vertical line.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pandas as pd

from taslel_bench.record import run_files
from taslel_bench.util.tables import markdown_table

ONE_MS_US = 1000.0  # [µs]
STEP_COLUMNS = ("qp_solve_us", "qp_solve_cpu_us", "qp_setup", "qp_iterations", "qp_u_error_nm", "qp_status")
WALL, THREAD_CPU = "wall", "thread CPU"  # which measurement the deadline figures of a row come from
FINISHED = ("ok", "degraded")
FIGURE = "qp_solve_times.png"


def _label(row: pd.Series, keys: list[str]) -> str:
    """The backend with every other setting the sweep varies (``solver (condensed, estimator=mlp)``)."""
    extra = [str(row[k]) if k == "filter_formulation" else f"{k}={row[k]}" for k in keys]
    return f"{row['solver']} ({', '.join(extra)})" if extra else str(row["solver"])


def _varied(done: pd.DataFrame, keys: list[str]) -> list[str]:
    """The group keys other than world and backend that take more than one value among the filtered runs."""
    return [k for k in keys if k not in ("scenario", "solver") and not k.startswith("solver.") and k in done
            and done[k].astype(str).nunique() > 1]  # solver.<key> overrides: part of the backend's name


def _ticks(sweep_dir: Path, runs: pd.DataFrame) -> dict[str, np.ndarray]:
    """The runs' per-tick columns (:data:`STEP_COLUMNS`) concatenated; missing columns are NaN."""
    parts: dict[str, list[np.ndarray]] = {c: [] for c in STEP_COLUMNS}
    for run_dir in runs["run_dir"]:
        path = sweep_dir / str(run_dir) / run_files.STEPS
        if not isinstance(run_dir, str) or not path.is_file():
            continue
        steps = pd.read_parquet(path, columns=[c for c in STEP_COLUMNS if c in _columns(path)])
        filtered = steps["qp_status"].to_numpy() >= 0 if "qp_status" in steps else np.ones(len(steps), bool)
        for c in STEP_COLUMNS:
            col = steps[c].to_numpy(float) if c in steps else np.full(len(steps), np.nan)
            parts[c].append(col[filtered])
    return {c: np.concatenate(v) if v else np.zeros(0) for c, v in parts.items()}


def _columns(path: Path) -> list[str]:
    import pyarrow.parquet as pq

    return list(pq.read_schema(path).names)


def _tolerances(settings: object, equality_rows: bool = True) -> tuple[str, str]:
    """(route, tolerance text) from a run's ``solver_settings`` (the backend's ``describe()``); a backend's
    ``settings_with_equalities`` count only for QPs with equality rows (``equality_rows``: the full
    formulation; the condensed QP has none)."""
    try:
        d = ast.literal_eval(str(settings))
    except (ValueError, SyntaxError):
        return "—", "—"
    if not isinstance(d, dict):
        return "—", "—"
    native = dict(d.get("settings") or {})
    if equality_rows:
        native.update(dict(d.get("settings_with_equalities") or {}))
    tol = [f"{k}={v:g}" for k, v in native.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
           and (k.startswith("eps") or "tol" in k) and "iterative_refinement" not in k]  # fmt: skip
    check = d.get("check") or {}
    if isinstance(check, dict) and check:
        level = check.get("level", "kkt")
        tol.append(f"check {level}" + (f" primal {check.get('primal'):g}" if "primal" in check else ""))
    if d.get("kind") == "cross-checked reference":
        tol.append(f"agree {d.get('agree_u_nm'):g} N·m")
    return str(d.get("kind", "—")), ", ".join(tol) if tol else "solver defaults"


def _rate(mask: np.ndarray) -> float:
    return float(np.mean(mask)) if mask.size else math.nan


def verdict_rows(sweep_dir: Path, frame: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """One row per (world, backend label): the columns of the module doc."""
    done = frame[frame["status"].isin(FINISHED)] if "status" in frame else frame.iloc[0:0]
    done = done[done.get("solver", pd.Series(dtype=str)).notna() & (done.get("solver") != "none")]
    if done.empty or "run_dir" not in done:
        return pd.DataFrame()
    other = _varied(done, keys)
    labels = done.apply(lambda r: _label(r, other), axis=1)
    groups = [(scenario, label, runs, _ticks(sweep_dir, runs))
              for (scenario, label), runs in done.groupby([done["scenario"], labels], sort=True)]  # fmt: skip
    timing = {w: _timing([t for s, _, _, t in groups if s == w]) for w in {g[0] for g in groups}}
    return pd.DataFrame([_row(str(scenario), str(label), runs, t, timing[scenario], done[done["scenario"] == scenario])
                         for scenario, label, runs, t in groups])  # fmt: skip


def _row(scenario: str, label: str, runs: pd.DataFrame, t: dict[str, np.ndarray], timing: str,
         world: pd.DataFrame) -> dict[str, object]:  # fmt: skip
    """The verdict row of one backend in one world (``world``: every run of the world, for its machine load)."""
    solve, it, err = _solve_times(t, timing), t["qp_iterations"], t["qp_u_error_nm"]
    checked = err[np.isfinite(err)]
    period_us = 1e6 / float(runs["control_rate_hz"].astype(float).iloc[0]) if "control_rate_hz" in runs else ONE_MS_US
    tol_nm = float(runs["qp_reference_tol_nm"].astype(float).iloc[0]) if "qp_reference_tol_nm" in runs else math.nan
    condensed = "filter_formulation" in runs and str(runs["filter_formulation"].iloc[0]) == "condensed"
    route, tol = _tolerances(runs["solver_settings"].iloc[0] if "solver_settings" in runs else "", not condensed)
    setup = t["qp_setup"] == 1  # the first solve of a new QP layout (NaN in runs that did not record it)
    s = solve[np.isfinite(solve) & ~setup]
    setups = solve[np.isfinite(solve) & setup]
    wall = t["qp_solve_us"][np.isfinite(t["qp_solve_us"]) & ~setup]
    busy, share = _machine(world)
    return {
        "scenario": scenario, "backend": label, "runs": len(runs), "ticks": int(t["qp_status"].size),
        "success_rate": _rate(t["qp_status"] == 0),
        "wrong_rate": _rate(checked > tol_nm) if checked.size else math.nan,
        "checks": int(checked.size),
        "u_err_p99_nm": float(np.percentile(checked, 99)) if checked.size else math.nan,
        "u_err_max_nm": float(checked.max()) if checked.size else math.nan,
        "solve_p50_us": float(np.median(s)) if s.size else math.nan,
        "solve_p99_us": float(np.percentile(s, 99)) if s.size else math.nan,
        "solve_max_us": float(s.max()) if s.size else math.nan,
        "miss_period_rate": _rate(s > period_us), "miss_1ms_rate": _rate(s > ONE_MS_US),
        "setups": int(setups.size), "setup_max_us": float(setups.max()) if setups.size else math.nan,
        "wall_p99_us": float(np.percentile(wall, 99)) if wall.size else math.nan,
        "wall_miss_period_rate": _rate(wall > period_us),
        "iterations": float(np.median(it[it >= 0])) if np.any(it >= 0) else math.nan,
        "rtf": float(runs["real_time_factor"].astype(float).mean()) if "real_time_factor" in runs else math.nan,
        "route": route, "tolerances": tol, "timing": timing, "machine_busy": busy, "cpu_share": share,
        "period_us": period_us,
    }  # fmt: skip


def _timing(world_ticks: list[dict[str, np.ndarray]]) -> str:
    """:data:`THREAD_CPU` when every backend of the world has thread CPU times for its solves (so they are
    ranked on one measurement), else :data:`WALL` (runs recorded before the CPU times existed)."""
    has_cpu = all(np.isfinite(t["qp_solve_cpu_us"][np.isfinite(t["qp_solve_us"])]).all() and t["qp_solve_us"].size
                  for t in world_ticks)  # fmt: skip
    return THREAD_CPU if has_cpu else WALL


def _machine(world: pd.DataFrame) -> tuple[bool, float]:
    """(a run of the world had a busy machine, the lowest CPU share of its runs)."""
    share = float(pd.to_numeric(world["machine_cpu_share"], errors="coerce").min()) if "machine_cpu_share" in world \
        else math.nan
    busy = "machine_busy" in world and bool(world["machine_busy"].fillna(False).astype(bool).any())
    return busy, share


def _solve_times(ticks: dict[str, np.ndarray], timing: str) -> np.ndarray:
    """[µs] per solve: the thread's CPU time over the backend's timed interval (:data:`THREAD_CPU`; never
    above the wall timer), or the backend's wall timer."""
    wall = ticks["qp_solve_us"]
    if timing == WALL:
        return wall
    return np.where(np.isfinite(wall), np.fmin(wall, ticks["qp_solve_cpu_us"]), np.nan)


def _setups_text(r: pd.Series) -> str:
    """`` (its 2 first builds of a QP layout judged apart: up to 1321 µs)``; "" if none."""
    if not r.get("setups"):
        return ""
    return (f" (its {int(r['setups'])} first build(s) of a QP layout judged apart: up to "
            f"{r['setup_max_us']:.0f} µs)")


def _busy_note(rows: pd.DataFrame) -> str:
    """What the sentence says first when a run of the world had a busy machine ("" otherwise)."""
    if "machine_busy" not in rows or not rows["machine_busy"].any():
        return ""
    share = float(rows["cpu_share"].min())
    if (rows["timing"] == THREAD_CPU).all():
        return f"machine busy: CPU share {share:.2f} -- deadline figures from thread CPU time. "
    return (f"machine busy: CPU share {share:.2f} -- no thread CPU times recorded, the deadline figures are the "
            f"wall clock's and include the waits for a CPU. ")


def _qualifies(r: pd.Series) -> bool:
    """No failed solve, no wrong answer (with reference checks), no deadline miss at the control period."""
    return bool(
        r["success_rate"] == 1.0 and r["checks"] > 0 and r["wrong_rate"] == 0.0 and r["miss_period_rate"] == 0.0
    )


def _why_not(r: pd.Series) -> str:
    parts = []
    if r["success_rate"] != 1.0:
        parts.append(f"{1 - r['success_rate']:.2%} failed solves")
    if r["checks"] == 0:
        parts.append("no reference checks")
    elif r["wrong_rate"] != 0.0:
        parts.append(f"{r['wrong_rate']:.2%} wrong answers (u error up to {r['u_err_max_nm']:.2g} N·m)")
    if r["miss_period_rate"] != 0.0:
        parts.append(f"{r['miss_period_rate']:.2%} solves over the {r['period_us']:.0f} µs period")
    return ", ".join(parts)


def _sentence(world: str, rows: pd.DataFrame) -> str:
    ok = rows[rows.apply(_qualifies, axis=1)].sort_values("solve_p99_us")
    out = rows[~rows.index.isin(ok.index)]
    rejected = "; ".join(f"{r['backend']}: {_why_not(r)}" for _, r in out.iterrows() if _why_not(r))
    if ok.empty:
        right = rows[(rows["success_rate"] == 1.0) & (rows["checks"] > 0) & (rows["wrong_rate"] == 0.0)]
        closest = ""
        if len(right):
            c = right.sort_values(["miss_period_rate", "solve_p99_us"]).iloc[0]
            closest = (f" Closest: **{c['backend']}**, no failed solve and no wrong answer, the fewest solves over "
                       f"the period ({c['miss_period_rate']:.2%}; median {c['solve_p50_us']:.0f} µs, p99 "
                       f"{c['solve_p99_us']:.0f} µs).")
        return (f"**{world}**: {_busy_note(rows)}no backend qualifies" + (f" ({rejected})." if rejected else ".")
                + closest)
    best = ok.iloc[0]
    text = (f"**{world}**: {_busy_note(rows)}ship **{best['backend']}** -- the fastest (solve p99 "
            f"{best['solve_p99_us']:.0f} µs, median {best['solve_p50_us']:.0f} µs, max {best['solve_max_us']:.0f} µs) "
            f"of the {len(ok)} backend(s) with no failed solve, no wrong answer in {int(best['checks'])} reference "
            f"checks (u error <= {best['u_err_max_nm']:.1g} N·m) and no solve over the {best['period_us']:.0f} µs "
            f"control period"
            + _setups_text(best))
    return text + (f". Not qualified: {rejected}." if rejected else ".")


def solver_verdict(sweep_dir: Path, frame: pd.DataFrame, keys: list[str]) -> tuple[str, pd.DataFrame]:
    """(markdown section, the verdict rows); empty when the sweep has no filtered runs."""
    rows = verdict_rows(Path(sweep_dir), frame, keys)
    if rows.empty:
        return "", rows
    lines = ["## Solver verdict: which backend to ship\n",
             ("Per world, one row per backend (seeds pooled, backends never): per-tick rates over the filtered "
             "ticks of its finished runs. `wrong_rate`: share of the reference-checked ticks "
             "(`record.reference_every`) whose solved u is off the tight reference (quadprog x DAQP) by more than "
             "`record.reference_tol_nm`; `u_err_*`: max_j |u_j - u_ref,j| on those ticks; `solve_*`: the backend's "
             "thread CPU time over the backend's timed interval (`timing`; the wall clock, `wall_*`, also counts waits "
             "for a CPU); `miss_period_rate` / `miss_1ms_rate`: solves longer than the control period / 1 ms; "
             "`route`: persistent (set up once, updated every tick) or qpsolvers (set up every call). The backend "
             "to ship is the fastest by solve p99 among those with no failed solve, no wrong answer and no "
             "deadline miss.\n")]
    shown = [c for c in rows.columns if c not in ("scenario", "period_us", "cpu_share", "machine_busy")]
    for world, g in rows.groupby("scenario", sort=True):
        lines += [f"### {world}\n", markdown_table(g[shown]), _sentence(str(world), g) + "\n"]
    lines.append(_overall(rows))
    return "\n".join(lines), rows


def _overall(rows: pd.DataFrame) -> str:
    worlds = rows["scenario"].nunique()
    quals = rows[rows.apply(_qualifies, axis=1)]
    counts = quals.groupby("backend")["scenario"].nunique()
    everywhere = counts[counts == worlds].index
    if not len(everywhere):
        return f"**Over the sweep** ({worlds} world(s)): no backend qualifies in every world.\n"
    worst = quals[quals["backend"].isin(everywhere)].groupby("backend")["solve_p99_us"].max().sort_values()
    return (f"**Over the sweep** ({worlds} world(s)): ship **{worst.index[0]}**, qualified in every world with the "
            f"lowest worst-world solve p99 ({worst.iloc[0]:.0f} µs)"
            + (f"; next: {', '.join(f'{b} ({v:.0f} µs)' for b, v in worst.iloc[1:].items())}" if len(worst) > 1 else "")
            + ".\n")


def machine_busy_line(frame: pd.DataFrame) -> str:
    """The report's line on runs measured on a busy machine ("" if none: every run had its CPU)."""
    if "machine_busy" not in frame:
        return ""
    busy = frame[frame["machine_busy"].fillna(False).astype(bool)]
    if busy.empty:
        return ""
    share = pd.to_numeric(busy.get("machine_cpu_share", pd.Series(dtype=float)), errors="coerce").min()
    return (f"**Machine busy** during {len(busy)} of {len(frame)} runs (their loop had a CPU {share:.0%} of the time "
            f"at the least): their wall-clock timings (tick, real-time factor, `wall_*`) measure the machine, not "
            f"the code; the solver verdict's deadline figures are the solves' thread CPU time.\n")


def solve_time_figure(sweep_dir: Path, frame: pd.DataFrame, keys: list[str], plt) -> list[str]:
    """``qp_solve_times.png`` (module doc); nothing when no run has solve times."""
    done = frame[frame["status"].isin(FINISHED)] if "status" in frame else frame.iloc[0:0]
    done = done[done.get("solver", pd.Series(dtype=str)).notna() & (done.get("solver") != "none")]
    if done.empty or "run_dir" not in done:
        return []
    other = _varied(done, keys)
    labels = done.apply(lambda r: _label(r, other), axis=1)
    worlds = sorted(done["scenario"].astype(str).unique())
    data = {w: {lab: _ticks(sweep_dir, runs)["qp_solve_us"]
                for lab, runs in done[done["scenario"] == w].groupby(labels)} for w in worlds}  # fmt: skip
    if not any(np.isfinite(t).any() for d in data.values() for t in d.values()):
        return []
    period = 1e6 / float(done["control_rate_hz"].astype(float).iloc[0]) if "control_rate_hz" in done else ONE_MS_US
    fig, axes = plt.subplots(1, len(worlds), figsize=(4.2 * len(worlds) + 1, 3.4), squeeze=False, sharey=True)
    for ax, w in zip(axes[0], worlds, strict=True):
        for lab, t in sorted(data[w].items()):
            t = np.sort(t[np.isfinite(t)])
            if not t.size:
                continue
            y = np.arange(1, t.size + 1) / t.size
            line = ax.step(t, y, where="post", lw=1, label=lab)[0]
            p99 = np.percentile(t, 99)
            ax.plot([p99], [0.99], "o", ms=4, color=line.get_color())
            ax.plot([t[-1]], [1.0], "x", ms=6, color=line.get_color())
        ax.axvline(period, color="k", ls="--", lw=0.8, label=f"control period {period:.0f} µs")
        ax.set_xscale("log")
        ax.set_xlabel("QP solve time per tick [µs]")
        ax.set_title(w, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("share of ticks solved within")
    axes[0][-1].legend(fontsize=6, loc="lower right")
    fig.suptitle("QP solve time, every tick (ECDF; o: p99, x: max; backend timer)", fontsize=9)
    fig.tight_layout()
    fig.savefig(Path(sweep_dir) / FIGURE, dpi=120)
    plt.close(fig)
    return [FIGURE]


__all__ = ["machine_busy_line", "solve_time_figure", "solver_verdict", "verdict_rows"]
