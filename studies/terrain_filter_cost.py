"""The terrain study's cost target: the tick median with ``filter=terrain`` against the paper's filter on the same
backend, measured in one process with the two filters interleaved (machine noise hits both alike).

    python studies/terrain_filter_cost.py [--worlds steps,rough,logs,slope] [--nominals flat,preset]
                                          [--repeats 7] [--out results/terrain/cost.md]

Nominals: ``preset`` is that of ``+experiment=terrain`` (its ``controller`` block: terrain following, foothold
choice with the mid-swing re-plan, swing feet from the measured sag); ``flat`` switches those off (the paper's
flat-ground nominal, the stricter reading of the target: the paper's filter tick is cheaper with it). Per world
and nominal: seed 0, 0.5 s stand + ``--duration`` s trot, DAQP, the URDF plant, no run files; the two filters
run ``--repeats`` times in the order paper, terrain, paper, terrain, ...; medians over the walking ticks of the
wall time of the whole tick (``tick_us``) and of its filter part (QP build + solve). The table gives the mean of
the per-run medians and the ratio of those means, plus the smallest and largest ratio of a (paper, terrain) pair
run back to back: the spread is the machine's noise. ``--out`` also writes the table with the machine, package
versions, code version and load averages (a new file; an existing one is not overwritten).
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import sys
from pathlib import Path

import numpy as np

FILTERS = {"paper": "filter=id_cbf_qp", "terrain": "filter=terrain"}

FLAT_GROUND_NOMINAL = ["controller.terrain_following=false", "controller.foothold_search=0.0",
                       "controller.foothold_replan_phase=0.0", "controller.swing_from_measured_hips=false"]
NOMINALS = {"flat": FLAT_GROUND_NOMINAL, "preset": []}
COLUMNS = ("nominal", "world", "paper tick p50 [us]", "terrain tick p50 [us]", "ratio of means",
           "pair ratios min-max", "filter part paper -> terrain [us]")


def tick_medians(world: str, filter_override: str, nominal: list[str], duration: float) -> tuple[float, float]:
    """(tick median, filter-part median) [us] over the walking ticks of one episode."""
    from taslel_bench.config.compose import compose
    from taslel_bench.record.trace import TICK_PARTS
    from taslel_bench.sim.build import Built

    cfg = compose(["+experiment=terrain", f"scenario={world}", filter_override, "solver=daqp", f"duration={duration}",
                   "seed=0", *nominal, "progress=false", "record.mcap=false"])
    tr = Built(cfg).episode.run().trace
    walk = slice(round(float(cfg.controller.stand_duration) * float(cfg.control_rate_hz)), tr.n)
    part = TICK_PARTS.index("filter")
    return float(np.median(tr.tick_us[walk])), 1e6 * float(np.median(tr.tick_parts_s[walk, part]))


def measure(nominal: str, world: str, repeats: int, duration: float) -> list[str]:
    """One table row: both filters interleaved ``repeats`` times."""
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in FILTERS}
    for _ in range(repeats):
        for name, override in FILTERS.items():
            runs[name].append(tick_medians(world, override, NOMINALS[nominal], duration))
    paper, terrain = np.asarray(runs["paper"]), np.asarray(runs["terrain"])
    pairs = terrain[:, 0] / paper[:, 0]
    p, t = paper.mean(axis=0), terrain.mean(axis=0)
    return [nominal, world, f"{p[0]:.0f}", f"{t[0]:.0f}", f"{t[0] / p[0]:.2f}", f"{pairs.min():.2f}-{pairs.max():.2f}",
            f"{p[1]:.0f} -> {t[1]:.0f}"]


def header(argv: list[str], load_start: tuple[float, ...]) -> str:
    from taslel_bench.util.machine import machine_info

    m = machine_info()
    load_end = os.getloadavg()
    return (f"# Terrain filter cost against the paper's filter\n\n`python studies/terrain_filter_cost.py "
            f"{' '.join(argv)}` · {dt.datetime.now().isoformat(timespec='seconds')}\n\n"
            f"Machine: {m['cpu']}, {m['cores']} cores, {m['os']}, Python {m['python']}; load average (1 min) "
            f"{load_start[0]:.1f} at start, {load_end[0]:.1f} at end  \nPackages: {m['packages']}  \n"
            f"Code: {m['code']}\n\n{__doc__.split(chr(10) + chr(10), 2)[2]}\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", default="steps,rough,logs,slope")
    ap.add_argument("--nominals", default="flat,preset", help=f"comma-separated, of {sorted(NOMINALS)}")
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    nominals = a.nominals.split(",")
    bad = [n for n in nominals if n not in NOMINALS]
    if bad:
        ap.error(f"--nominals: {bad} not among {sorted(NOMINALS)}")
    if a.out is not None and a.out.exists():
        ap.error(f"--out: {a.out} exists; results are not overwritten (move it away or name a new file)")
    load_start = os.getloadavg()
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    print("\n".join(lines), flush=True)
    for nominal in nominals:
        for world in a.worlds.split(","):
            lines.append("| " + " | ".join(measure(nominal, world, a.repeats, a.duration)) + " |")
            print(lines[-1], flush=True)
    if a.out is not None:
        from taslel_bench.record.run_files import atomic_write

        text = header(sys.argv[1:], load_start) + "\n".join(lines) + "\n"
        atomic_write(a.out, lambda tmp: tmp.write_text(text))
        print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
