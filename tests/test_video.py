"""Videos of runs, headless: ``python -m taslel_bench.render`` and ``record.video=true`` in subprocesses with
``MUJOCO_GL=egl``, falling back to ``osmesa`` (each GL backend binds PyOpenGL once per process). The MP4 is
read back with imageio-ffmpeg (its own ffmpeg decodes it): frame count, size, and content."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pandas as pd
import pytest

from taslel_bench.record.video import frame_rows, verdict_text
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["duration=0.2", "progress=false", "filter.enabled=false", "record.mcap=false"]
EXPECTED_FRAMES = 22  # (0.5 s stand + 0.2 s) * 30 frames/s = 21 intervals -> frames at 0, 1/30, ..., 0.7 s


def _headless(cmd: list[str]) -> subprocess.CompletedProcess:
    """Run ``cmd`` with MUJOCO_GL=egl, then osmesa if EGL is not available; the last attempt's result."""
    for backend in ("egl", "osmesa"):
        env = {**os.environ, "MUJOCO_GL": backend, "PYTHONPATH": str(ROOT)}
        env.pop("PYOPENGL_PLATFORM", None)
        proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300, check=False)
        if proc.returncode == 0 and "video_error" not in proc.stdout:
            return proc
    return proc


def _frames(path: Path) -> list[np.ndarray]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    return [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]


def test_frame_times_cover_the_run_at_the_frame_rate():
    t_s = np.arange(700) * 1e-3  # ticks of a 0.7 s run at 1 kHz; row k holds the state at t_s[k] + 1 ms
    rows = frame_rows(t_s, 1e-3, 30.0)
    assert len(rows) == EXPECTED_FRAMES
    assert rows[0] == 0 and rows[-1] == 699 and rows[15] == round(15 / 30 / 1e-3) - 1


def test_render_a_short_run_to_an_mp4_whose_frame_count_matches(tmp_path):
    run(compose_cfg(SHORT), tmp_path)
    proc = _headless([sys.executable, "-m", "taslel_bench.render", str(tmp_path), "--width", "320", "--height", "240"])
    assert proc.returncode == 0, proc.stderr[-2000:]
    video = tmp_path / "video.mp4"
    assert video.stat().st_size > 1000
    n, _ = imageio_ffmpeg.count_frames_and_secs(str(video))
    assert n == EXPECTED_FRAMES
    frames = _frames(video)
    assert len(frames) == EXPECTED_FRAMES and frames[0].shape == (240, 320, 3)
    assert frames[-1].std() > 10  # a picture, not a blank frame
    band = frames[-1][:30, :100].mean()  # the overlay's dark band with white text
    assert band < frames[-1][120:, :].mean()


def test_bad_run_folder_is_refused(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "taslel_bench.render", str(tmp_path)], cwd=ROOT, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120, check=False)  # fmt: skip
    assert proc.returncode != 0 and "is not a run folder: no steps.parquet, config.yaml" in proc.stderr


@pytest.mark.slow
def test_record_video_renders_at_the_end_of_a_run(tmp_path):
    run_dir = tmp_path / "run"
    proc = _headless([sys.executable, "-m", "taslel_bench", *SHORT, "record.video=true", "record.video_width=160",
                      "record.video_height=120", f"hydra.run.dir={run_dir}"])  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert "video_error" not in summary, summary.get("video_error")
    assert (
        summary["video_frames"]
        == EXPECTED_FRAMES
        == imageio_ffmpeg.count_frames_and_secs(str(run_dir / "video.mp4"))[0]
    )
    assert len(pd.read_parquet(run_dir / "steps.parquet")) == 700


def test_verdict_text_reads_the_safety_keys_when_present():
    assert verdict_text({"safe": True}) == "verdict: safe"
    assert verdict_text({"safe": False, "unsafe_reasons": "fell"}) == "verdict: UNSAFE fell"
    assert verdict_text({"fell": True, "fall_reason": "trunk_height", "trips": 2}).endswith("fell (trunk_height), 2 "
                                                                                            "trips")


def test_overlay_fit_cuts_to_the_longest_prefix_that_fits():
    """The overlay's line cut (a binary search) gives what cutting one character at a time gave."""
    from PIL import Image, ImageDraw, ImageFont

    from taslel_bench.record.video import _fit

    draw = ImageDraw.Draw(Image.new("RGB", (512, 64)))
    font = ImageFont.load_default(size=14)

    def one_at_a_time(text: str, width: int) -> str:
        if draw.textlength(text, font=font) <= width:
            return text
        while text and draw.textlength(text + "...", font=font) > width:
            text = text[:-1]
        return text + "..."

    verdict = ("verdict: UNSAFE tripped: trips=22 > 0 (new contacts of a swing foot or a leg link with an obstacle); "
               "cone_edge: friction_cone_edge_rate_worst_window=0.307 > 0.25 (loaded contacts at the cone edge)")
    for text in (verdict, "t =  3.000 s", "status: ok", "x" * 300, ""):
        for width in (0, 20, 200, 502, 5000):
            fitted = _fit(draw, text, font, width)
            assert fitted == one_at_a_time(text, width), (text[:20], width)
            assert _fit(draw, text, font, width) == fitted  # remembered


