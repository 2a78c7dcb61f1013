"""Tables and figure of a QP replay (:mod:`taslel_bench.qp.replay`), qpbenchmark style.

    python -m taslel_bench.replay_report <folder with replay_qps.parquet files> [-o out]

Writes ``report.md``, ``results.csv`` (one row per backend x profile x mode), ``overhead.csv`` and
``solve_times.png``. Success / correctness come from the first pass (the report checks that every pass
agrees); timings are per pass and shown as the median over passes with the (min-max) over passes.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from taslel_bench.record import run_files
from taslel_bench.util.machine import machine_info
from taslel_bench.util.stats import SHGEOM_SHIFT_US, shifted_geometric_mean
from taslel_bench.util.tables import markdown_table

if TYPE_CHECKING:
    from pandas.api.typing import DataFrameGroupBy

QP_TABLE = "replay_qps.parquet"  # per QP x backend x profile x mode x pass, in a job folder
JOB_INFO = "replay_job.json"  # the job's backend, settings and machine
KEYS = ["solver", "profile", "mode"]
US = 1e6


def load_tables(folder: Path) -> tuple[pd.DataFrame, list[dict]]:
    files = sorted(Path(folder).rglob(QP_TABLE))
    if not files:
        raise FileNotFoundError(f"no {QP_TABLE} under {folder}")
    infos = [json.loads(f.with_name(JOB_INFO).read_text()) for f in files if f.with_name(JOB_INFO).is_file()]
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True), infos


def _spread(per_pass: pd.Series, fmt: str = "{:.0f}") -> str:
    """median over passes (min-max)."""
    v = per_pass.to_numpy(float)
    if v.size == 0 or not np.isfinite(v).any():
        return "-"
    if v.size == 1:
        return fmt.format(v[0])
    return f"{fmt.format(np.median(v))} ({fmt.format(v.min())}-{fmt.format(v.max())})"


def summarize(frame: pd.DataFrame, deadlines_hz: tuple[float, ...] = (1000.0, 500.0)) -> pd.DataFrame:
    """One row per backend x profile x mode (unavailable ones included with their reason)."""
    rows = [_summarize_group(key, g, deadlines_hz) for key, g in frame.groupby(KEYS, sort=False)]
    return _add_shgeom_rel(pd.DataFrame(rows))


def _summarize_group(key: tuple, g: pd.DataFrame, deadlines_hz: tuple[float, ...]) -> dict:
    """The summary row of one backend x profile x mode: its status (the reason when it did not run), else
    outcome, solve times [µs], deadline misses [%] at each rate [Hz] and the per-QP cost breakdown [µs]."""
    row = dict(zip(KEYS, key, strict=True))
    row["backend"] = g["backend"].iloc[0] if "backend" in g else ""
    if (g["qp"] < 0).all():
        row["status"] = str(g["status"].iloc[0])
        return row
    row["status"] = "ran"
    first = g[g["repeat"] == 0]
    per_pass = g.groupby("repeat")
    row.update(_outcome_columns(g, first))
    row.update(_solve_time_columns(per_pass))
    row.update(_deadline_columns(g, per_pass, row["passes"], deadlines_hz))
    row.update(_cost_columns(per_pass))
    row["iterations_median"] = float(first["iterations"].median())
    row.update(_spread_columns(row))
    row["settings"] = g["settings"].iloc[0] if "settings" in g else ""
    return row


def _outcome_columns(g: pd.DataFrame, first: pd.DataFrame) -> dict:
    """Passes, whether every pass gives the same success / correctness per QP, and the first pass's
    success / correctness rates [%], solved-but-wrong count and largest |du| of the solved QPs [N·m]."""
    outcome = g.pivot_table(index="qp", columns="repeat", values=["success", "correct"], aggfunc="first")
    solved = first["success"]
    return {
        "passes": int(g["repeat"].nunique()),
        "passes_agree": bool(all((outcome[c].nunique(axis=1) == 1).all()  # pyright: ignore[reportCallIssue] pandas-stubs: df[key] is a Series, but on these MultiIndex columns a DataFrame
                                 for c in ("success", "correct"))),
        "n": len(first),
        "success_pct": 100.0 * solved.mean(),
        "correct_pct": 100.0 * first["correct"].mean(),
        "wrong_but_solved": int((solved & ~first["correct"]).sum()),
        "max_du_nm": float(first.loc[solved, "du_nm"].max()) if solved.any() else np.nan,
    }


def _solve_time_columns(per_pass: DataFrameGroupBy) -> dict:
    """Native solve time [µs]: median / p99 / max and shifted geometric mean of each pass, as the median
    over passes with the min and max over passes (``*_min``, ``*_max``)."""
    cols: dict[str, float] = {}
    for q, name in ((50, "median"), (99, "p99"), (100, "max")):
        s = per_pass["solve_s"].apply(lambda v, q=q: np.percentile(v, q) * US)
        cols[f"solve_{name}_us"] = float(np.median(s))
        cols[f"solve_{name}_us_min"], cols[f"solve_{name}_us_max"] = float(s.min()), float(s.max())
    sg = per_pass["solve_s"].apply(lambda v: shifted_geometric_mean(v.to_numpy() * US))
    cols["shgeom_us"], cols["shgeom_us_min"], cols["shgeom_us_max"] = float(np.median(sg)), sg.min(), sg.max()
    return cols


def _deadline_columns(
    g: pd.DataFrame, per_pass: DataFrameGroupBy, passes: int, deadlines_hz: tuple[float, ...]
) -> dict:
    """p99 solve time [µs] of each QP's fastest pass, and per rate [Hz] the deadline-miss rate [%] (build +
    native solve > one period): with each QP's fastest pass, median over passes (and its spread), and with
    the Python call instead of the native solve."""
    # per-QP minimum over passes: filters out OS preemption on this shared machine (a stall rarely hits
    # the same QP in every pass); compare with the raw per-pass numbers to see the noise
    best = g.groupby("qp")[["solve_s", "build_s"]].min()
    cols: dict[str, object] = {
        "solve_p99_us_minpass": float(np.percentile(best["solve_s"], 99) * US) if passes > 1 else np.nan
    }
    for hz in deadlines_hz:
        period = 1.0 / hz
        best_miss = best["build_s"] + best["solve_s"] > period
        cols[f"miss_{hz:g}hz_minpass_pct"] = 100.0 * float(np.mean(best_miss))
        miss = per_pass.apply(lambda d, p=period: 100.0 * np.mean(d["build_s"] + d["solve_s"] > p))
        miss_py = per_pass.apply(lambda d, p=period: 100.0 * np.mean(d["build_s"] + d["call_s"] > p))
        cols[f"miss_{hz:g}hz_pct"] = float(np.median(miss))
        cols[f"miss_{hz:g}hz_pct_spread"] = _spread(miss, "{:.2f}")
        cols[f"miss_{hz:g}hz_python_pct"] = float(np.median(miss_py))
    return cols


def _cost_columns(per_pass: DataFrameGroupBy) -> dict:
    """Median per QP [µs] (median over QPs, then over passes) of the recorded QP build, the native solve,
    the backend's overhead, the rest of the Python call (dispatch), the whole call and the replay's check."""
    med = per_pass[["build_s", "solve_s", "overhead_s", "call_s", "check_s"]].median().median() * US
    disp = per_pass.apply(lambda d: np.median(d["call_s"] - d["solve_s"] - d["overhead_s"].fillna(0.0)) * US)
    return {
        "build_us": med["build_s"],
        "native_us": med["solve_s"],
        "backend_overhead_us": med["overhead_s"],
        "dispatch_us": float(np.median(disp)),
        "call_us": med["call_s"],
        "check_us": med["check_s"],
    }


def _spread_columns(row: dict) -> dict:
    """Solve-time cells as text [µs]: median over passes (min-max), or the one pass's value."""
    cols = {}
    for k in ("solve_median_us", "solve_p99_us", "solve_max_us", "shgeom_us"):
        cols[k + "_spread"] = _spread(pd.Series([row[k + "_min"], row[k], row[k + "_max"]])
                                      if row["passes"] > 1 else pd.Series([row[k]]))  # fmt: skip
    return cols


