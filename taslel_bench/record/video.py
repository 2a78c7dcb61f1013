"""A video of a run (``video.mp4``) and stills, rendered from ``steps.parquet`` with MuJoCo's offscreen
``Renderer`` (headless: EGL, or OSMesa with ``MUJOCO_GL=osmesa``).

A row of ``steps.parquet`` holds the plant's full state at the end of its tick (trunk pose, joints), so the
plant rebuilt from the run's ``config.yaml`` is posed row by row (``mj_forward``) and drawn: frame i shows
the state at simulated time i / fps (the row whose end-of-tick time is nearest), seen by a camera tracking
the trunk, with the MuJoCo contact force of each loaded foot as a blue arrow (the recorded force, at the
recorded foot position) and text overlays: simulated time, the run's status and verdict (``safe`` /
``unsafe_reasons`` of the summary when it has them, else the status alone), the phase (stand / walking)
and the events (QP failures, falls) as they happen. MP4 (H.264) written through imageio-ffmpeg.

Entry point: ``python -m taslel_bench.render <run folder>`` (:mod:`taslel_bench.render`); ``record.video=true``
renders at the end of a run.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from omegaconf import OmegaConf

from taslel_bench.plant.contacts import foot_radius_m
from taslel_bench.record import run_files
from taslel_bench.robot import quadruped as quad

if TYPE_CHECKING:
    from PIL import ImageFont

VIDEO_NAME = "video.mp4"
FORCE_SCALE_M_PER_N = 0.004  # [m/N] arrow length per newton (as in the Foxglove scene)
CAMERA = {"distance": 1.4, "azimuth": 130.0, "elevation": -18.0}  # [m], [deg], [deg] tracking the trunk
HEADLIGHT = {"ambient": (0.45, 0.45, 0.45), "diffuse": (0.6, 0.6, 0.6)}
EVENT_SHOW_S = 0.6  # [s] an event's text stays this long (a fall: to the end)
STATE_COLUMNS = [*(f"base_{ax}_w_m" for ax in "xyz"), *(f"base_quat_{c}" for c in "wxyz"),
                 *(f"q_{j.removesuffix('_joint')}_rad" for j in quad.JOINT_NAMES)]  # fmt: skip
FOOT_COLUMNS = [f"{leg}_foot_{ax}_w_m" for leg in quad.LEGS for ax in "xyz"]
FORCE_COLUMNS = [f"{leg}_grf_plant_{ax}_w_n" for leg in quad.LEGS for ax in "xyz"]


class GLUnavailable(RuntimeError):
    """No headless OpenGL context could be made (the message says what to install or set)."""


def use_headless_gl() -> str:
    """Point MuJoCo's Renderer at a headless GL context: ``MUJOCO_GL`` if set (``egl`` or ``osmesa``), else
    EGL. Returns the backend. MuJoCo reads ``MUJOCO_GL`` when it is imported; this also works when it was
    imported before the variable was set (the renderer looks its context class up at construction)."""
    from mujoco.rendering.classic import gl_context

    backend = os.environ.get("MUJOCO_GL", "").strip().lower() or "egl"
    if backend not in ("egl", "osmesa"):
        return backend  # glfw/glx: the user's choice (needs a display)
    os.environ.setdefault("MUJOCO_GL", backend)
    try:
        if backend == "egl":
            from mujoco.egl import GLContext
        else:
            from mujoco.osmesa import GLContext
    except Exception as exc:
        raise GLUnavailable(_gl_help(backend, exc)) from exc
    gl_context.GLContext = GLContext
    return backend


def _gl_help(backend: str, exc: BaseException) -> str:
    return (f"MuJoCo's offscreen renderer could not use MUJOCO_GL={backend} ({type(exc).__name__}: {exc}). "
            "Headless rendering needs Debian's libegl1 and libgl1-mesa-dri (MUJOCO_GL=egl, the default) or "
            "libosmesa6 (MUJOCO_GL=osmesa): apt-get install -y libegl1 libgl1-mesa-dri libosmesa6")  # fmt: skip


def frame_rows(t_s: np.ndarray, dt_s: float, fps: float, t0_s: float = 0.0, t1_s: float | None = None) -> np.ndarray:
    """Row index of each frame: frame i shows simulated time t0 + i / fps (up to ``t1_s``, default the end
    of the last tick), the row whose end-of-tick time t_s + dt is nearest."""
    end = float(t_s[-1]) + dt_s if t1_s is None else min(float(t1_s), float(t_s[-1]) + dt_s)
    n = int(np.floor((end - t0_s) * fps + 1e-9)) + 1
    times = t0_s + np.arange(max(n, 0)) / fps
    return np.clip(np.rint((times - float(t_s[0])) / dt_s).astype(int) - 1, 0, len(t_s) - 1)


class RunFrames:
    """Frames of one run's recorded states: the plant model posed from steps.parquet rows, a camera
    tracking the trunk, force arrows, and the overlays."""

    def __init__(self, model, steps: pd.DataFrame, width: int, height: int, summary: dict | None = None,
                 events: Sequence[dict] = ()) -> None:  # fmt: skip
        import mujoco

        use_headless_gl()
        self.m, self.d = model, mujoco.MjData(model)
        self.steps, self.summary, self.events = steps, dict(summary or {}), list(events)
        self.width, self.height = int(width) // 2 * 2, int(height) // 2 * 2  # H.264 (yuv420p): even sizes
        self.model_size_check()
        try:
            self.renderer = mujoco.Renderer(model, self.height, self.width)
        except Exception as exc:
            raise GLUnavailable(_gl_help(os.environ.get("MUJOCO_GL", "egl"), exc)) from exc
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.camera.trackbodyid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
        self.camera.distance, self.camera.azimuth, self.camera.elevation = (
            CAMERA["distance"], CAMERA["azimuth"], CAMERA["elevation"])  # fmt: skip
        self._qadr = qpos_addresses(model)
        self._state = steps[STATE_COLUMNS].to_numpy(float)
        self._feet = steps[FOOT_COLUMNS].to_numpy(float).reshape(-1, quad.N_LEGS, 3)
        self._forces = steps[FORCE_COLUMNS].to_numpy(float).reshape(-1, quad.N_LEGS, 3)
        self.t_s = steps["t_s"].to_numpy(float)
        self.dt_s = float(np.median(np.diff(self.t_s))) if len(self.t_s) > 1 else 1e-3

    def model_size_check(self) -> None:
        """The offscreen buffer must hold the frame (MuJoCo's default is 640x480); a brighter headlight
        (the plant has no lights). Visual settings only: the model's physics is untouched."""
        vis = self.m.vis.global_
        vis.offwidth, vis.offheight = max(vis.offwidth, self.width), max(vis.offheight, self.height)
        self.m.vis.headlight.ambient[:] = HEADLIGHT["ambient"]
        self.m.vis.headlight.diffuse[:] = HEADLIGHT["diffuse"]

    def frame(self, row: int) -> np.ndarray:
        """(height, width, 3) uint8 image of the state of ``row``, with arrows and overlays."""
        import mujoco

        self.d.qpos[self._qadr] = self._state[row]
        self.d.qvel[:] = 0.0
        mujoco.mj_forward(self.m, self.d)
        self.renderer.update_scene(self.d, camera=self.camera)
        self._add_force_arrows(row)
        image = self.renderer.render()
        return _overlay(image, self._overlay_lines(row))

    def _add_force_arrows(self, row: int) -> None:
        import mujoco

        scene = self.renderer.scene
        for foot, force in zip(self._feet[row], self._forces[row], strict=True):
            norm = float(np.linalg.norm(force))
            if not np.isfinite(norm) or norm < 1.0 or scene.ngeom >= scene.maxgeom:
                continue
            tail = foot - np.array([0.0, 0.0, foot_radius_m(self.m)])
            geom = scene.geoms[scene.ngeom]
            mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), np.zeros(3), np.zeros(9),
                                np.array([0.15, 0.45, 0.95, 1.0], np.float32))  # fmt: skip
            mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_ARROW, 0.01, tail, tail + force * FORCE_SCALE_M_PER_N)
            scene.ngeom += 1

    def _overlay_lines(self, row: int) -> list[tuple[str, tuple[int, int, int]]]:
        t = self.t_s[row] + self.dt_s  # the state's time (end of the tick)
        stand = float(self.summary.get("stand_duration_s", 0.0) or 0.0)
        lines = [(f"t = {t:6.3f} s" + ("  (stand)" if t < stand else ""), (255, 255, 255)),
                 (f"status: {self.summary.get('status', '?')}", (255, 255, 255)),
                 (verdict_text(self.summary), (255, 255, 255))]  # fmt: skip
        for e in self.events:
            te = e.get("t_s")
            if te is None or not (te <= t and (t - te <= EVENT_SHOW_S or e.get("kind") == "fall")):
                continue
            lines.append((f"{e.get('kind')} at {te:.3f} s: {str(e.get('message', ''))[:48]}", (255, 80, 80)))
        return lines[:8]


