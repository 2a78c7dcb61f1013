"""Collection throughput of nominal episodes, the core loop against the fast loop, on the same draws
(``python -m studies.estimator_collect_speed [--episodes N] [--workers W]``).

Prints env-steps/s (physics steps per wall second, all workers) of ``estimators.collect`` with
``--loop core`` and ``--loop fast`` on the same N nominal training episodes (seed 0, no filter, 5 s each),
whether their windows are identical, and the machine's load before and after; a printed benchmark, not a
test (the number depends on the machine and on what else runs on it).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from estimators.collect import EpisodeConfig, collect


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--patch-fraction", type=float, default=0.0)
    a = ap.parse_args(argv)
    print(f"cpus {os.cpu_count()}, load before {os.getloadavg()[0]:.2f}")
    rates, windows = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for loop in ("core", "fast"):
            cfg = replace(EpisodeConfig(), loop=loop)
            man = collect(Path(tmp) / loop, {"train": a.episodes}, seed=0, workers=a.workers, cfg=cfg,
                          patch_fraction=a.patch_fraction)
            rates[loop] = man["env_steps_per_s"]
            windows[loop] = np.load(Path(tmp) / loop / "train.npz")["X"]
            print(f"{loop}: {man['env_steps']:,} env steps in {man['wall_time_s']:.1f} s -> "
                  f"{rates[loop]:,.0f} env-steps/s with {a.workers} workers "
                  f"({man['env_steps_per_s_per_worker']['nominal']:,.0f} per worker)", flush=True)
    same = np.array_equal(windows["core"], windows["fast"])
    print(f"fast / core = {rates['fast'] / rates['core']:.2f}x; windows identical: {same}; "
          f"load after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