def _add_shgeom_rel(out: pd.DataFrame) -> pd.DataFrame:
    """Add ``shgeom_rel``: the shifted geometric mean relative to the best of its profile (when any ran)."""
    if "shgeom_us" in out:
        best = out.groupby("profile")["shgeom_us"].transform("min")
        out["shgeom_rel"] = (out["shgeom_us"] + SHGEOM_SHIFT_US) / (best + SHGEOM_SHIFT_US)
    return out


def _pivot(summary: pd.DataFrame, value: str, fmt: str, second: str | None = None) -> pd.DataFrame:
    """Rows: solver; columns: profile / mode (qpbenchmark's layout); unavailable cells '-'. With ``second``:
    cells "value / second"."""
    s = summary.copy()

    def f(v: object) -> str:
        return fmt.format(v) if isinstance(v, float) and np.isfinite(v) else "-"

    missing = pd.Series(np.nan, index=s.index)  # a column no backend wrote (none ran): every cell '-'
    cells = [f(v) for v in s.get(value, missing)]
    if second is not None:
        cells = [c if c == "-" else f"{c} / {f(w)}" for c, w in zip(cells, s.get(second, missing), strict=True)]
    s["cell"] = cells
    s["column"] = s["profile"] + " / " + s["mode"]
    cols = list(dict.fromkeys(s["column"]))
    return s.pivot(index="solver", columns="column", values="cell").reindex(columns=cols).fillna("-")