def verdict_text(summary: dict) -> str:
    """The safety verdict of a summary: ``safe`` / ``unsafe: reasons`` when it has the keys, else a note
    and the fall/trip counts it has."""
    if "safe" in summary:
        reasons = summary.get("unsafe_reasons") or ""
        return "verdict: safe" if summary["safe"] is True else f"verdict: UNSAFE {reasons}".strip()
    fell = summary.get("fell")
    trips = summary.get("trips")
    parts = ([f"fell ({summary.get('fall_reason')})"] if fell else []) + ([f"{int(trips)} trips"] if trips else [])
    return "verdict: n/a" + (f"; {', '.join(parts)}" if parts else "")


def qpos_addresses(model) -> np.ndarray:
    """qpos indices of STATE_COLUMNS: the free joint's position and quaternion, then the 12 joints."""
    import mujoco

    free = next(j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    joints = [model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)] for name in quad.JOINT_NAMES]
    return np.array([*range(model.jnt_qposadr[free], model.jnt_qposadr[free] + 7), *joints])


def _overlay(image: np.ndarray, lines: list[tuple[str, tuple[int, int, int]]]) -> np.ndarray:
    """Text lines on a dark band at the top-left of the image (PIL's default font)."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(image)
    draw = ImageDraw.Draw(img)
    line_h = max(11, img.height // 24)
    font = _font(line_h - 2)
    lines = [(_fit(draw, text, font, img.width - 10), colour) for text, colour in lines]
    width = max((draw.textlength(text, font=font) for text, _ in lines), default=0)
    draw.rectangle([0, 0, int(width) + 10, line_h * len(lines) + 6], fill=(0, 0, 0))
    for i, (text, colour) in enumerate(lines):
        draw.text((5, 3 + i * line_h), text, fill=colour, font=font)
    return np.asarray(img)


# PIL's default font per size (loading it costs more than drawing a line)
_FONTS: dict[int, ImageFont.FreeTypeFont | ImageFont.ImageFont] = {}
_FITTED: dict[tuple[str, int, int], str] = {}  # (text, font size, width) -> the text cut to fit: lines repeat
_FITTED_MAX = 4096  # entries kept (a long video's lines change every frame only in their time stamp)


def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """PIL's default font at ``size`` px, loaded once."""
    from PIL import ImageFont

    font = _FONTS.get(size)
    if font is None:
        font = _FONTS[size] = ImageFont.load_default(size=size)
    return font


