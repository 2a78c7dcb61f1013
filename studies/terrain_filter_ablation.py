"""Which part of ``filter=terrain`` makes the A1 fall on real terrain: run the terrain filter with
subsets of its four parts switched on, per world and seed, and print one line per run and a falls table.

Parts (each an override of ``conf/filter/terrain.yaml``; a part not listed is switched off):
  cone       per-foot pyramids about the terrain normal (off: the paper's world-z pyramid, one mu)
  estimate   contact-aware stance (off: the gait schedule)
  legs       shin and knee barriers on every leg (off: no whole-leg rows)
  legsswing  shin and knee barriers on swing legs only
  terrclear  swing-foot clearance above the terrain (off: no ground-clearance row at all)
``none`` is the terrain preset with every part off (EoM, stance contact, world-z pyramid, torque limits,
priority relaxation: no barrier row, as the preset drops the paper's clearance and obstacle rows);
``all`` = ``filter=terrain``.
Two references can stand beside them: ``paper`` (``filter=id_cbf_qp``, the paper's filter) and ``nominal`` (the
filter off).

    python studies/terrain_filter_ablation.py OUT --worlds slope,steps,logs,rough --seeds 0,1,2 \\
        --parts all,terrclear+estimate,terrclear+estimate+legsswing,none [--extra controller.terrain_following=true]

Runs: 0.5 s stand + 10 s trot, URDF plant, default backend, no MCAP; run folders under OUT (complete runs are
skipped on a rerun, as in a sweep). Falls and trips are the harness's (contacts of the plant).
"""

from __future__ import annotations

import argparse
from pathlib import Path

PARTS_OFF = {  # the overrides that switch a part of filter=terrain off
    "cone": ["filter.friction_cone=pyramid"],
    "estimate": ["filter.stance_source=schedule"],
    "legs": ["filter.barriers.shin=null", "filter.barriers.knee=null"],
    "terrclear": ["filter.barriers.terrain_clearance=null"],
}
SWING_ONLY_LEGS = ["filter.barriers.shin.swing_only=true", "+filter.barriers.knee.swing_only=true"]
PARTS = (*PARTS_OFF, "legsswing")
REFERENCES = {"paper": ["filter=id_cbf_qp"], "nominal": ["filter.enabled=false"]}


def overrides_for(spec: str) -> list[str]:
    """``filter=terrain`` overrides that leave only the parts named in ``spec`` ("a+b", "all" or "none") on;
    ``paper`` and ``nominal`` give the references' overrides."""
    if spec in REFERENCES:
        return list(REFERENCES[spec])
    on = set(PARTS_OFF) if spec == "all" else set() if spec == "none" else set(spec.split("+"))
    unknown = on - set(PARTS)
    if unknown:
        raise ValueError(f"parts {spec!r}: unknown {sorted(unknown)}; valid: {', '.join(PARTS)}, all, none, "
                         f"or alone {', '.join(REFERENCES)}")
    if {"legs", "legsswing"} <= on:
        raise ValueError(f"parts {spec!r}: legs and legsswing exclude each other")
    out = ["filter=terrain"]
    for part, off in PARTS_OFF.items():
        if part not in on and not (part == "legs" and "legsswing" in on):
            out += off
    return out + (SWING_ONLY_LEGS if "legsswing" in on else [])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--worlds", default="slope,steps,logs,rough")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--parts", default="all,terrclear+estimate,terrclear+estimate+legsswing,none")
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--extra", default="", help="overrides added to every run, comma-separated "
                    "(e.g. controller.terrain_following=true)")
    a = ap.parse_args()
    specs = a.parts.split(",")
    for spec in specs:
        overrides_for(spec)  # bad part names refused before anything runs

    from taslel_bench.config.compose import compose
    from taslel_bench.sim.run import run

    falls: dict[tuple[str, str], list[int]] = {}
    for world in a.worlds.split(","):
        for seed in a.seeds.split(","):
            for spec in specs:
                over = [f"scenario={world}", f"seed={seed}", f"duration={a.duration}", "record.mcap=false",
                        "progress=false", *overrides_for(spec), *filter(None, a.extra.split(","))]
                s = run(compose(over), a.out / f"{world}_{spec}_s{seed}", {"scenario": world}, over)
                falls.setdefault((world, spec), []).append(int(bool(s["fell"])))
                print(f"{world:8s} seed {seed} {spec:32s} status {s['status']:8s} fell {s['fell']!s:5s} "
                      f"t_fall {s['time_to_fall_s']:5.2f} s  walked {s['distance_m']:.2f} m  trips {s.get('trips')} "
                      f"early touchdowns {s.get('touchdowns_early')}  {s['fall_reason']}", flush=True)
    print("\nfalls / runs (10 s trot)\n| world | " + " | ".join(specs) + " |")
    print("|---" * (len(specs) + 1) + "|")
    for world in a.worlds.split(","):
        cells = [f"{sum(falls[world, s])}/{len(falls[world, s])}" for s in specs]
        print(f"| {world} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
