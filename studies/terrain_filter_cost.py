"""Issue 28's cost target: the tick median with ``filter=terrain`` against the paper's filter on the same backend,
measured in one process with the two filters interleaved (machine noise hits both alike).

    python studies/terrain_filter_cost.py --worlds steps,rough,logs,slope [--terrain-following false]

The nominal is that of ``+experiment=terrain`` by default (its ``controller`` block: terrain following, foothold
choice with the mid-swing re-plan, swing feet from the measured sag); ``--terrain-following false`` switches
those off (the paper's flat-ground nominal). Per
world: seed 0, 0.5 s stand + ``--duration`` s trot, DAQP, the URDF plant, no files written; each filter run
``--repeats`` times in the order paper, terrain, paper, terrain, ...; medians over the walking ticks (the wall
time of the whole tick, ``tick_us``, and of its filter part: QP build + solve), averaged over the repeats.
"""

from __future__ import annotations

import argparse

import numpy as np

FILTERS = {"paper": "filter=id_cbf_qp", "terrain": "filter=terrain"}


FLAT_GROUND_NOMINAL = ["controller.terrain_following=false", "controller.foothold_search=0.0",
                       "controller.foothold_replan_phase=0.0", "controller.swing_from_measured_hips=false"]


def tick_medians(world: str, filter_override: str, terrain_following: str, duration: float) -> tuple[float, float]:
    """(tick median, filter-part median) [us] over the walking ticks of one episode."""
    from taslel_bench.config.compose import compose
    from taslel_bench.record.trace import TICK_PARTS
    from taslel_bench.sim.build import Built

    nominal = [] if terrain_following == "true" else FLAT_GROUND_NOMINAL
    cfg = compose(["+experiment=terrain", f"scenario={world}", filter_override, "solver=daqp", f"duration={duration}",
                   "seed=0", *nominal, "progress=false", "record.mcap=false"])
    built = Built(cfg)
    tr = built.episode.run().trace
    walk = slice(round(float(cfg.controller.stand_duration) * float(cfg.control_rate_hz)), tr.n)
    part = TICK_PARTS.index("filter")
    return float(np.median(tr.tick_us[walk])), 1e6 * float(np.median(tr.tick_parts_s[walk, part]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", default="steps,rough,logs,slope")
    ap.add_argument("--terrain-following", default="true", choices=("true", "false"))
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    print("| world | paper tick p50 [us] | terrain tick p50 [us] | ratio | filter part paper -> terrain [us] |\n"
          "|---|---|---|---|---|")
    for world in a.worlds.split(","):
        runs: dict[str, list[tuple[float, float]]] = {name: [] for name in FILTERS}
        for _ in range(a.repeats):
            for name, override in FILTERS.items():
                runs[name].append(tick_medians(world, override, a.terrain_following, a.duration))
        paper, terrain = np.mean(runs["paper"], axis=0), np.mean(runs["terrain"], axis=0)
        print(f"| {world} | {paper[0]:.0f} | {terrain[0]:.0f} | {terrain[0] / paper[0]:.2f} | "
              f"{paper[1]:.0f} -> {terrain[1]:.0f} |", flush=True)


if __name__ == "__main__":
    main()