def _fit(draw, text: str, font, width_px: int) -> str:
    """``text`` cut (with an ellipsis) to the longest prefix that fits ``width_px``: a binary search over the
    prefix length (a verdict line has hundreds of characters; cutting one at a time measured the text ~300
    times per frame, 2/3 of a clip's rendering time), remembered per text, font size and width."""
    key = (text, int(getattr(font, "size", 0)), width_px)
    fitted = _FITTED.get(key)
    if fitted is not None:
        return fitted
    if draw.textlength(text, font=font) <= width_px:
        fitted = text
    else:
        lo, hi = 0, len(text)  # text[:lo] + "..." fits (or lo = 0); text[:hi] + "..." does not
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if draw.textlength(text[:mid] + "...", font=font) <= width_px:
                lo = mid
            else:
                hi = mid
        fitted = text[:lo] + "..."
    if len(_FITTED) >= _FITTED_MAX:
        _FITTED.clear()
    _FITTED[key] = fitted
    return fitted


# ------------------------------------------------------------------------------------------- run folders
def plant_of_run(run_dir: Path):
    """The run's MuJoCo plant, rebuilt from its config.yaml (the scenario's terrain and edits)."""
    from taslel_bench.config.axes import build_axis
    from taslel_bench.config.schema import load_run_config
    from taslel_bench.config.settings import robot_description
    from taslel_bench.sim.build import build_plant_model

    cfg = load_run_config(Path(run_dir) / "config.yaml")
    return build_plant_model(cfg, robot_description(cfg), build_axis(cfg, "scenario"),
                             np.random.default_rng(int(cfg.seed)))