def test_still_strip_of_a_fall_links_its_clip_and_a_trip_is_found_from_contacts(tmp_path):
    """The report's stills (sweep/stills.py): a fall row gets a PNG strip of 5 frames and an event clip
    (no video.mp4 in the run); the first trip is the first walking tick of a swing foot on an obstacle."""
    from PIL import Image

    from taslel_bench.sweep.stills import STILL_SIZE, STRIP_OFFSETS_S, first_trip_s, still_strips

    run_dir = tmp_path / "sweep" / "r0"
    run(compose_cfg(SHORT), run_dir)
    row = pd.Series({"run_dir": "r0", "status": "ok", "fell": True, "time_to_fall_s": 0.6, "fall_reason": "test"})
    os.environ.setdefault("MUJOCO_GL", "egl")
    lines = still_strips(tmp_path / "sweep", pd.DataFrame([row]))
    assert len(lines) == 2 and "fall at 0.600 s (test)" in lines[1] and "no still" not in lines[1]
    assert "replay: `python -m taslel_bench.view r0 --time 0.000`" in lines[1]  # from the sweep folder
    png = tmp_path / "sweep" / "stills" / "r0.png"
    assert Image.open(png).size == (STILL_SIZE[0] * len(STRIP_OFFSETS_S), STILL_SIZE[1])
    clip = tmp_path / "sweep" / "stills" / "r0.mp4"
    # 0 .. 0.7 s (the run ends)
    assert "(stills/r0.mp4)" in lines[1] and imageio_ffmpeg.count_frames_and_secs(str(clip))[0] == EXPECTED_FRAMES
    drawn = png.stat().st_mtime_ns, clip.stat().st_mtime_ns
    assert still_strips(tmp_path / "sweep", pd.DataFrame([row]), keep=True) == lines  # --keep-stills: not drawn again
    assert (png.stat().st_mtime_ns, clip.stat().st_mtime_ns) == drawn
    steps = pd.read_parquet(run_dir / "steps.parquet")
    assert first_trip_s(run_dir) is None  # flat floor: nothing to trip on
    steps.loc[600, "FL_obstacle_contact"], steps.loc[600, "FL_stance"] = True, False
    steps.loc[100, "nonfoot_obstacle_contact"] = True  # during the stand: not a trip
    steps.to_parquet(run_dir / "steps.parquet")
    assert first_trip_s(run_dir) == pytest.approx(steps["t_s"][600])
    still_strips(tmp_path / "sweep", pd.DataFrame([row]), keep=True)  # the run changed since: drawn again
    assert png.stat().st_mtime_ns > drawn[0] and clip.stat().st_mtime_ns > drawn[1]


def test_still_strips_are_capped_first_of_each_group_first_and_the_rest_listed(tmp_path):
    """With ``max_strips`` below the events: the earliest event of each group is drawn first; every other event is
    still listed, with its time and replay command, and the report says how many were drawn."""
    from taslel_bench.sweep.stills import still_strips, strip_order

    rows = [{"scenario": "logs", "filter_variant": "paper"}, {"scenario": "logs", "filter_variant": "paper"},
            {"scenario": "steps", "filter_variant": "paper"}, {"scenario": "logs", "filter_variant": "terrain"}]
    events = [(f"r{i}", pd.Series(r), ("fall", 1.0)) for i, r in enumerate(rows)]
    events.insert(1, ("bad", pd.Series(rows[0]), "ValueError: no trace"))
    assert strip_order(events) == [0, 3, 4, 2]  # r0, r2, r3 (one per group), then r1; the failed event never
    run_dir = tmp_path / "sweep" / "r0"
    run(compose_cfg(SHORT), run_dir)
    (tmp_path / "sweep" / "r1").symlink_to(run_dir, target_is_directory=True)
    fell = {"status": "ok", "fell": True, "time_to_fall_s": 0.6, "fall_reason": "test"}
    frame = pd.DataFrame([{"run_dir": "r0", **fell}, {"run_dir": "r1", **fell}])
    os.environ.setdefault("MUJOCO_GL", "egl")
    lines = still_strips(tmp_path / "sweep", frame, max_strips=1)
    assert "[video](" in lines[1] and "[video](" not in lines[2]
    assert "fall at 0.600 s (test); replay: `python -m taslel_bench.view r1 --time 0.000`" in lines[2]
    assert "Strips drawn for 1 of 2 events" in lines[3]
    assert not (tmp_path / "sweep" / "stills" / "r1.png").exists()
