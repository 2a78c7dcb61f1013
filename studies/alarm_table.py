"""Alarms that mean danger: which runs the health checks flag, against which runs were unsafe.

    python -m studies.alarm_table SWEEP_DIR... [--out results/alarms]
    python -m studies.alarm_table results/alarms/summary.parquet     # the table again from the shipped runs

Reads each sweep folder's ``summary.parquet`` (or a summary.parquet given itself): runs of
``+experiment=terrain`` with ``+filter_variant`` paper / terrain and ``+mismatch_plant`` none / lossy / mass / com.
The runs on the URDF plant (``none``: the filter's model is the plant) are the calibration set: the limit of each
promise check (:mod:`taslel_bench.metrics.health`) is :data:`CALIBRATION_MARGIN` x the largest value any safe
calibration run reached (a margin for seeds and worlds not seen), rounded up to 0.01; the plants that are not their
URDF are the evaluation set, never used to compute a limit (the margin itself was fixed after a first look at part of
the runs: results/alarms/README.md). For each rule the table counts runs x {safe, unsafe} x {flagged, not}, per plant
and filter:

* ``residual`` -- the model-residual alarm alone (``residual_alarm_rate`` over its limit);
* ``degraded (before)`` -- the health rule before the promise checks: the guarantee checks of that rule and the
  residual alarm;
* ``degraded`` -- the guarantee checks with the promise checks at their calibrated limits (the residual reported
  as model error, not degrading).

Target: every unsafe run flagged, at most 10 % of the safe runs flagged.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd

from taslel_bench.metrics.health import GUARANTEE_CHECKS, MODEL_CHECKS, HealthLimits
from taslel_bench.util.machine import machine_info
from taslel_bench.util.provenance import describe

PROMISE_KEYS = ("filter_promise_cone_edge_rate_worst_window", "filter_promise_stance_in_air_rate_worst_window")
PLANT_ORDER = ("none", "lossy", "mass", "com")
FILTER_ORDER = ("paper", "terrain")
CALIBRATION_MARGIN = 2.0  # [-] a promise limit = this x the largest value of a safe run on the URDF plant


def load(sweeps: list[Path]) -> pd.DataFrame:
    frames = [pd.read_parquet(s if s.suffix == ".parquet" else s / "summary.parquet") for s in map(Path, sweeps)]
    df = pd.concat(frames, ignore_index=True)
    df["plant"] = df["run_dir"].str.extract(r"mismatch_plant=(\w+)")[0]
    df["filter"] = df["run_dir"].str.extract(r"filter_variant=(\w+)")[0]
    df["world"] = np.where(df["run_dir"].str.contains("scenario.friction=0.3"), "low_friction 0.3",
                           df["run_dir"].str.extract(r"scenario=(\w+)")[0])
    return df


def _over(df: pd.DataFrame, key: str, limit: float) -> pd.Series:
    values = pd.to_numeric(df.get(key), errors="coerce") if key in df else pd.Series(np.nan, index=df.index)
    return values.fillna(-math.inf) > limit


def calibrated_limits(df: pd.DataFrame) -> dict[str, float]:
    """Each promise check's limit: :data:`CALIBRATION_MARGIN` x the largest value a safe run on the URDF plant
    reached, rounded up to 0.01."""
    calibration = df[(df["plant"] == "none") & df["safe"].astype(bool)]
    return {key: math.ceil(CALIBRATION_MARGIN * float(calibration[key].max()) * 100 - 1e-9) / 100
            for key in PROMISE_KEYS}


def flags(df: pd.DataFrame, limits: dict[str, float]) -> dict[str, pd.Series]:
    """rule -> (runs) flagged."""
    health = HealthLimits()
    before = pd.Series(False, index=df.index)
    for key, (attr, _) in {**GUARANTEE_CHECKS, **MODEL_CHECKS}.items():
        if key not in PROMISE_KEYS:
            before |= _over(df, key, getattr(health, attr))
    residual = pd.Series(False, index=df.index)
    for key, (attr, _) in MODEL_CHECKS.items():
        residual |= _over(df, key, getattr(health, attr))
    after = pd.Series(False, index=df.index)
    for key, (attr, _) in GUARANTEE_CHECKS.items():
        after |= _over(df, key, limits[key] if key in limits else getattr(health, attr))
    return {"residual": residual, "degraded (before)": before, "degraded": after}


def table(df: pd.DataFrame, rule_flags: dict[str, pd.Series]) -> list[str]:
    head = "| plant | filter | safe runs | unsafe runs | " + " | ".join(
        f"{r}: safe flagged | {r}: unsafe flagged" for r in rule_flags) + " |"
    lines = [head, "|" + "---|" * (4 + 2 * len(rule_flags))]
    for plant in PLANT_ORDER:
        for filt in FILTER_ORDER:
            sel = (df["plant"] == plant) & (df["filter"] == filt)
            safe, unsafe = sel & df["safe"].astype(bool), sel & ~df["safe"].astype(bool)
            cells = [f"{int((f & safe).sum())}/{int(safe.sum())} | {int((f & unsafe).sum())}/{int(unsafe.sum())}"
                     for f in rule_flags.values()]
            lines.append(f"| {plant} | {filt} | {int(safe.sum())} | {int(unsafe.sum())} | " + " | ".join(cells) + " |")
    return lines


def totals(df: pd.DataFrame, rule_flags: dict[str, pd.Series]) -> list[str]:
    evaluation = df["plant"] != "none"
    safe, unsafe = evaluation & df["safe"].astype(bool), evaluation & ~df["safe"].astype(bool)
    lines = ["| rule | safe runs flagged | unsafe runs flagged | unsafe runs missed |", "|---|---|---|---|"]
    for rule, f in rule_flags.items():
        missed = df.loc[unsafe & ~f, "run_dir"].tolist()
        lines.append(f"| {rule} | {int((f & safe).sum())}/{int(safe.sum())} "
                     f"({100 * (f & safe).sum() / max(int(safe.sum()), 1):.0f} %) | {int((f & unsafe).sum())}/"
                     f"{int(unsafe.sum())} | {len(missed)} |")
    return lines


def missed_runs(df: pd.DataFrame, flagged: pd.Series) -> list[str]:
    unsafe = (df["plant"] != "none") & ~df["safe"].astype(bool) & ~flagged
    return [f"- `{r.run_dir}`: {r.unsafe_reasons}" for r in df[unsafe].itertuples()]


def provenance(df: pd.DataFrame, sweeps: list[Path]) -> list[str]:
    commits = sorted({str(c)[:12] for c in df.get("git_commit", pd.Series(dtype=str)).dropna()})
    versions = {k: sorted({str(v) for v in df[k].dropna()}) for k in df.columns if k.endswith("_version")}
    return [f"Generated by `python -m studies.alarm_table {' '.join(str(s) for s in sweeps)}` ({describe()}) from "
            f"{len(df)} runs of commit(s) {', '.join(commits) or 'unknown'}.",
            f"- Machine: {machine_info()}.",
            "- Versions: " + (", ".join(f"{k} {'/'.join(v)}" for k, v in versions.items()) or "(not recorded)") + "."]


def _defaults_text() -> str:
    health = HealthLimits()
    return ", ".join(f"`{attr}` {getattr(health, attr):g}" for key, (attr, _) in GUARANTEE_CHECKS.items()
                     if key in PROMISE_KEYS)


def _defaults_match(limits: dict[str, float]) -> bool:
    health = HealthLimits()
    return all(getattr(health, GUARANTEE_CHECKS[key][0]) == value for key, value in limits.items())


def report(df: pd.DataFrame, sweeps: list[Path]) -> str:
    limits = calibrated_limits(df)
    rule_flags = flags(df, limits)
    out = ["# Alarms against danger: the health checks per plant and filter", "",
           *provenance(df, sweeps), "",
           "Promise limits calibrated on the safe runs of the URDF plant (the filter's model is the plant): "
           + ", ".join(f"`{k}` {v:g}" for k, v in limits.items()) + "; the defaults of `health` "
           + ("are these." if _defaults_match(limits) else "differ: " + _defaults_text()), "",
           "## The evaluation plants (lossy, mass, com) together", "", *totals(df, rule_flags), "",
           "## Per plant and filter (flagged / runs)", "", *table(df, rule_flags), "",
           "## Unsafe runs the guarantee checks did not flag", "", *(missed_runs(df, rule_flags["degraded"]) or
                                                                    ["(none)"]), ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweeps", nargs="+", type=Path, help="sweep folders, or summary.parquet files")
    parser.add_argument("--out", type=Path, default=None, help="folder for table.md and summary.parquet")
    args = parser.parse_args(argv)
    df = load(args.sweeps)
    text = report(df, args.sweeps)
    if args.out is None:
        print(text)
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(text)
    written = [args.out / "table.md"]
    if not all(s.suffix == ".parquet" for s in args.sweeps):  # the runs themselves, beside their table
        df.drop(columns=["plant", "filter", "world"]).to_parquet(args.out / "summary.parquet")
        written.append(args.out / "summary.parquet")
    print("wrote " + ", ".join(map(str, written)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
