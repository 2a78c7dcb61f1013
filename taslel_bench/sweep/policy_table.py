"""The policy study's comparison (``+experiment=policy``): per robot and world, each nominal controller (the
paper's blind trot, the shipped learned policy) alone, with the paper's filter and with the terrain filter, side by
side with the verdicts, and one sentence per target of the study saying met or missed, with the numbers.

Numbers are means over a cell's finished runs (``ok`` or ``degraded``; ``runs`` shows finished/all). A world is
the scenario with its friction when the sweep varies ``scenario.friction`` (``low_friction 0.3``).
"""

from __future__ import annotations

import math
from typing import SupportsFloat, cast

import pandas as pd
from scipy.stats import fisher_exact

from taslel_bench.sweep.terrain_table import VARIANT_COLUMN, _falls, _finished, _fmt, _mean, _unsafe
from taslel_bench.util.tables import markdown_table

CONTROLLER_COLUMN = "controller"
CONTROLLERS = ("trot", "policy")
# filter off, filter=id_cbf_qp, filter=terrain, filter=terrain_release, filter=terrain_bounded,
# filter=terrain_guarded
VARIANTS = ("nominal", "paper", "terrain", "release", "bounded", "guarded")
FILTERS = ("paper", "terrain", "release", "bounded", "guarded")
WORLD_ORDER = ("flat", "low_friction", "friction_patch", "logs", "steps", "rough", "slope", "push", "payload")
SLIPPERY = ("low_friction", "friction_patch")  # the help target: strictly fewer unsafe runs than alone
ROUGH = ("logs", "steps", "rough", "slope")  # the help target: fewer falls or trips on at least two
COMMAND_MPS = 0.5  # [m/s] the policies' forward command when a run's summary does not say (commanded_speed_mps)
SPEED_TOLERANCE_MPS = 0.1
MAX_FLAT_INTERVENTION_NM = 1.0
MAX_DISTANCE_LOSS = 0.10  # do no harm: mean distance not lower by more than this share
METRICS = {"trips/run": "trips", "distance [m]": "distance_m", "speed [m/s]": "mean_speed_mps",
           "intervention [N·m]": "intervention_nm_mean", "tick p50 [µs]": "tick_us_median"}


def is_policy_study(frame: pd.DataFrame) -> bool:
    return bool(CONTROLLER_COLUMN in frame and VARIANT_COLUMN in frame and "scenario" in frame
                and (frame[CONTROLLER_COLUMN].astype(str) == "policy").any())


def world_of(frame: pd.DataFrame) -> pd.Series:
    """The world of each run: the scenario, with its friction when the sweep varies ``scenario.friction``."""
    world = frame["scenario"].astype(str)
    if "scenario.friction" in frame:
        friction = frame["scenario.friction"].fillna("").astype(str)
        world = world.where(friction == "", world + " " + friction)
    return world


def _worlds(frame: pd.DataFrame) -> list[str]:
    present = set(world_of(frame))
    return sorted(present, key=lambda w: (WORLD_ORDER.index(w.split()[0]) if w.split()[0] in WORLD_ORDER else 99, w))


def cell(frame: pd.DataFrame, robot: str, world: str, controller: str, variant: str) -> pd.DataFrame:
    """Every run (any status) of one robot, world, nominal controller and filter variant."""
    robots = frame["robot"].astype(str) if "robot" in frame else pd.Series(robot, index=frame.index)
    return frame[(robots == robot) & (world_of(frame) == world)
                 & (frame[CONTROLLER_COLUMN].astype(str) == controller)
                 & (frame[VARIANT_COLUMN].astype(str) == variant)]  # fmt: skip


def comparison_table(frame: pd.DataFrame, robot: str) -> pd.DataFrame:
    rows = []
    for world in _worlds(frame):
        for controller in CONTROLLERS:
            for variant in VARIANTS:
                runs = cell(frame, robot, world, controller, variant)
                if runs.empty:
                    continue
                done = _finished(runs)
                row = {"world": world, "nominal": controller, "filter": variant, "runs": f"{len(done)}/{len(runs)}",
                       "unsafe": _unsafe(done), "falls": _falls(done)}  # fmt: skip
                row.update({name: _fmt(_mean(done, col)) for name, col in METRICS.items()})
                rows.append(row)
    return pd.DataFrame(rows)


