"""Do the tick's parts slow each other down, or does the glue between them slow them down?

    python -m studies.tick_interleaving [--ticks N] [--rounds R] [overrides ...]

The bench's sum-of-parts limit times each part alone, in a tight loop. The default loop runs at ~0.5-0.6 of
that limit, although by instructions it is at 0.82 of its parts (`studies.tick_instructions`). Two causes are
possible: the parts (MuJoCo, Pinocchio, the QP build, the solver) evict each other's code and data from the
caches when they run one after the other, or the Python glue between them (its bytecode, objects, numpy
temporaries and Numba hand-overs) costs more time than its instructions suggest and evicts the parts' caches.

This study records N consecutive walking ticks of one episode and replays the limit's parts on them
(:mod:`taslel_bench.qp.tick_replay`, which checks that the replay redoes the loop's work), timing every call
with ``perf_counter`` as the bench does:

* ``alone``: each part over the N ticks in its own loop (the bench's isolated parts, replayed in order);
* ``bare``: the parts of tick i back to back, tick after tick, with nothing between them but the replay's
  argument lookups (what a tick would cost with no glue at all);
* ``loop``: a clean run of the episode loop, its own per-part timers (``tick_<part>_us``) over the same ticks
  (their sum is the tick) and its wall time per tick (the tick plus what runs between ticks: the trace's row
  copy, the end checks, the loop itself), as the bench's real-time factor counts it.

If ``bare`` is as slow as ``loop`` the parts evict each other and no glue cut reaches the limit; if ``bare``
is close to ``alone`` the glue is what costs. Prints medians [µs] per part and the share sum(alone) / x, x the
bare sum, the loop's tick and its wall time per tick; each round runs the loop and both replays one after the
other, because this VM's speed drifts by up to 2x within minutes. Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from taslel_bench.api import compose
from taslel_bench.qp.tick_replay import PARTS, TickRecorder, record_ticks, replay
from taslel_bench.record.trace import TICK_PARTS
from taslel_bench.sim.build import Built


def record(overrides: list[str], n: int) -> tuple[Built, TickRecorder]:
    """Build the run (obstacle, 3 s walk, reference check off, then ``overrides``), run it once (kernels
    loaded), then once more recording ``n`` walking ticks (the copies slow that run: its timers are not used)."""
    built = Built(compose(["scenario=obstacle", "duration=3.0", "progress=false", "record.reference_every=0",
                           *overrides]))  # fmt: skip
    e = built.episode
    e.s = replace(e.s, analyse=False)
    e.run()
    return built, record_ticks(built, n)


def loop_run(built: Built, rec: TickRecorder) -> tuple[np.ndarray, float]:
    """A clean run of the episode: its own timers over the recorded ticks (µs per part, one row per tick,
    ``tick_<part>_us``) and its wall time per tick [µs] (mean over the run, as the real-time factor)."""
    res = built.episode.run()
    return res.trace.tick_parts_s[rec.k0 : rec.k0 + rec.n] * 1e6, res.wall_time_s / res.trace.n * 1e6


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ticks", type=int, default=1000, help="walking ticks recorded and replayed")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of (clean loop run, replay alone, replay bare)")
    ap.add_argument("overrides", nargs="*", help="config overrides, e.g. filter.formulation=full")
    args = ap.parse_args(argv)
    built, rec = record(args.overrides, args.ticks)
    print(f"median µs per part over {args.ticks} walking ticks; each round: a clean run of the loop, then the "
          "replays, one after the other (the VM's speed drifts between rounds)\n")
    print("| round | way | " + " | ".join(PARTS) + " | sum | alone / this |")
    print("|---|---|" + "---|" * (len(PARTS) + 2))
    for r in range(args.rounds):
        loop, wall_us = loop_run(built, rec)
        alone, bare, _ = replay(built, rec)
        a = np.array([np.median(alone[p]) for p in PARTS if p in alone])
        b = np.array([np.median(bare[p]) for p in PARTS if p in bare])
        for way, x in (("alone", a), ("bare", b)):
            print(f"| {r} | {way} | " + " | ".join(f"{v:.1f}" for v in x) + f" | {x.sum():.1f} | "
                                                                            f"{a.sum() / x.sum():.2f} |")
        parts = ", ".join(f"{k} {v:.1f}" for k, v in zip(TICK_PARTS, np.median(loop, axis=0), strict=True))
        tick = float(np.median(loop.sum(axis=1)))
        print(f"| {r} | loop tick, median ({parts}) |" + " |" * len(PARTS) + f" {tick:.1f} | {a.sum() / tick:.2f} |")
        print(f"| {r} | loop wall per tick, mean |" + " |" * len(PARTS) + f" {wall_us:.1f} | {a.sum() / wall_us:.2f} |")


if __name__ == "__main__":
    main()
