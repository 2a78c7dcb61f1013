"""``python -m taslel_bench.seed_scan --seeds 0:2000 [overrides] --out results/startup/seed_scan.md``: build
every seed's run exactly as a run would (:class:`taslel_bench.sim.build.Built`: initial state, friction check on
that state) and simulate its stand; report the seeds that cannot start or fall while standing.

A seed *starts* when building raises nothing (the friction check found at least one foot contact, with the
configured friction); it *stands* when the stand phase ends without a fall.
"""

from __future__ import annotations

import argparse
import datetime as dt
import sys
import time
from pathlib import Path

import numpy as np

from taslel_bench.record import run_files
from taslel_bench.sim.build import Built
from taslel_bench.util.machine import machine_info
from taslel_bench.util.tables import markdown_table


def scan(seeds: range, overrides: list[str], stand: bool = True) -> list[dict[str, object]]:
    """One row per seed: started, error, feet touching at the start, stood (if ``stand``)."""
    from taslel_bench.api import compose

    cfg = compose(["filter.enabled=false", "progress=false", "record.mcap=false", *overrides])
    cfg.duration = 1e-3  # the stand, then one walking tick
    rows = []
    for i, seed in enumerate(seeds):
        cfg.seed = seed
        row: dict[str, object] = {"seed": seed, "started": False, "error": "", "feet_touching": 0, "stood": None}
        try:
            built = Built(cfg)
        except Exception as exc:  # the scan reports every failure
            row["error"] = f"{type(exc).__name__}: {exc}"
            rows.append(row)
            continue
        row["started"], row["feet_touching"] = True, len(built.friction_checked)
        if stand:
            res = built.episode.run()
            row["stood"] = res.status == "ok" and not res.fell
            row["error"] = res.fall_reason or res.message
        rows.append(row)
        if (i + 1) % 200 == 0:
            print(f"  {i + 1}/{len(seeds)} seeds", file=sys.stderr, flush=True)
    return rows


def markdown(rows: list[dict[str, object]], command: str, seconds: float) -> str:
    started = [r for r in rows if r["started"]]
    stood = [r for r in started if r["stood"]]
    feet = np.array([r["feet_touching"] for r in started])
    info = machine_info()
    when = dt.datetime.now().isoformat(timespec="seconds")
    machine = f"{info['cpu']}, {info['cores']} cores, Python {info['python']}; {info['packages']}"
    spread = f"{feet.min()} / {np.median(feet)} / {feet.max()}" if feet.size else "—"
    lines = [
        "# Seed scan: does every seed start?\n",
        f"Generated {when} by `{command}` ({info['code']}) in {seconds:.0f} s on {machine}.\n",
        ("Each seed is built exactly as its run would be (initial state drawn once from the seed, the lowest "
         "foot sphere placed 0.1 mm into the floor, the friction of every touching foot checked against the "
         "scenario), then its stand is simulated.\n"),
        markdown_table([(f"{rows[0]['seed']}..{rows[-1]['seed']} ({len(rows)})", len(started), len(stood), spread)],
                       ["seeds", "started", "stood (no fall in the stand)",
                        "feet touching at the start: min / median / max"]),
    ]
    failed = [r for r in rows if not r["started"] or r["stood"] is False]
    if failed:
        lines.append("## Seeds that did not start or fell while standing\n")
        lines += [f"- seed {r['seed']}: {r['error']}" for r in failed]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    ap.add_argument("--seeds", default="0:2000", help="first:last+1 (default 0:2000)")
    ap.add_argument("--no-stand", action="store_true", help="only build (no stand simulation)")
    ap.add_argument("--out", type=Path, help="markdown report to write")
    ap.add_argument("overrides", nargs="*", help="config overrides, e.g. scenario=low_friction")
    args = ap.parse_args(argv)
    first, last = (int(x) for x in args.seeds.split(":"))
    t0 = time.perf_counter()
    rows = scan(range(first, last), args.overrides, stand=not args.no_stand)
    text = markdown(rows, "python -m taslel_bench.seed_scan " + " ".join(sys.argv[1:] if argv is None else argv),
                    time.perf_counter() - t0)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        run_files.atomic_write(args.out, lambda p: p.write_text(text))
    print(text)
    bad = sum(1 for r in rows if not r["started"] or r["stood"] is False)
    raise SystemExit(1 if bad else 0)


if __name__ == "__main__":
    main()
