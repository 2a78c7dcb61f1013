"""The terrain study's comparison of a ``+experiment=terrain`` sweep: the three controllers (``filter_variant``:
nominal = filter off, paper = ``filter=id_cbf_qp``, terrain = ``filter=terrain``) side by side per world and
plant (``mismatch_plant``: ``none`` = the URDF, ``lossy``), with the verdicts, and one sentence per target
of the study saying met or missed, with the numbers.

Numbers are means over a cell's finished runs (``ok`` or ``degraded``; ``runs`` shows finished/all, so a
crashed run is never silently dropped); tick costs are the runs' medians, averaged. Targets are read on the
URDF plant (the study's rule), the lossy plant is shown beside. The walked-distance target (2.5 m in 10 s) is
scaled to the sweep's duration and the sentence says so.
"""

from __future__ import annotations

import math

import pandas as pd

from taslel_bench.metrics.verdict import reason_tags
from taslel_bench.util.tables import markdown_table

VARIANT_COLUMN = "filter_variant"
PLANT_COLUMN = "mismatch_plant"
VARIANTS = ("nominal", "paper", "terrain")
WORLDS = ("flat", "low_friction", "logs", "steps", "rough", "slope", "friction_patch")
ROUGH_WORLDS = ("logs", "steps", "rough", "slope")  # the 0 falls / <= 1 trip / >= 2.5 m target
PLANT_LABELS = {"none": "URDF plant", "": "URDF plant", "lossy": "lossy plant (model not told)"}
# the terrain study's targets (conf/experiment/terrain.yaml)
MAX_TRIPS_PER_RUN = 1.0
MIN_DISTANCE_M_PER_10_S = 2.5  # [m]
MAX_GRF_MAE_Z_N = 2.0  # [N] vertical GRF error over every loaded contact, flat
MAX_SLIDING_SHARE_OF_NOMINAL = 0.40
MAX_CONE_EDGE_RATE = 0.05
MAX_TICK_COST_RATIO = 2.0  # terrain filter / paper filter, tick median, same backend
# table column -> summary column (means over finished runs)
METRICS = {
    "trips/run": "trips",
    # landings on a walkable surface in the second half of the swing: touchdowns, not trips (absent in older sweeps)
    "early touchdowns/run": "touchdowns_early",
    "distance [m]": "distance_m",
    "GRF err z loaded [N]": "grf_mae_z_n",
    "sliding [m]": "sliding_distance_m",
    "cone edge": "friction_cone_edge_rate",
    "touchdown slip [m/s]": "touchdown_slip_mps_mean",
    "tick p50 [µs]": "tick_us_median",
    "filter p50 [µs]": "tick_filter_us_median",
    "relaxed ticks": "filter_relaxed_ticks",
}


def _finished(runs: pd.DataFrame) -> pd.DataFrame:
    return runs[runs["status"].isin(["ok", "degraded"])] if "status" in runs else runs.iloc[0:0]


def _mean(runs: pd.DataFrame, col: str) -> float:
    if col not in runs:
        return math.nan
    v = pd.to_numeric(runs[col], errors="coerce").dropna()
    return float(v.mean()) if len(v) else math.nan


def _fmt(x: float) -> str:
    return "—" if math.isnan(x) else f"{x:.3g}"


def _falls(runs: pd.DataFrame) -> str:
    return f"{int(runs['fell'].fillna(False).astype(bool).sum())}/{len(runs)}" if len(runs) and "fell" in runs else "—"


def _unsafe(runs: pd.DataFrame) -> str:
    """``k/n`` unsafe of the judged runs, with the reasons' counts."""
    if "safe" not in runs or runs["safe"].isna().all():
        return "—"
    judged = runs[runs["safe"].notna()]
    counts: dict[str, int] = {}
    for text in judged.loc[~judged["safe"].astype(bool), "unsafe_reasons"] if "unsafe_reasons" in judged else []:
        for tag in reason_tags(text):
            counts[tag] = counts.get(tag, 0) + 1
    bad = int((~judged["safe"].astype(bool)).sum())
    why = ", ".join(f"{tag} {k}" for tag, k in sorted(counts.items()))
    return f"{bad}/{len(judged)}" + (f" ({why})" if why else "")


def cell(frame: pd.DataFrame, world: str, variant: str, plant: str) -> pd.DataFrame:
    """Every run (any status) of one world, controller and plant."""
    plant_values = ("none", "") if plant in ("none", "") else (plant,)
    plants = frame[PLANT_COLUMN].fillna("").astype(str) if PLANT_COLUMN in frame else pd.Series("", index=frame.index)
    return frame[(frame["scenario"] == world) & (frame[VARIANT_COLUMN].astype(str) == variant)
                 & plants.isin(plant_values)]  # fmt: skip


