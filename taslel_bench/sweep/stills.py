"""The sweep report's still strips: for every finished run that fell or tripped, the second before the event
as a row of frames (PNG) rendered from the run's steps.parquet (:mod:`taslel_bench.record.video`), linked to
the run's ``video.mp4`` or, when the run has none (``record.video=false``), to a clip of the event
rendered beside the strip (from 2 s before to 0.5 s after it).

Beside each strip, the command replaying the run in MuJoCo Studio's web viewer (:func:`view_command`).

The event is the fall (``time_to_fall_s``) or, for a run that did not fall, the first trip
(``first_trip_s``: the first of the onsets ``trips`` counts, :mod:`taslel_bench.metrics.clearance`).
Files: ``<sweep>/stills/<run>.png`` (and ``.mp4``). With ``keep=True`` (``python -m taslel_bench.report
<sweep> --keep-stills``) a strip, and its clip, newer than every file of its run is kept as it is, not drawn
again (a 420-run sweep's 210 strips and clips take ~15 min); a change of the drawing code is not seen then.

At most ``max_strips`` events (default MAX_STRIPS; ``--max-stills`` of the report command,
``hydra.callbacks.sweep_report.max_still_strips`` of a sweep) are drawn, ~3 s each: first the earliest event of
each group of the sweep's axes (robot, scenario and its friction, controller, filter, solver, estimator), then the
others in the table's order; every other event is listed with its time and replay command, without a strip.
"""

from __future__ import annotations

import logging
import re
import shlex
import traceback
from pathlib import Path

import numpy as np
import pandas as pd
from omegaconf import OmegaConf

from taslel_bench.record import run_files
from taslel_bench.robot import quadruped as quad

logger = logging.getLogger(__name__)

STILLS_DIR = "stills"
STRIP_OFFSETS_S = (-1.0, -0.75, -0.5, -0.25, 0.0)  # [s] frame times relative to the event
STILL_SIZE = (256, 192)  # [px] width, height of one frame
CLIP_WINDOW_S = (-2.0, 0.5)  # [s] the event clip, relative to the event
FPS = 30.0
PROGRESS_EVERY = 20  # runs between progress lines while the stills render
VIEW_LEAD_S = 1.0  # [s] the viewer command opens the run this long before the event
MAX_STRIPS = 100  # events drawn as strips and clips per report (~3 s each); the rest are listed
GROUP_KEYS = ("robot", "scenario", "scenario.friction", "controller", "filter_variant", "solver", "estimator")


def event_of_run(run_dir: Path, row: pd.Series) -> tuple[str, float] | None:
    """("fall", t) or ("trip", t) [s of simulated time] of a run, or None (no fall, no trip)."""
    if bool(row.get("fell")) and np.isfinite(float(row.get("time_to_fall_s", np.nan))):
        return "fall", float(row["time_to_fall_s"])
    trips = row.get("trips")
    if trips is None or not np.isfinite(float(trips)) or float(trips) <= 0:
        return None
    t = row.get("first_trip_s")  # the summary's own first trip (taslel_bench.metrics.clearance)
    if t is None or not np.isfinite(float(t)):
        t = first_trip_s(run_dir)  # a summary written before first_trip_s existed
    return ("trip", float(t)) if t is not None else None


def first_trip_s(run_dir: Path) -> float | None:
    """Simulated time [s] of the first walking tick with a swing foot or a lower leg on an obstacle (from
    steps.parquet, for summaries without ``first_trip_s``; it also counts a contact continuing from stance)."""
    cfg = OmegaConf.load(Path(run_dir) / "config.yaml")
    legs = [*(f"{leg}_obstacle_contact" for leg in quad.LEGS), *(f"{leg}_stance" for leg in quad.LEGS)]
    steps = pd.read_parquet(Path(run_dir) / run_files.STEPS, columns=["t_s", "nonfoot_obstacle_contact", *legs])
    touch = steps["nonfoot_obstacle_contact"].to_numpy(bool).copy()
    for leg in quad.LEGS:
        touch |= steps[f"{leg}_obstacle_contact"].to_numpy(bool) & ~steps[f"{leg}_stance"].to_numpy(bool)
    touch &= steps["t_s"].to_numpy() >= float(cfg.controller.stand_duration)
    hits = np.flatnonzero(touch)
    return float(steps["t_s"].iloc[hits[0]]) if hits.size else None