def run_record(run_dir: Path) -> tuple[pd.DataFrame, dict, list[dict]]:
    """steps.parquet, summary.json ({} while the run is not complete) and events.json of a run folder."""
    run_dir = Path(run_dir)
    steps = pd.read_parquet(run_dir / run_files.STEPS, columns=["t_s", *STATE_COLUMNS, *FOOT_COLUMNS, *FORCE_COLUMNS])
    summary = json.loads((run_dir / run_files.SUMMARY).read_text()) if (run_dir / run_files.SUMMARY).is_file() else {}
    events = json.loads((run_dir / run_files.EVENTS).read_text()) if (run_dir / run_files.EVENTS).is_file() else []
    return steps, summary, events


def write_mp4(path: Path, frames, width: int, height: int, fps: float) -> int:
    """Encode ``frames`` (an iterable of (h, w, 3) uint8) to an H.264 MP4 at ``path``, atomically (a
    temporary name renamed into place). Returns the number of frames written."""
    import imageio_ffmpeg

    count = 0

    def encode(tmp: Path) -> None:
        nonlocal count
        writer = imageio_ffmpeg.write_frames(str(tmp), (width, height), codec="libx264", quality=6,
                                             fps=fps,  # pyright: ignore[reportArgumentType] imageio_ffmpeg is unannotated: int inferred from the default; it takes a float
                                             pix_fmt_out="yuv420p", macro_block_size=2,
                                             output_params=["-f", "mp4"])  # fmt: skip
        writer.send(None)
        try:
            for image in frames:
                writer.send(np.ascontiguousarray(image))
                count += 1
        finally:
            writer.close()

    run_files.atomic_write(Path(path), encode)
    return count


def render_video(run_dir: Path, out: Path | None = None, *, model=None, summary: dict | None = None,
                 fps: float = 30.0, width: int = 480, height: int = 360,
                 t0_s: float = 0.0, t1_s: float | None = None) -> tuple[Path, int]:  # fmt: skip
    """Render the run in ``run_dir`` (steps.parquet; the plant from config.yaml unless ``model`` is given;
    the summary and events for the overlays) from simulated time ``t0_s`` to ``t1_s`` into ``out``
    (default ``<run>/video.mp4``). Returns (path, frames written)."""
    steps, saved_summary, events = run_record(run_dir)
    summary = {**saved_summary, **(summary or {})}
    summary.setdefault("stand_duration_s", _stand_duration(run_dir))
    frames = RunFrames(model if model is not None else plant_of_run(run_dir), steps, width, height, summary, events)
    rows = frame_rows(frames.t_s, frames.dt_s, fps, t0_s, t1_s)
    path = Path(out) if out is not None else Path(run_dir) / VIDEO_NAME
    try:
        n = write_mp4(path, (frames.frame(int(r)) for r in rows), frames.width, frames.height, fps)
    finally:
        frames.renderer.close()
    return path, n


def _stand_duration(run_dir: Path) -> float:
    cfg_path = Path(run_dir) / "config.yaml"
    return float(OmegaConf.load(cfg_path).controller.stand_duration) if cfg_path.is_file() else 0.0


def render_at_end_of_run(run_dir: Path, model, summary: dict, record) -> None:
    """``record.video=true``: render ``<run>/video.mp4`` once steps.parquet and events.json are written and
    before summary.json (whose keys it fills: ``video_frames``, ``video_s`` [s of wall time], or
    ``video_error``); a rendering failure is noted, never loses the run."""
    import time
    import traceback

    t = time.perf_counter()
    try:
        _, n = render_video(run_dir, model=model, summary=summary, fps=float(record.video_fps),
                            width=int(record.video_width), height=int(record.video_height))  # fmt: skip
        summary.update({"video_frames": n, "video_s": time.perf_counter() - t})
    except Exception:  # a video must not lose the run
        summary["video_error"] = traceback.format_exc().strip().splitlines()[-1]