def _md(frame: pd.DataFrame, index: bool = True) -> str:
    return markdown_table(frame.reset_index() if index else frame, fmt=str).rstrip("\n")


def _figure(frame: pd.DataFrame, out: Path) -> str | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    ran = frame[frame["qp"] >= 0]
    profiles = list(dict.fromkeys(ran["profile"]))
    fig, axes = plt.subplots(1, len(profiles), figsize=(7 * len(profiles), 5), squeeze=False, sharey=True)
    for ax, prof in zip(axes[0], profiles, strict=True):
        sub = ran[ran["profile"] == prof]
        colors = {name: f"C{k % 10}" for k, name in enumerate(sorted(ran["solver"].unique()))}
        for (solver, mode), g in sub.groupby(["solver", "mode"]):
            t = np.sort(g["solve_s"].to_numpy() * US)
            ls = {"cold": ":", "warm": "--", "persistent": "-"}.get(mode, "-")
            ax.plot(t, np.arange(1, t.size + 1) / t.size, ls, color=colors[solver], label=f"{solver} {mode}")
        for hz, c, y in ((1000, "red", 0.02), (500, "orange", 0.07)):
            ax.axvline(1e6 / hz, color=c, lw=0.8)
            ax.text(1e6 / hz, y, f" {hz} Hz period", color=c, fontsize=8)
        ax.set_xscale("log")
        ax.set_xlabel("solve time [µs] (native call, all passes)")
        ax.set_title(f"profile: {prof}")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("fraction of QPs solved within")
    axes[0][-1].legend(fontsize=7, ncol=2, loc="lower right")
    fig.tight_layout()
    path = out / "solve_times.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def write_report(folder: Path, out: Path | None = None) -> Path:
    """Summarise every replay table under ``folder`` into ``out`` (default ``folder``)."""
    out = Path(out or folder)
    out.mkdir(parents=True, exist_ok=True)
    frame, infos = load_tables(Path(folder))
    summary = summarize(frame, _deadlines_hz(infos))
    run_files.atomic_write(out / "results.csv", lambda p: summary.to_csv(p, index=False))
    overhead = _overhead_table(summary)
    run_files.atomic_write(out / "overhead.csv", lambda p: overhead.round(2).to_csv(p, index=False))
    fig = _figure(frame, out)
    info = infos[0] if infos else {}
    lines = _intro_lines(frame, info, machine_info())
    lines += _rate_lines(summary)
    lines += _profile_lines(summary)
    lines += _overhead_lines(overhead)
    lines += _not_run_lines(summary)
    if fig:
        lines += ["## Solve-time distributions", "", f"![solve times]({fig})", ""]
    lines += _settings_lines(summary)
    path = out / "report.md"
    run_files.atomic_write(path, lambda p: p.write_text("\n".join(lines) + "\n"))
    return path


def _deadlines_hz(infos: list[dict]) -> tuple[float, ...]:
    """The deadline rates [Hz] of the first job's config (default 1000 and 500 Hz)."""
    rates = infos[0]["config"].get("deadlines_hz", (1000, 500)) if infos else (1000, 500)
    return tuple(float(h) for h in rates)