def _count(runs: pd.DataFrame, col: str) -> int:
    if col == "unsafe":
        return int((~runs["safe"].astype(bool)).sum()) if "safe" in runs else 0
    return int(runs[col].fillna(False).astype(bool).sum()) if col in runs else 0


def fisher_p(count: int, runs: int, count_ref: int, runs_ref: int) -> float:
    """Two-sided Fisher exact p of ``count`` of ``runs`` against ``count_ref`` of ``runs_ref`` (how often counts
    this far apart arise when both cells have the same rate): 4 of 10 against 3 of 10 gives 1.0."""
    _, p = fisher_exact([[count, runs - count], [count_ref, runs_ref - count_ref]])  # (odds ratio, p)
    return float(cast(SupportsFloat, p))  # cast: scipy's stub types the result's items as object


def _versus(filtered: pd.DataFrame, alone: pd.DataFrame, col: str) -> str:
    """"N vs M (p P)": the filtered runs' count of ``col`` against alone, with :func:`fisher_p`."""
    n, n_alone = _count(filtered, col), _count(alone, col)
    p = fisher_p(n, len(filtered), n_alone, len(alone))
    return f"{n} vs {n_alone} ({f'p {p:.2f}' if p >= 0.01 else 'p < 0.01'})"


def target_sentences(frame: pd.DataFrame, robot: str) -> list[str]:
    """One sentence per target of the study for ``robot`` (met / missed, with the numbers)."""
    out = []
    flat = _finished(cell(frame, robot, "flat", "policy", "nominal"))
    if len(flat):
        speed = _mean(flat, "mean_speed_mps")
        command = _mean(flat, "commanded_speed_mps")
        command = COMMAND_MPS if math.isnan(command) else command
        ok = _count(flat, "fell") == 0 and abs(speed - command) <= SPEED_TOLERANCE_MPS
        out.append(f"**{'met' if ok else 'missed'}**: the policy alone on flat ground: {_count(flat, 'fell')} falls "
                   f"in {len(flat)} runs, mean forward speed {speed:.3f} m/s at a {command:.3g} m/s command "
                   f"(target: 0 falls, within {SPEED_TOLERANCE_MPS} m/s).")
    for controller in CONTROLLERS:
        alone = _finished(cell(frame, robot, "flat", controller, "nominal"))
        for variant in FILTERS:
            filtered = _finished(cell(frame, robot, "flat", controller, variant))
            if not len(filtered) or not len(alone):
                continue
            torque = _mean(filtered, "intervention_nm_mean")
            added = _count(filtered, "fell") - _count(alone, "fell")
            ok = torque <= MAX_FLAT_INTERVENTION_NM and added <= 0
            out.append(f"**{'met' if ok else 'missed'}**: minimally invasive, {controller} + {variant} filter on flat "
                       f"ground: mean intervention {torque:.2f} N·m (target <= {MAX_FLAT_INTERVENTION_NM}), falls "
                       f"{_count(filtered, 'fell')} vs {_count(alone, 'fell')} alone.")
    for controller in CONTROLLERS:
        for variant in FILTERS[1:]:  # the terrain filters
            out += _no_harm(frame, robot, controller, variant)
            out += _helps(frame, robot, controller, variant)
    return out


def _shorter(filtered: pd.DataFrame, alone: pd.DataFrame) -> bool:
    """The filtered runs' mean distance is lower than the controller's alone by more than MAX_DISTANCE_LOSS."""
    d_alone, d_filtered = _mean(alone, "distance_m"), _mean(filtered, "distance_m")
    return not math.isnan(d_alone) and d_alone > 0 and d_filtered < (1.0 - MAX_DISTANCE_LOSS) * d_alone


