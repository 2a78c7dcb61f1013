"""Collection throughput of nominal episodes (``python -m studies.estimator_collect_speed [--episodes N]
[--workers W] [--batch B] [--windows FILE] [--compare FILE]``).

Prints env-steps/s (physics steps per wall second, all workers, and per worker) of ``estimators.collect`` on
N nominal training episodes (seed 0, no filter, 5 s each) and the machine's load before and after; a printed
benchmark, not a test (the number depends on the machine and on what else runs on it). ``--windows``
keeps the collected windows; ``--compare`` checks them against windows kept by another checkout (run the
same command there: the printed line says whether every window is identical).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
from pathlib import Path

import numpy as np

from estimators.collect import EpisodeConfig, collect


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--patch-fraction", type=float, default=0.0)
    ap.add_argument("--batch", type=int, default=0, help="episodes stepped together (0: the episode loop)")
    ap.add_argument("--windows", type=Path, help="keep the collected train.npz here")
    ap.add_argument("--compare", type=Path, help="a train.npz of the same command from another checkout")
    a = ap.parse_args(argv)
    print(f"cpus {os.cpu_count()}, load before {os.getloadavg()[0]:.2f}")
    cpu0 = _cpu_s()
    with tempfile.TemporaryDirectory() as tmp:
        man = collect(Path(tmp), {"train": a.episodes}, seed=0, workers=a.workers, cfg=EpisodeConfig(),
                      patch_fraction=a.patch_fraction, batch=a.batch)
        print(f"{man['env_steps']:,} env steps in {man['wall_time_s']:.1f} s -> {man['env_steps_per_s']:,.0f} "
              f"env-steps/s with {a.workers} {'threads, batches of ' + str(a.batch) if a.batch else 'workers'} "
              f"({man['env_steps_per_s_per_worker']['nominal']:,.0f} per worker); load after {os.getloadavg()[0]:.2f}",
              flush=True)
        print(f"CPU {(_cpu_s() - cpu0) / man['env_steps'] * 1e6:.1f} µs per env step (every process and thread: "  # type: ignore[operator]
              f"what the cores spent, whatever else ran)", flush=True)
        if a.windows is not None:
            shutil.copy(Path(tmp) / "train.npz", a.windows)
        if a.compare is not None:
            mine, other = np.load(Path(tmp) / "train.npz"), np.load(a.compare)
            same = set(mine.files) == set(other.files) and all(_same(mine[k], other[k]) for k in other.files)
            print(f"windows and labels identical to {a.compare}: {same}")


def _cpu_s() -> float:
    """[s] user + system CPU time of this process and its ended children."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal shapes and values, NaN equal to NaN (the unfiltered episodes' filter_mu, no patch)."""
    return np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


if __name__ == "__main__":
    main()