def _overhead_table(summary: pd.DataFrame) -> pd.DataFrame:
    """The cost breakdown of the backends that ran [µs per QP], with the closed loop's share (``in_loop_us``
    = build + call) and the native solve's share of it [%]."""
    ran = summary[summary["status"] == "ran"]
    costs = ["build_us", "native_us", "backend_overhead_us", "dispatch_us", "call_us", "check_us"]
    overhead = ran[[*KEYS, "backend", *costs]].copy()
    overhead["in_loop_us"] = overhead["build_us"] + overhead["call_us"]
    overhead["native_share_pct"] = 100.0 * overhead["native_us"] / overhead["in_loop_us"]
    return overhead


def _intro_lines(frame: pd.DataFrame, info: dict, m: dict) -> list[str]:
    """Title, provenance (time, code, test set, tolerances, passes), machine ``m``, modes and profiles."""
    cfg = info.get("config", {})
    scen = frame[frame["qp"] >= 0].drop_duplicates("qp")["scenario"].value_counts().to_dict()
    return [
        "# QP replay benchmark",
        "",
        (f"Generated {dt.datetime.now().isoformat(timespec='seconds')} by `python -m taslel_bench.replay`, "
         f"{m['code']}."),
        f"Test set: `{Path(info.get('testset', '?')).name}`, {info.get('n_qps', '?')} QPs from "
        f"{len(info.get('runs', []))} closed-loop runs; replayed per scenario: "
        + ", ".join(f"{k} {v}" for k, v in scen.items())
        + f"; QPs without a reference (excluded): {int(frame['n_without_reference'].max())}.",
        f"Correctness tolerances (checked by the replay, not the backend): {cfg.get('tolerances', {})}.",
        f"Passes: {cfg.get('repeats', '?')}; timings are median over passes (min-max over passes).",
        "",
        (f"Machine: {m['cpu']}, {m['cores']} cores, {m['os']}, Python {m['python']} "
        "(shared with other jobs: absolute times are noisy, compare within a table)."),
        f"Versions: {m['packages']}.",
        "",
        ("Modes: **cold** = reset before every QP (no guess, set up from scratch); **warm** = previous "
         "tick's answer as initial guess (qpsolvers `initvals`); **persistent** = native solver set up once "
         "per layout, values updated in place and warm started. Profiles: **default** = the solver's own "
         "settings and no answer check inside the backend (success = the solver says solved); "
         "**high_accuracy** = `conf/solver/*.yaml` as a closed-loop sweep uses them (tuned tolerances, "
         "backend answer check on)."),
        "",
    ]  # fmt: skip


def _rate_lines(summary: pd.DataFrame) -> list[str]:
    """The solver x (profile / mode) tables: success and correctness rates [%], relative shifted geometric
    mean of the solve time, deadline-miss rates [%] at 1 kHz and 500 Hz."""
    return [
        "## Success rate [%] (backend status `solved`)",
        "",
        _md(_pivot(summary, "success_pct", "{:.2f}")),
        "",
        "## Correctness rate [%] (u within tolerance of the reference AND residuals/gap within tolerance)",
        "",
        _md(_pivot(summary, "correct_pct", "{:.2f}")),
        "",
        (f"## Shifted geometric mean of solve time, relative to the best of its profile "
         f"(shift {SHGEOM_SHIFT_US:g} µs)"),
        "",
        _md(_pivot(summary, "shgeom_rel", "{:.1f}")),
        "",
        "## Deadline-miss rate [%] at 1 kHz (recorded build time + native solve time > 1 ms)",
        "",
        ("Cells: median over passes / with each QP's fastest pass (the second filters out stalls of this "
         "shared 2-core machine: the slow solves have the same iteration counts as the typical ones)."),
        "",
        _md(_pivot(summary, "miss_1000hz_pct", "{:.2f}", "miss_1000hz_minpass_pct")),
        "",
        "## Deadline-miss rate [%] at 500 Hz (> 2 ms)",
        "",
        _md(_pivot(summary, "miss_500hz_pct", "{:.2f}", "miss_500hz_minpass_pct")),
        "",
    ]  # fmt: skip


def _profile_lines(summary: pd.DataFrame) -> list[str]:
    """One section per settings profile: the table of the backends that ran with it."""
    lines: list[str] = []
    for prof in dict.fromkeys(summary["profile"]):
        s = summary[(summary["profile"] == prof) & (summary["status"] == "ran")]
        lines += [f"## Settings profile `{prof}`", "", _md(_profile_table(s), index=False), ""]
    return lines