def comparison_table(frame: pd.DataFrame, plant: str) -> pd.DataFrame:
    """Rows (world, controller) of one plant: runs finished/all, safe verdicts, falls and the metrics."""
    rows = []
    for world in [w for w in WORLDS if w in set(frame["scenario"])]:
        for variant in VARIANTS:
            runs = cell(frame, world, variant, plant)
            if runs.empty:
                continue
            done = _finished(runs)
            row = {"world": world, "controller": variant, "runs": f"{len(done)}/{len(runs)}",
                   "unsafe": _unsafe(done), "falls": _falls(done)}  # fmt: skip
            row.update({name: _fmt(_mean(done, col)) for name, col in METRICS.items()})
            rows.append(row)
    return pd.DataFrame(rows)


def _plants(frame: pd.DataFrame) -> list[str]:
    if PLANT_COLUMN not in frame:
        return ["none"]
    values = sorted(set(frame[PLANT_COLUMN].fillna("").astype(str).replace("", "none")))
    return sorted(values, key=lambda p: (p != "none", p))


def _duration_s(frame: pd.DataFrame) -> float:
    return _mean(frame, "duration_s") if "duration_s" in frame else 10.0


# the trip target's reading: the verdict's trips (taslel_bench.metrics.clearance), mean and largest count per run
TRIP_READINGS = {"trips": "trips"}


def _trip_readings(on: pd.DataFrame, falls: int, walked: bool) -> tuple[bool, str]:
    """(met, text of the reading: mean per run, largest run, and met (every run <= the bound), met on average
    only (the mean <= the bound, some run over it) or missed)."""
    parts, met_every = [], False
    for label, col in TRIP_READINGS.items():
        counts = pd.to_numeric(on[col], errors="coerce").dropna() if col in on else pd.Series(dtype=float)
        if counts.empty:
            continue
        mean, most, over = float(counts.mean()), float(counts.max()), int((counts > MAX_TRIPS_PER_RUN).sum())
        ok = falls == 0 and walked
        if ok and most <= MAX_TRIPS_PER_RUN:
            verdict = "met"
        elif ok and mean <= MAX_TRIPS_PER_RUN:
            verdict = f"met on average, not in every run ({over} of {len(on)} over)"
        else:
            verdict = "missed"
        met_every = verdict == "met" if col == "trips" else met_every
        parts.append(f"{label} {_fmt(mean)} (at most {_fmt(most)}): {verdict}")
    return met_every, "; ".join(parts)


def _rough_targets(frame: pd.DataFrame) -> list[str]:
    duration = _duration_s(frame)
    need_m = MIN_DISTANCE_M_PER_10_S * (duration / 10.0 if not math.isnan(duration) else 1.0)
    out = []
    for world in ROUGH_WORLDS:
        on = _finished(cell(frame, world, "terrain", "none"))
        if on.empty:
            continue
        falls = int(on["fell"].fillna(False).astype(bool).sum())
        dist = _mean(on, "distance_m")
        met, readings = _trip_readings(on, falls, dist >= need_m)
        early = (f"; early touchdowns (walkable landings in the second half of the swing, no trips) "
                 f"{_fmt(_mean(on, 'touchdowns_early'))} per run, "
                 f"{_fmt(_mean(on, 'touchdowns_early_beyond_20ms'))} more than 20 ms early"
                 if "touchdowns_early" in on else "")  # fmt: skip
        beside = "; ".join(f"{v}: falls {_falls(_finished(cell(frame, world, v, 'none')))}, trips "
                           f"{_fmt(_mean(_finished(cell(frame, world, v, 'none')), 'trips'))}, "
                           f"{_fmt(_mean(_finished(cell(frame, world, v, 'none')), 'distance_m'))} m"
                           for v in ("nominal", "paper"))  # fmt: skip
        out.append(f"**{world}** (target: 0 falls, <= {MAX_TRIPS_PER_RUN:g} trip per run, >= {need_m:.3g} m walked "
                   f"in {duration:.3g} s): {'met' if met else 'missed'}: falls {falls}/{len(on)}, {_fmt(dist)} m; "
                   f"{readings}{early} ({beside}).")
    return out


def _flat_target(frame: pd.DataFrame) -> list[str]:
    on = _finished(cell(frame, "flat", "terrain", "none"))
    if on.empty:
        return []
    err, paper = _mean(on, "grf_mae_z_n"), _mean(_finished(cell(frame, "flat", "paper", "none")), "grf_mae_z_n")
    met = not math.isnan(err) and err <= MAX_GRF_MAE_Z_N
    return [(f"**flat GRF** (target: vertical GRF error over every loaded contact <= {MAX_GRF_MAE_Z_N:g} N): "
            f"{'met' if met else 'missed'}: {_fmt(err)} N with the terrain filter (paper filter {_fmt(paper)} N).")]