def _name(run_dir: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", run_dir).strip("_") or "run"


def still_strip(run_dir: Path, t_event_s: float, out: Path) -> Path:
    """The frames at :data:`STRIP_OFFSETS_S` around ``t_event_s``, side by side, as a PNG at ``out``."""
    from PIL import Image

    from taslel_bench.record.video import RunFrames, plant_of_run, run_record

    steps, summary, events = run_record(run_dir)
    frames = RunFrames(plant_of_run(run_dir), steps, *STILL_SIZE, summary, events)
    try:
        images = []
        for offset in STRIP_OFFSETS_S:
            row = int(np.clip(np.rint((t_event_s + offset - frames.t_s[0]) / frames.dt_s) - 1, 0, len(frames.t_s) - 1))
            images.append(frames.frame(row))
    finally:
        frames.renderer.close()
    strip = np.concatenate(images, axis=1)
    out.parent.mkdir(parents=True, exist_ok=True)
    run_files.atomic_write(out, lambda p: Image.fromarray(strip).save(p, format="PNG"))
    return out


def view_command(run_dir: str, t_event_s: float) -> str:
    """The command replaying the run in MuJoCo Studio's web viewer (:mod:`taslel_bench.view`), run from the sweep
    folder, opened :data:`VIEW_LEAD_S` before the event (simulated time [s])."""
    return f"python -m taslel_bench.view {shlex.quote(run_dir)} --time {max(t_event_s - VIEW_LEAD_S, 0.0):.3f}"


def _video_link(sweep_dir: Path, run_dir: str, t_event_s: float, name: str, keep: bool = False) -> str:
    """The run's video.mp4 (relative to the sweep folder), else a clip of the event rendered now (``keep``: or
    kept from before when it is newer than the run's files)."""
    from taslel_bench.record.video import VIDEO_NAME, render_video

    if (sweep_dir / run_dir / VIDEO_NAME).is_file():
        return f"{run_dir}/{VIDEO_NAME}"
    clip = Path(STILLS_DIR) / f"{name}.mp4"
    if keep and _up_to_date(sweep_dir / clip, sweep_dir / run_dir):
        return str(clip)
    t0, t1 = t_event_s + CLIP_WINDOW_S[0], t_event_s + CLIP_WINDOW_S[1]
    render_video(sweep_dir / run_dir, sweep_dir / clip, fps=FPS, width=STILL_SIZE[0] * 2, height=STILL_SIZE[1] * 2,
                 t0_s=max(0.0, t0), t1_s=t1)  # fmt: skip
    return str(clip)


def _event_or_error(run_dir: Path, row: pd.Series) -> tuple[str, float] | str | None:
    """:func:`event_of_run`, or the last line of its traceback when it fails (reported as the run's missing still)."""
    try:
        return event_of_run(run_dir, row)
    except Exception:  # a still that cannot be drawn is reported, the report is still written
        return traceback.format_exc().strip().splitlines()[-1]


def strip_order(events: list) -> list[int]:
    """Indices of ``events`` ((run_dir, row, event) in table order) in drawing order: the earliest event of each
    group of GROUP_KEYS first, then the rest, each part in table order; failed events (text) never drawn."""
    seen: set[tuple] = set()
    first, rest = [], []
    for i, (_, row, event) in enumerate(events):
        if isinstance(event, str):
            continue
        group = tuple(str(row.get(k, "")) for k in GROUP_KEYS)
        (rest if group in seen else first).append(i)
        seen.add(group)
    return first + rest


def _up_to_date(out: Path, run_dir: Path) -> bool:
    """``out`` exists and is newer than every file of the run (summary, steps, events, config)."""
    if not out.is_file():
        return False
    newest = max((f.stat().st_mtime for f in run_dir.iterdir() if f.is_file()), default=0.0)
    return out.stat().st_mtime >= newest


def still_strips(sweep_dir: Path, frame: pd.DataFrame, keep: bool = False, max_strips: int = MAX_STRIPS) -> list[str]:
    """Report lines: per finished run that fell or tripped, its still strip linked to its video (``keep``:
    strips and clips newer than their run's files are not drawn again); at most ``max_strips`` drawn (module
    doc), the other events listed with their replay command."""
    if frame.empty or "run_dir" not in frame or "status" not in frame:
        return []
    lines: list[str] = []
    runs = [(str(row["run_dir"]), row) for _, row in frame[frame["status"].isin(("ok", "degraded"))].iterrows()]
    events = [(run_dir, row, _event_or_error(sweep_dir / run_dir, row)) for run_dir, row in runs]
    events = [(run_dir, row, event) for run_dir, row, event in events if event is not None]
    drawn = set(strip_order(events)[:max(0, max_strips)])
    for i, (run_dir, row, event) in enumerate(events):
        if i % PROGRESS_EVERY == 0:  # ~3 s per run: a large sweep's report renders for minutes
            logger.info("report: still strips and clips %d/%d", i, len(events))
        if isinstance(event, str):  # event_of_run failed
            lines.append(f"- `{run_dir}`: no still ({event})\n")
            continue
        kind, t = event
        reason = f" ({row.get('fall_reason')})" if kind == "fall" else ""
        if i not in drawn:
            lines.append(f"- `{run_dir}`: {kind} at {t:.3f} s{reason}; replay: `{view_command(run_dir, t)}`\n")
            continue
        try:
            name = _name(run_dir)
            png = sweep_dir / STILLS_DIR / f"{name}.png"
            if not (keep and _up_to_date(png, sweep_dir / run_dir)):
                still_strip(sweep_dir / run_dir, t, png)
            link = _video_link(sweep_dir, run_dir, t, name, keep)
            lines.append(f"- `{run_dir}`: {kind} at {t:.3f} s{reason}; frames at "
                         f"{', '.join(f'{o:+g}' for o in STRIP_OFFSETS_S)} s, [video]({link}); "
                         f"replay: `{view_command(run_dir, t)}`\n\n"
                         f"  [![{kind} of {run_dir}]({png.relative_to(sweep_dir)})]({link})\n")  # fmt: skip
        except Exception:  # a still that cannot be drawn is reported, the report is still written
            lines.append(f"- `{run_dir}`: no still ({traceback.format_exc().strip().splitlines()[-1]})\n")
    drawable = sum(not isinstance(event, str) for _, _, event in events)  # a failed event is listed, never drawn
    if drawable > len(drawn):
        lines.append(f"_Strips drawn for {len(drawn)} of {drawable} events (the first of each group first; "
                     f"`--max-stills` sets the number)._\n")
    if not lines:
        return []
    head = ("## The second before each fall or trip\n\nRendered from each run's steps.parquet (MuJoCo's offscreen "
            "renderer; blue arrows: MuJoCo contact forces); a still links to the run's video. The `replay:` command, "
            "run in the sweep folder, replays the run in MuJoCo Studio's web viewer (a browser page on 127.0.0.1; "
            "time scrubber, force arrows, the events on a timeline) from a second before the event.\n")  # fmt: skip
    return [head, *lines]
