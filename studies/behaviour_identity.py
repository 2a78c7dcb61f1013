"""Behaviour identity across a refactor: run a fixed set of configs, keep their summaries, compare two sets.

    python -m studies.behaviour_identity record --out /tmp/identity/before     # on the old code
    python -m studies.behaviour_identity record --out /tmp/identity/after      # on the new code
    python -m studies.behaviour_identity compare /tmp/identity/before /tmp/identity/after
    python -m studies.behaviour_identity record --set speed --out /tmp/identity/before   # the tick-speed set

Each case is one ``python -m taslel_bench`` run (the command line users type, so the script works on any
version of the package) into ``<out>/<case>_s<seed>/``. ``compare`` reads both folders' ``summary.json``
and ``steps.parquet`` and prints one row per run: summary keys compared, keys that differ (wall-clock
timings excluded), the largest |difference| of the applied torques and the trunk position over every
tick, and the number of ``steps.parquet`` columns that are not bit-identical (every column but the timers,
names ending ``_us``: trunk, joints, torques, contact forces and flags, QP status and iterations, metrics;
NaN equal to NaN; columns present in both). A refactor that preserves
behaviour shows 0 differing keys, 0.0 and 0 columns there. ``--set all`` (default) is the set that
produced the core redesign's identity table; ``--set speed`` the tick-speed set (10 s runs);
``--set terrain`` ``filter=terrain`` on the terrain worlds (the terrain filter's cost work, 5 s runs).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

SEEDS = (0, 1)
# name -> overrides: every scenario, both formulations, two backends, three estimators, filter off, the
# mismatch `lossy` case with the model told and with the robust option, contact-based stance
CASES: dict[str, list[str]] = {
    "flat": ["scenario=flat"],
    "low_friction": ["scenario=low_friction"],
    "obstacle": ["scenario=obstacle"],
    "logs": ["scenario=logs"],
    "logs_profile": ["scenario=logs", "scenario.coefficients=[0,0,1.28,-2.56,1.28]"],
    "logs_nominal": ["scenario=logs", "filter.enabled=false"],
    "friction_patch": ["scenario=friction_patch"],
    "push": ["scenario=push"],
    "push_300n": ["scenario=push", "scenario.pushes=[{t_s:2.0,force_n:[0,300,0],duration_s:0.2}]"],
    "payload": ["scenario=payload"],
    "perturbed": ["scenario=perturbed"],
    "lossy_matched": ["+experiment=mismatch", "+mismatch_plant=lossy", "+mismatch_filter=matched"],
    "lossy_robust": ["+experiment=mismatch", "+mismatch_plant=lossy", "+mismatch_filter=robust",
                     "scenario.friction=0.3"],
    "condensed_obstacle": ["scenario=obstacle", "filter.formulation=condensed"],
    "osqp_obstacle": ["scenario=obstacle", "solver=osqp"],
    "qpsolvers_osqp": ["scenario=flat", "solver=qpsolvers", "solver.name=osqp", "duration=2"],
    "fixed_low_friction": ["scenario=low_friction", "estimator=fixed"],
    "attention_step_patch": ["scenario=friction_patch", "estimator=attention_step"],
    "mlp_payload": ["scenario=payload", "estimator=mlp"],
    "contact_stance": ["scenario=low_friction", "filter.stance_source=contact", "duration=3"],
    "contact_gain": ["scenario=low_friction", "filter.contact_velocity_gain=50"],
    "filter_late": ["scenario=obstacle", "filter.start_time=3"],
}
# the tick-speed set: worlds x {default backend, osqp}, 10 s each, one seed
SPEED_WORLDS: dict[str, list[str]] = {
    "flat": ["scenario=flat"],
    "obstacle": ["scenario=obstacle"],
    "logs_terrain": ["scenario=logs", "filter=terrain"],
    "low_friction_nominal": ["scenario=low_friction", "filter.enabled=false"],
    "push": ["scenario=push"],
}
SPEED_CASES: dict[str, list[str]] = {
    **{name: [*o, "duration=10"] for name, o in SPEED_WORLDS.items()},
    **{f"{name}_osqp": [*o, "duration=10", "solver=osqp"] for name, o in SPEED_WORLDS.items()
       if "filter.enabled=false" not in o},
}
# the terrain-filter set (the terrain filter's cost work): filter=terrain on the terrain worlds under the preset's
# nominal (terrain following, foothold choice) and under the paper's flat-ground nominal, the landing barrier switched
# on, the paper's filter under the preset's nominal; 5 s each, seeds 0 and 1
FLAT_GROUND_NOMINAL = ["controller.terrain_following=false", "controller.foothold_search=0.0",
                       "controller.foothold_replan_phase=0.0", "controller.swing_from_measured_hips=false"]
TERRAIN_WORLDS = ("steps", "rough", "logs", "slope", "friction_patch", "low_friction")
TERRAIN_CASES: dict[str, list[str]] = {
    **{f"terrain_{w}": ["+experiment=terrain", f"scenario={w}", "filter=terrain", "duration=5"]
       for w in TERRAIN_WORLDS},
    **{f"terrain_{w}_flat_nominal": ["+experiment=terrain", f"scenario={w}", "filter=terrain", "duration=5",
                                     *FLAT_GROUND_NOMINAL] for w in ("steps", "rough", "logs", "slope")},
    **{f"terrain_{w}_landing": ["+experiment=terrain", f"scenario={w}", "filter=terrain", "duration=5",
                                "filter.barriers.landing={_target_:taslel_bench.filter.barriers.landing.LandingVelocity}"]
       for w in ("rough", "logs")},
    **{f"paper_{w}": ["+experiment=terrain", f"scenario={w}", "filter=id_cbf_qp", "duration=5"]
       for w in ("rough", "logs")},
}
SETS = {"all": (CASES, SEEDS), "speed": (SPEED_CASES, (0,)), "terrain": (TERRAIN_CASES, SEEDS)}
COMMON = ["record.mcap=false", "progress=false"]
# steps.parquet columns that time the code (µs): the only ones a behaviour-preserving change may alter
TIMER_SUFFIX = "_us"
# summary keys that measure wall-clock time (or say where/when a run happened), not behaviour
# (the deadline-miss rates count wall-clock solve times; file sizes and memory follow the timer columns)
TIMING_WORDS = ("_us", "wall_time", "real_time_factor", "warmup_s", "residuals_s", "recording_s", "reference_s",
                "deadline_miss", "over_1ms", "memory_peak", "result_files", "_sha256", "git_", "machine",
                "started", "plant_source", "model_source")


def record(out: Path, jobs: int, case_set: str = "all") -> None:
    out.mkdir(parents=True, exist_ok=True)
    cases, seeds = SETS[case_set]
    runs = [(f"{name}_s{seed}", [*overrides, f"seed={seed}", *COMMON]) for name, overrides in cases.items()
            for seed in seeds]

    def one(item: tuple[str, list[str]]) -> tuple[str, int]:
        name, overrides = item
        run_dir = out / name
        cmd = [sys.executable, "-m", "taslel_bench", *overrides, f"hydra.run.dir={run_dir}", "force=true"]
        proc = subprocess.run(cmd, check=False, capture_output=True, text=True)
        (out / f"{name}.log").write_text(proc.stdout + proc.stderr)
        return name, proc.returncode

    with ThreadPoolExecutor(jobs) as pool:
        for name, rc in pool.map(one, runs):
            print(f"{name}: exit {rc}", flush=True)


PROVENANCE_KEYS = ("identity",)  # the hashes of the code and files a run read: they change with any edit


def _timing(key: str) -> bool:
    return key in PROVENANCE_KEYS or any(word in key for word in TIMING_WORDS)


def _same(a: object, b: object) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b or (a is None and isinstance(b, float) and math.isnan(b)) or (
        b is None and isinstance(a, float) and math.isnan(a))


def compare(before: Path, after: Path) -> int:
    names = sorted(p.parent.name for p in before.glob("*/summary.json"))
    print("| run | keys compared | keys differing | only before | only after | max abs diff u [N·m] | "
          "max abs diff trunk pos [m] | columns not identical (timers excepted) |")
    print("|---|---|---|---|---|---|---|---|")
    bad = 0
    for name in names:
        a = json.loads((before / name / "summary.json").read_text())
        path_b = after / name / "summary.json"
        if not path_b.is_file():
            print(f"| {name} | missing after | | | | | | |")
            bad += 1
            continue
        b = json.loads(path_b.read_text())
        keys = sorted(k for k in set(a) & set(b) if not _timing(k))
        differ = [k for k in keys if not _same(a[k], b[k])]
        only_a = sorted(k for k in set(a) - set(b) if not _timing(k))
        only_b = sorted(k for k in set(b) - set(a) if not _timing(k))
        du, dp, cols = _trajectory_diff(before / name, after / name)
        bad += bool(differ) or du != 0.0 or dp != 0.0 or not cols.startswith("0 ")
        shown = ", ".join(f"{k} ({a[k]!r} -> {b[k]!r})" for k in differ[:4]) + (" ..." if len(differ) > 4 else "")
        print(f"| {name} | {len(keys)} | {len(differ)}{': ' + shown if differ else ''} | "
              f"{', '.join(only_a) or '-'} | {', '.join(only_b) or '-'} | {du:.3g} | {dp:.3g} | {cols} |")
    print(f"\n{len(names)} runs, {bad} with a difference")
    return 1 if bad else 0


def _physics_columns_differing(fa: pd.DataFrame, fb: pd.DataFrame) -> str:
    """How many columns present in both frames, timers excepted, are not bit-identical (NaN == NaN), of how
    many, with the first few names."""
    cols = [c for c in fa.columns if not c.endswith(TIMER_SUFFIX) and c in fb.columns]
    bad = [c for c in cols if not _column_identical(fa[c].to_numpy(), fb[c].to_numpy())]
    return f"{len(bad)}" + (f" of {len(cols)}: {', '.join(bad[:4])}" if bad else f" (of {len(cols)})")


def _column_identical(a: np.ndarray, b: np.ndarray) -> bool:
    if a.dtype.kind == "f" and b.dtype.kind == "f":
        return bool(np.array_equal(a, b, equal_nan=True))
    return bool(np.array_equal(a, b))


def _trajectory_diff(a: Path, b: Path) -> tuple[float, float, str]:
    fa, fb = pd.read_parquet(a / "steps.parquet"), pd.read_parquet(b / "steps.parquet")
    if len(fa) != len(fb):
        return math.inf, math.inf, "length differs"
    u = [c for c in fa.columns if c.startswith("u_") and c.endswith("_nm") and c in fb.columns]
    p = [c for c in ("base_x_w_m", "base_y_w_m", "base_z_w_m") if c in fa.columns and c in fb.columns]
    du = float(np.nanmax(np.abs(fa[u].to_numpy() - fb[u].to_numpy()))) if u and len(fa) else 0.0
    dp = float(np.nanmax(np.abs(fa[p].to_numpy() - fb[p].to_numpy()))) if p and len(fa) else 0.0
    return du, dp, _physics_columns_differing(fa, fb)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("--out", type=Path, required=True)
    rec.add_argument("--jobs", type=int, default=2)
    rec.add_argument("--set", dest="case_set", choices=sorted(SETS), default="all")
    cmp_ = sub.add_parser("compare")
    cmp_.add_argument("before", type=Path)
    cmp_.add_argument("after", type=Path)
    a = ap.parse_args(argv)
    if a.cmd == "record":
        record(a.out, a.jobs, a.case_set)
        return 0
    return compare(a.before, a.after)


if __name__ == "__main__":
    sys.exit(main())
