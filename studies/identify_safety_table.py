"""The filter with the untold, the told and the identified model on the lossy plant, beside the URDF plant, from the
sweep folder of ``results/identify/README.md``: per world and case, seeds pooled (means over runs), the falls, the
cone-edge share of loaded contacts (|f_t| >= 0.98 mu f_n in MuJoCo's contact frame; over the run and in its worst
0.5 s window), the clearance violation rate over swing ticks and its p95 depth (worlds with a clearance profile),
the foot and shin trips (worlds with obstacles), the controller model's residual alarm rate; then whether the
case is within 10 % of the URDF plant's value for the four targets (cone-edge share, clearance violation rate,
residual alarm rate, falls; a value of 0 is met only by 0), and, for the identified model, whether it is within
10 % of the told model's.

Cases: `URDF plant` = `+mismatch_plant=none` (the model is right); on the `lossy` plant (damping 1.5 N·m·s/rad,
armature 0.01 kg·m², friction loss 0.2 N·m): `untold` = the URDF model, `told` = `+mismatch_filter=matched`
(the true values as `model.*`), `identified` = `model=identified model.from=<file>`.

    python -m studies.identify_safety_table SWEEP_FOLDER [--out FILE.md]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pandas as pd

from studies.study_table import table_study

HEADER = ["| world | case | runs | falls | cone-edge share | cone-edge share, worst 0.5 s | clearance violation rate "
          "| clearance depth p95 [mm] | trips (foot + shin) per run | residual alarm rate | within 10 % of the URDF "
          "plant: cone / clearance / alarm / falls | within 10 % of told: cone / clearance / alarm / falls |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
CASES = ("URDF plant", "untold", "told", "identified")
TOLERANCE = 0.10


def case(row: pd.Series) -> str:
    if row["mismatch_plant"] == "none":
        return "URDF plant"
    if "model=identified" in str(row["overrides"]):
        return "identified"
    return "told" if row.get("mismatch_filter") == "matched" else "untold"


def world(row: pd.Series) -> str:
    name = "bump" if row["scenario"] == "perturbed" else row["scenario"]
    return f"{name} mu={row['friction_true']:g}"


def metrics(g: pd.DataFrame) -> dict[str, float]:
    trips = g[["foot_trips", "shin_trips"]].sum(axis=1, min_count=1) if "foot_trips" in g else pd.Series(dtype=float)
    return {"runs": len(g), "falls": float(g["fell"].astype(bool).sum()),
            "cone": g["friction_cone_edge_rate"].mean(), "cone_worst": g["friction_cone_edge_rate_worst_window"].mean(),
            "clearance": pd.to_numeric(g["clearance_violation_rate"], errors="coerce").mean(),
            "depth_mm": 1e3 * pd.to_numeric(g["clearance_violation_depth_p95_m"], errors="coerce").mean(),
            "trips": trips.mean() if len(trips) else math.nan, "alarm": g["residual_alarm_rate"].mean()}


def within(value: float, base: float) -> str:
    if math.isnan(value) or math.isnan(base):
        return "n/a"
    return "yes" if abs(value - base) <= TOLERANCE * abs(base) else "no"


def checks(m: dict[str, float], base: dict[str, float] | None) -> str:
    """``within`` for the four targets against ``base`` (n/a without one)."""
    if base is None:
        return "n/a"
    return " / ".join(within(m[k], base[k]) for k in ("cone", "clearance", "alarm", "falls"))


def _f(x: float, fmt: str = ".3f") -> str:
    return "n/a" if math.isnan(x) else format(x, fmt)


def rows(args: argparse.Namespace) -> list[str]:
    frame = pd.read_parquet(Path(args.sweep) / "summary.parquet")
    frame = frame.assign(case=frame.apply(case, axis=1), world=frame.apply(world, axis=1))
    out = []
    for name, w in frame.groupby("world", sort=False):
        found = {c: metrics(g) for c, g in w.groupby("case")}
        base = found.get("URDF plant")
        for c in (c for c in CASES if c in found):
            m = found[c]
            check = checks(m, base) if c != "URDF plant" else "—"
            vs_told = checks(m, found.get("told")) if c == "identified" else "—"
            out.append(f"| {name} | {c} | {m['runs']} | {m['falls']:.0f} | {_f(m['cone'])} | {_f(m['cone_worst'])} | "
                       f"{_f(m['clearance'])} | {_f(m['depth_mm'], '.1f')} | {_f(m['trips'], '.1f')} | "
                       f"{_f(m['alarm'])} | {check} | {vs_told} |")
    return out


def main(argv: list[str] | None = None) -> None:
    table_study("studies.identify_safety_table", __doc__, HEADER, rows, argv,
                add_args=lambda ap: ap.add_argument("sweep", type=Path, help="sweep folder (summary.parquet)"))


if __name__ == "__main__":
    main()
