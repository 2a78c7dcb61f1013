"""How early are the swing-foot "trips" of the terrain worlds? (``python -m studies.terrain_trip_timing SWEEP
[--out FILE.md]``, SWEEP = a ``+experiment=terrain`` sweep folder, e.g. the one of ``results/terrain/``)

The terrain study's trip target counts every foot trip. On logs, steps, rough and slope almost all of them are
``foot_trips_top_late_swing``: a swing foot whose first contact with the relief is on a top (normal within 45
deg of vertical) in the second half of its swing, before the gait's scheduled touchdown (the same event on the
floor is an early touchdown and no trip). This study reads each run's ``steps.parquet`` and finds those onsets
again: per leg, the first tick of ``{leg}_obstacle_contact`` (the foot sensor's contact with an obstacle, re-armed
after 10 ms without one) with the leg outside the filter's stance set and the schedule's stance
(``{leg}_stance``, ``{leg}_scheduled_stance``), swing phase >= 0.5 and the contact normal's world z >= cos 45
deg (``{leg}_contact_frame_normal_z_w``). How early each one is = (1 - swing phase) x the swing's duration
(gait period x (1 - duty), from the run's config).

Columns per world, controller and plant (runs that did not fall): runs; late-top landings per run as the
summary counts them (``foot_trips_top_late_swing``) and as found here (the check of this reading: the two
differ where the foot sensor and the contact-frame log disagree on the onset tick); of those found here, the
share within 5, 10 and 20 ms of the scheduled touchdown; median and max [ms] before it; the swing phase's
minimum; then the verdict's trips per run, and the same with the landings found here within 10 ms and within 20
ms of the scheduled touchdown not counted (the largest run's count of the latter in brackets): a reading of
the trip rule that tolerates touchdowns this close to the schedule. Swing duration 200 ms in the preset.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from studies.study_table import table_study
from taslel_bench.metrics.clearance import TRIP_REARM_S, onsets
from taslel_bench.metrics.contacts import FLANK_COS

LEGS = ("FL", "FR", "RL", "RR")
WORLDS = ("logs", "steps", "rough", "slope")
HEADER = [("| world | controller | plant | runs | late-top landings/run (summary) | found here/run | <= 5 ms early | "
           "<= 10 ms | <= 20 ms | median early [ms] | max early [ms] | min swing phase | trips/run | trips/run "
           "less landings <= 10 ms early | <= 20 ms early (max per run) |"),
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]


def late_top_phases(run: Path) -> tuple[np.ndarray, float]:
    """(swing phases of the run's late-swing top landings, swing duration [ms])."""
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    swing_ms = 1000.0 * float(cfg["controller"]["period"]) * (1.0 - float(cfg["controller"]["duty"]))
    d = pd.read_parquet(run / "steps.parquet")
    rearm = max(1, round(TRIP_REARM_S / (d["t_s"].iloc[1] - d["t_s"].iloc[0])))  # the harness's trip re-arm
    walking = d["t_s"].to_numpy() >= float(cfg["controller"]["stand_duration"])
    phases = []
    for leg in LEGS:
        touch = d[f"{leg}_obstacle_contact"].to_numpy(bool)
        new = onsets(touch, rearm)
        air = ~d[f"{leg}_stance"].to_numpy(bool) & ~d[f"{leg}_scheduled_stance"].to_numpy(bool)
        phase = d[f"{leg}_swing_phase"].to_numpy(float)
        top = d[f"{leg}_contact_frame_normal_z_w"].to_numpy(float) >= FLANK_COS
        phases.append(phase[new & air & top & (phase >= 0.5) & walking])
    return np.concatenate(phases), swing_ms


def label(run: Path, key: str) -> str:
    for part in run.name.split(","):
        if part.lstrip("+").startswith(key + "="):
            return part.split("=", 1)[1]
    return "?"


def rows(sweep: Path):
    runs = sorted(p for p in sweep.iterdir() if (p / "summary.json").exists() and (p / "steps.parquet").exists())
    groups: dict[tuple[str, str, str], list[Path]] = {}
    for run in runs:
        key = (label(run, "scenario"), label(run, "filter_variant"), label(run, "mismatch_plant"))
        if key[0] in WORLDS:
            groups.setdefault(key, []).append(run)
    for (world, controller, plant), group in sorted(groups.items()):
        counted, phases, trips, swing_ms, n = [], [], [], 200.0, 0
        for run in group:
            s = json.loads((run / "summary.json").read_text())
            if s.get("fell"):
                continue
            p, swing_ms = late_top_phases(run)
            counted.append(float(s.get("foot_trips_top_late_swing", math.nan)))
            phases.append(p)
            early_ms = (1.0 - p) * swing_ms
            total = float(s.get("trips", math.nan))
            trips.append((total, total - np.sum(early_ms <= 10.0), total - np.sum(early_ms <= 20.0)))
            n += 1
        if not n:
            yield f"| {world} | {controller} | {plant} | 0 | - | - | - | - | - | - | - | - | - | - | - |"
            continue
        early = (1.0 - np.concatenate(phases)) * swing_ms
        share = [f"{np.mean(early <= ms):.2f}" if early.size else "-" for ms in (5.0, 10.0, 20.0)]
        med = f"{np.median(early):.0f}" if early.size else "-"
        top = f"{early.max():.0f}" if early.size else "-"
        low = f"{1.0 - early.max() / swing_ms:.2f}" if early.size else "-"
        t = np.array(trips)
        yield (f"| {world} | {controller} | {plant} | {n} | {np.nanmean(counted):.1f} | {early.size / n:.1f} | "
               f"{' | '.join(share)} | {med} | {top} | {low} | {np.nanmean(t[:, 0]):.1f} | {np.nanmean(t[:, 1]):.1f} | "
               f"{np.nanmean(t[:, 2]):.1f} ({np.nanmax(t[:, 2]):.0f}) |")


def _sweep_arg(ap) -> None:
    ap.add_argument("sweep", type=Path, help="a +experiment=terrain sweep folder")


def _rows(a):
    if not a.sweep.is_dir():
        raise SystemExit(f"sweep: {a.sweep} is not a folder (a +experiment=terrain sweep folder)")
    return rows(a.sweep)


def main(argv: list[str] | None = None) -> None:
    table_study("studies.terrain_trip_timing", __doc__, HEADER, _rows, argv, add_args=_sweep_arg)


if __name__ == "__main__":
    main()