def _no_harm(frame: pd.DataFrame, robot: str, controller: str, variant: str) -> list[str]:
    worse = []
    judged = 0
    for world in _worlds(frame):
        alone = _finished(cell(frame, robot, world, controller, "nominal"))
        terrain = _finished(cell(frame, robot, world, controller, variant))
        if not len(alone) or not len(terrain):
            continue
        judged += 1
        d_alone, d_terrain = _mean(alone, "distance_m"), _mean(terrain, "distance_m")
        reasons = []
        for col, label in (("fell", "falls"), ("unsafe", "unsafe runs")):
            if _count(terrain, col) > _count(alone, col):
                reasons.append(f"{label} {_versus(terrain, alone, col)}")
        if _shorter(terrain, alone):
            reasons.append(f"distance {d_terrain:.2f} vs {d_alone:.2f} m")
        if reasons:
            worse.append(f"{world} ({', '.join(reasons)})")
    if not judged:
        return []
    verdict = "met" if not worse else "missed"
    detail = "no world worse" if not worse else "worse on " + "; ".join(worse)
    return [f"**{verdict}**: do no harm, {controller} + {variant} filter vs {controller} alone over {judged} worlds: "
            f"{detail} (falls and unsafe runs no more, distance at most {MAX_DISTANCE_LOSS:.0%} lower)."]


def _helps(frame: pd.DataFrame, robot: str, controller: str, variant: str) -> list[str]:
    out = []
    slippery, rough_better, rough_judged = [], [], 0
    for world in _worlds(frame):
        base = world.split()[0]
        alone = _finished(cell(frame, robot, world, controller, "nominal"))
        terrain = _finished(cell(frame, robot, world, controller, variant))
        if not len(alone) or not len(terrain):
            continue
        if base in SLIPPERY:
            versus = _versus(terrain, alone, "unsafe")
            slippery.append((world, _count(terrain, "unsafe"), _count(alone, "unsafe"), versus))
        if base in ROUGH:
            rough_judged += 1
            # fewer trips counts only without more falls and without a shorter walk: a run that falls early, or
            # is held back, has less time and ground to trip on
            falls, falls_alone = _count(terrain, "fell"), _count(alone, "fell")
            fewer_trips = (falls <= falls_alone and _mean(terrain, "trips") < _mean(alone, "trips")
                           and not _shorter(terrain, alone))
            if falls < falls_alone or fewer_trips:
                rough_better.append(world)
    if slippery:
        ok = all(t < a for _, t, a, _ in slippery)
        cells = ", ".join(f"{w}: {versus}" for w, _, _, versus in slippery)
        out.append(f"**{'met' if ok else 'missed'}**: helps on slippery ground, {controller} + {variant} filter: "
                   f"unsafe runs vs alone: {cells} (target: strictly fewer on each).")
    if rough_judged:
        ok = len(rough_better) >= 2
        better = ", ".join(rough_better) or "none"
        out.append(f"**{'met' if ok else 'missed'}**: helps on rough ground, {controller} + {variant} filter: fewer "
                   f"falls, or fewer trips with no more falls and no shorter walk, than alone on "
                   f"{len(rough_better)} of {rough_judged} worlds ({better}; target: at least 2).")
    return out


def policy_section(frame: pd.DataFrame) -> str:
    """Markdown section of the report ("" unless the sweep has a learned policy beside a filter axis)."""
    if frame.empty or not is_policy_study(frame):
        return ""
    parts = ["## Filters on the deployed controllers: blind trot and learned policy\n",
             ("Per robot and world: each nominal controller (`trot`: the paper's blind trot; `policy`: the robot's "
              "shipped learned policy) alone (`nominal`), with the paper's filter (`paper`), the terrain filter "
              "(`terrain`), the terrain filter that lets go of feet the nominal lifts (`release`, "
              "`filter=terrain_release`), the terrain filter with bounded corrections (`bounded`) and the one that "
              "moves a stance leg only to stop its foot sliding (`guarded`, `filter=terrain_guarded`), those the "
              "sweep ran. Means over finished runs "
              "(`runs` = finished/all); `unsafe` = runs whose verdict is `safe: false`, with the reasons' counts. "
              "The targets compare counts; beside each count compared, `p` is the two-sided Fisher exact test of "
              "the two counts over their runs (with 10 runs a cell, one or two runs apart gives p of 0.5 to 1: "
              "the sentence's met or missed is then not a measured difference).\n")]
    robots = sorted(set(frame["robot"].astype(str))) if "robot" in frame else ["a1"]
    for robot in robots:
        table = comparison_table(frame, robot)
        if len(table):
            parts += [f"### {robot}\n", markdown_table(table, fmt=str)]
        sentences = target_sentences(frame, robot)
        if sentences:
            parts += [f"#### Targets ({robot})\n", "\n".join(f"- {s}" for s in sentences) + "\n"]
    return "\n".join(parts)
