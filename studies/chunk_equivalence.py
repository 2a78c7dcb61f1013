"""Behaviour check of the chunked trace: run a fixed set of 10 s runs into ``OUT/<name>`` (summary.json,
steps.parquet), and compare two such folders key by key (summary) and column by column (steps).

    python studies/chunk_equivalence.py run OUT [extra overrides...]
    python studies/chunk_equivalence.py compare OUT_A OUT_B
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from hydra import compose, initialize_config_dir

CONF = str(Path(__file__).resolve().parent.parent / "conf")
RUNS = {
    "flat": ["scenario=flat"],
    "obstacle": ["scenario=obstacle"],
    "logs_terrain": ["scenario=logs", "filter=terrain"],
    "low_friction": ["scenario=low_friction"],
    "friction_patch": ["scenario=friction_patch"],
}
VOLATILE = ("wall_time", "_s_", "real_time", "tick_", "memory_", "warmup", "recording_s", "reference_s",
            "residuals_s", "qp_solve_us", "qp_build_us", "git_", "code_", "manifest", "config_sha256",
            "intervention_ms", "qp_deadline", "qp_solve_over", "result_files")


def run_all(out: Path, extra: list[str]) -> None:
    from taslel_bench.sim.run import run

    for name, ov in RUNS.items():
        for filt in ("true", "false"):
            over = [*ov, f"filter.enabled={filt}", "duration=10", "record.mcap=false", "progress=false", *extra]
            with initialize_config_dir(config_dir=CONF, version_base="1.3"):
                cfg = compose(config_name="config", overrides=over)
            s = run(cfg, out / f"{name}_filter_{filt}", {"scenario": ov[0].split("=")[1]}, over)
            print(name, filt, s["status"], s["ticks"], s.get("memory_peak_gb"), flush=True)


def _volatile(key: str) -> bool:
    return any(v in key for v in VOLATILE) and not key.endswith(("_rate", "_count"))


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    return a == b


def compare(a: Path, b: Path) -> int:
    bad = 0
    for run_a in sorted(a.iterdir()):
        run_b = b / run_a.name
        sa, sb = (json.loads((r / "summary.json").read_text()) for r in (run_a, run_b))
        keys = sorted(set(sa) | set(sb))
        diff = [k for k in keys if not _volatile(k) and not same(sa.get(k), sb.get(k))]
        fa, fb = (pd.read_parquet(r / "steps.parquet") for r in (run_a, run_b))
        cols = [c for c in fa.columns if not c.startswith("tick_") and c not in ("qp_solve_us", "qp_build_us")]
        cdiff = [
            c for c in cols if c not in fb or not np.array_equal(fa[c].to_numpy(), fb[c].to_numpy(), equal_nan=True)
        ]
        if list(fa.columns) != list(fb.columns):
            cdiff.append("<column order or set>")
        print(f"{run_a.name}: {len(keys)} summary keys, {len(diff)} differ {diff[:8]}; steps {fa.shape} vs "
              f"{fb.shape}, {len(cdiff)} columns differ {cdiff[:8]}")
        for k in diff[:8]:
            print(f"    {k}: {sa.get(k)!r} vs {sb.get(k)!r}")
        bad += len(diff) + len(cdiff)
    return bad


if __name__ == "__main__":
    if sys.argv[1] == "run":
        run_all(Path(sys.argv[2]), sys.argv[3:])
    else:
        sys.exit(1 if compare(Path(sys.argv[2]), Path(sys.argv[3])) else 0)