def _friction_target(frame: pd.DataFrame) -> list[str]:
    on = _finished(cell(frame, "low_friction", "terrain", "none"))
    off = _finished(cell(frame, "low_friction", "nominal", "none"))
    paper = _finished(cell(frame, "low_friction", "paper", "none"))
    if on.empty:
        return []
    slide_on, slide_off = _mean(on, "sliding_distance_m"), _mean(off, "sliding_distance_m")
    share = slide_on / slide_off if slide_off and not math.isnan(slide_off) else math.nan
    td_on, td_off = _mean(on, "touchdown_slip_mps_mean"), _mean(off, "touchdown_slip_mps_mean")
    edge = _mean(on, "friction_cone_edge_rate")
    checks = {"sliding": not math.isnan(share) and share <= MAX_SLIDING_SHARE_OF_NOMINAL,
              "touchdown slip": not math.isnan(td_off) and td_on < td_off,
              "cone edge": not math.isnan(edge) and edge <= MAX_CONE_EDGE_RATE}  # fmt: skip
    missed = [k for k, ok in checks.items() if not ok]
    verdict = "met" if not missed else "missed (" + ", ".join(missed) + ")"
    return [(f"**mu = 0.2** (targets: sliding <= {100 * MAX_SLIDING_SHARE_OF_NOMINAL:.0f} % of nominal, touchdown "
            f"slip below nominal, cone-edge share <= {MAX_CONE_EDGE_RATE:g}): {verdict}: sliding {_fmt(slide_on)} m "
            f"= {_fmt(100 * share)} % of nominal {_fmt(slide_off)} m (paper filter "
            f"{_fmt(_mean(paper, 'sliding_distance_m'))} m); touchdown slip {_fmt(td_on)} vs nominal {_fmt(td_off)} "
            f"m/s (paper {_fmt(_mean(paper, 'touchdown_slip_mps_mean'))}); cone edge {_fmt(edge)} (nominal "
            f"{_fmt(_mean(off, 'friction_cone_edge_rate'))}, paper {_fmt(_mean(paper, 'friction_cone_edge_rate'))}).")]


def _cost_target(frame: pd.DataFrame) -> list[str]:
    ratios = {}
    for world in WORLDS:
        on = _mean(_finished(cell(frame, world, "terrain", "none")), "tick_us_median")
        paper = _mean(_finished(cell(frame, world, "paper", "none")), "tick_us_median")
        if not (math.isnan(on) or math.isnan(paper)) and paper > 0:
            ratios[world] = on / paper
    if not ratios:
        return []
    worst = max(ratios, key=ratios.__getitem__)
    solvers = sorted(set(frame["solver"].dropna().astype(str)) - {"none", ""}) if "solver" in frame else []
    met = ratios[worst] <= MAX_TICK_COST_RATIO
    each = ", ".join(f"{w} {r:.2f}x" for w, r in ratios.items())
    return [(f"**cost** (target: tick median with the terrain filter <= {MAX_TICK_COST_RATIO:g}x the paper filter's, "
            f"same backend {', '.join(solvers) or '?'}): {'met' if met else 'missed'} in this sweep (worst {worst} "
            f"{ratios[worst]:.2f}x; {each}). Measured inside a sweep (jobs share the machine): the bench tool on a "
            "quiet machine is the reference for this target.")]


def target_sentences(frame: pd.DataFrame) -> list[str]:
    """One sentence per target of the terrain study, met or missed, with the numbers (URDF plant)."""
    return [*_rough_targets(frame), *_flat_target(frame), *_friction_target(frame), *_cost_target(frame)]


def terrain_section(frame: pd.DataFrame) -> str:
    """Markdown section of the report ("" when the sweep has no ``filter_variant`` axis)."""
    if VARIANT_COLUMN not in frame or "scenario" not in frame or frame.empty:
        return ""
    parts = ["## Terrain filter vs the paper's\n",
             ("Per world and plant, the three controllers side by side: nominal (filter off), paper "
             "(`filter=id_cbf_qp`), terrain (`filter=terrain`). Means over finished runs (`runs` = finished/all); "
             "`unsafe` = runs whose verdict is `safe: false`, with the reasons' counts; tick costs are per-run "
             "medians, averaged.\n")]
    for plant in _plants(frame):
        table = comparison_table(frame, plant)
        if len(table):
            parts += [f"### {PLANT_LABELS.get(plant, plant + ' plant')}\n", markdown_table(table, fmt=str)]
    sentences = target_sentences(frame)
    if sentences:
        parts += ["### Targets of the terrain study (URDF plant)\n", "\n".join(f"- {s}" for s in sentences) + "\n"]
    return "\n".join(parts)


def urdf_plant_runs(frame: pd.DataFrame) -> pd.DataFrame:
    """The runs on the URDF plant when the sweep also has mismatch plants (the paper's claims are made on the
    URDF plant and must not pool plants as if they were seeds); the frame as is otherwise."""
    if PLANT_COLUMN not in frame:
        return frame
    plants = frame[PLANT_COLUMN].fillna("").astype(str)
    return frame[plants.isin(["none", ""])] if plants.nunique() > 1 else frame