def _profile_table(s: pd.DataFrame) -> pd.DataFrame:
    """The displayed columns of summary rows ``s``: rates [%], largest |du| [N·m], solve times [µs] as
    median (min-max) over passes, relative shifted geometric mean, deadline misses [%], pass agreement."""
    return pd.DataFrame({
        "solver": s["solver"], "mode": s["mode"], "success %": s["success_pct"].round(2),
        "correct %": s["correct_pct"].round(2), "solved but wrong": s["wrong_but_solved"].astype(int),
        "max abs du [N·m]": s["max_du_nm"].map(lambda v: f"{v:.1e}"),
        "median [µs]": s["solve_median_us_spread"], "p99 [µs]": s["solve_p99_us_spread"],
        "max [µs]": s["solve_max_us_spread"],
        "p99 fastest pass [µs]": s["solve_p99_us_minpass"].round(0), "shgeom [µs]": s["shgeom_us_spread"],
        "shgeom rel": s["shgeom_rel"].round(1), "miss 1 kHz %": s["miss_1000hz_pct_spread"],
        "miss 500 Hz %": s["miss_500hz_pct_spread"],
        "miss 1 kHz % (Python call)": s["miss_1000hz_python_pct"].round(2),
        "passes agree": s["passes_agree"],
    })  # fmt: skip


def _overhead_lines(overhead: pd.DataFrame) -> list[str]:
    """The harness-overhead section: the cost breakdown [µs per QP] of profile high_accuracy (of every
    profile when high_accuracy did not run), rounded to 0.1 µs."""
    has_ha = (overhead["profile"] == "high_accuracy").any()
    oh = overhead[overhead["profile"] == "high_accuracy"] if has_ha else overhead
    oh = oh.drop(columns=["profile"]).round(1)
    return [
        "## Harness overhead vs native solve (median per QP [µs], profile high_accuracy)",
        "",
        ("`build` = the filter writing the QP, measured in the recorded runs; `native` = the timed solver "
         "call (`solve_time_s`: for qpsolvers backends it includes qpsolvers' own packing and the solver "
         "setup; for persistent ones the in-place update + solve); `backend overhead` = conversions + the "
         "backend's answer check (`overhead_s`); `dispatch` = the rest of the Python `solve()` call; "
         "`in loop` = build + call, what the Python closed loop pays; `check` = the replay's own correctness "
         "check (not in the loop). A C++ deployment would pay roughly build (~C++ speed) + native."),
        "",
        _md(oh, index=False),
        "",
    ]  # fmt: skip


def _not_run_lines(summary: pd.DataFrame) -> list[str]:
    """The "Not run" section (backend / profile / mode: reason), empty when everything ran."""
    unavailable = summary[summary["status"] != "ran"]
    if unavailable.empty:
        return []
    return ["## Not run", ""] + [f"- {r.solver} / {r.profile} / {r.mode}: {r.status}"
                                 for r in unavailable.itertuples()] + [""]  # fmt: skip


def _settings_lines(summary: pd.DataFrame) -> list[str]:
    """The "Settings in force" section: the settings of each backend / profile / mode that ran."""
    lines = ["## Settings in force", ""]
    for r in summary[summary["status"] == "ran"].drop_duplicates(["solver", "profile", "mode"]).itertuples():
        lines.append(f"- {r.solver} / {r.profile} / {r.mode}: `{r.settings}`")
    return lines


OUTCOME = ["success_pct", "correct_pct", "wrong_but_solved"]


def compare(first: Path, second: Path) -> tuple[bool, str]:
    """Do two replays' ``results.csv`` give the same success / correctness tables? (identical?, markdown)"""
    a, b = (pd.read_csv(p) for p in (first, second))
    a, b = (f[f["status"] == "ran"].set_index(KEYS)[OUTCOME].sort_index() for f in (a, b))
    joined = a.join(b.add_suffix(" (2nd)"), how="outer")
    same = bool(a.index.equals(b.index) and np.array_equal(a.to_numpy(), b.to_numpy()))
    return same, _md(joined.round(3))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("-o", "--out", type=Path, default=None)
    ap.add_argument("--compare", type=Path, default=None,
                    help="another replay's results.csv: print whether success/correctness tables are identical")
    args = ap.parse_args(argv)
    if args.compare is not None:
        same, table = compare(args.folder / "results.csv", args.compare)
        print(f"success/correctness tables identical: {same}\n\n{table}")
        raise SystemExit(0 if same else 1)
    print(write_report(args.folder, args.out))


if __name__ == "__main__":
    main()
