"""The run viewer (``python -m taslel_bench.view``): run folders refused with what they lack, trips found as the
summary counts them, the replay posing the recorded states under Studio's controls, the force arrows, the server on
127.0.0.1 stopped by Ctrl-C, and in headless Chromium the robot drawn where the viewer's camera puts it (pixels
differ from the same viewer with the robot hidden inside the robot's projected box, and barely outside it)."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import pytest

from taslel_bench.record.video import FORCE_SCALE_M_PER_N, plant_of_run, qpos_addresses
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.run import run
from taslel_bench.view.browser import (
    HeadlessChromium,
    find_chromium,
    save_png,
    settled_screenshot,
)
from taslel_bench.view.panel import force_arrows, track_trunk
from taslel_bench.view.playback import RecordingPlayback
from taslel_bench.view.recording import NotARunFolder, check_run_folder, load_recording, trip_events
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["scenario=logs", "duration=0.3", "progress=false", "record.mcap=false"]
SHOW_S = 0.6  # [s] the state shown in the browser test (walking, 0.1 s after the stand)
PAGE = (1000, 700)  # [px] browser window
READY = r"view: a browser shows the page"
PIXEL_DIFFERS = 8  # [of 255] the largest channel difference above which a pixel differs (grey robot, grey floor)
STATUS_BAR_PX = 40  # [px] the client's bar at the bottom of the page (its frame counter changes)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("logs_run")
    run(compose_cfg(SHORT), out)
    return out


# ------------------------------------------------------------------------------------------- run folders
def test_folders_that_are_not_runs_are_refused_naming_the_path_and_what_is_missing(tmp_path):
    with pytest.raises(NotARunFolder, match=r"no_such: no such folder"):
        check_run_folder(tmp_path / "no_such")
    (tmp_path / "config.yaml").write_text("seed: 0\n")
    with pytest.raises(NotARunFolder, match=rf"{re.escape(str(tmp_path))} is not a run folder: no steps.parquet"):
        check_run_folder(tmp_path)
    sweep = tmp_path / "sweep"
    for name in ("a", "b"):
        (sweep / name).mkdir(parents=True)
        (sweep / name / "config.yaml").write_text("seed: 0\n")
        (sweep / name / "steps.parquet").write_bytes(b"")
    holds = r"no config.yaml, steps.parquet; it holds run folders, e.g. .*/a \(2 runs\)"
    with pytest.raises(NotARunFolder, match=holds):
        check_run_folder(sweep)


def test_the_command_exits_2_on_a_folder_that_is_not_a_run(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "taslel_bench.view", str(tmp_path), "--no-browser"], cwd=ROOT,
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 2, proc.stderr
    assert f"error: {tmp_path} is not a run folder: no config.yaml, steps.parquet" in proc.stderr
    assert proc.stdout == ""


def test_trips_are_the_onsets_the_summary_counts():
    """Ticks of 1 ms, stand until 0.5 s: FL swings 0.55-0.75 s, scuffs the ground at 0.6 s (phase 0.25: a trip),
    again 5 ms after it let go (the same contact: re-armed only after 10 ms), lands at 0.72 s (phase 0.85: a
    touchdown, no trip) and meets a flank at 0.74 s (a trip); RR's calf touches an obstacle at 0.7 s (a trip); FR
    meets a flank in stance (no trip); a touch during the stand is not counted."""
    n = 1000
    t = np.arange(n) * 1e-3
    cols: dict[str, np.ndarray] = {"t_s": t}
    for leg in quad.LEGS:
        cols[f"{leg}_stance"] = np.ones(n, bool)
        cols[f"{leg}_scheduled_stance"] = np.ones(n, bool)
        cols[f"{leg}_swing_phase"] = np.zeros(n)
        cols[f"{leg}_foot_touching"] = np.ones(n, bool)
        cols[f"{leg}_foot_flank_contact"] = np.zeros(n, bool)
        cols[f"{leg}_leg_link_obstacle_contact"] = np.zeros(n, bool)
    cols["FL_stance"][550:750] = cols["FL_scheduled_stance"][550:750] = False  # FL swings 0.55-0.75 s
    cols["FL_swing_phase"][550:750] = np.arange(200) / 200
    cols["FL_foot_touching"][[*range(100, 110), *range(550, 750)]] = False
    cols["FL_foot_touching"][[*range(600, 605), *range(610, 612), *range(720, 750)]] = True
    cols["FL_foot_flank_contact"][740:745] = True
    cols["FR_foot_flank_contact"][800:810] = True
    cols["RR_leg_link_obstacle_contact"][700:720] = True
    events = trip_events(pd.DataFrame(cols), stand_s=0.5, dt_s=1e-3)
    assert [(round(e.t_s, 6), e.text) for e in events] == [(0.6, "FL foot scuffed the ground lifting"),
                                                           (0.7, "RR leg link hit an obstacle"),
                                                           (0.74, "FL foot struck a flank")]


def test_a_recorded_run_loads_with_its_rows_times_and_summary(run_dir):
    rec = load_recording(run_dir)
    assert rec.n == 800 and rec.dt_s == pytest.approx(1e-3)  # 0.5 s stand + 0.3 s, 1 kHz
    assert rec.state_time(0) == pytest.approx(1e-3) and rec.row_at(SHOW_S) == 599
    assert rec.state.shape == (800, 19) and rec.feet_w.shape == (800, 4, 3)
    assert rec.summary["scenario"] == "logs"
    assert sum(e.kind == "trip" for e in rec.events) == rec.summary.get("trips", 0)


# ------------------------------------------------------------------------------------------- the replay
class _Handle:
    """What the replay needs of Studio's ViewerHandle: the messages it sends to the viewer."""

    def __init__(self) -> None:
        self.sent: list = []

    def send_to_viewer(self, message) -> None:
        self.sent.append(message)


def _started_playback(rec, model, data, **kwargs) -> tuple[RecordingPlayback, _Handle]:
    from mujoco.studio import messages

    playback, handle = RecordingPlayback(rec, **kwargs), _Handle()
    playback.handle = handle  # pyright: ignore[reportAttributeAccessIssue]
    playback._on_post_model(messages.PostModelEvent(model=model, data=data))
    return playback, handle


def test_the_replay_poses_the_plant_from_the_recording_and_follows_studios_controls(run_dir):
    from mujoco.studio import messages, sim
    from mujoco.studio.sim_history import SimHistorySnapshot

    rec, model = load_recording(run_dir), plant_of_run(run_dir)
    data = mujoco.MjData(model)
    playback, handle = _started_playback(rec, model, data, start_row=rec.row_at(SHOW_S))
    playback._on_step(messages.StepEvent(model=model, data=data))
    np.testing.assert_array_equal(data.qpos[qpos_addresses(model)], rec.state[599])
    assert data.time == pytest.approx(SHOW_S)
    feet = [data.geom_xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_foot")] for leg in quad.LEGS]
    np.testing.assert_allclose(feet, rec.feet_w[600], atol=1e-9)  # the next tick's foot sensors: this state's feet
    np.testing.assert_array_equal(rec.feet_shown_w(599), rec.feet_w[600])
    history = [m for m in handle.sent if isinstance(m, SimHistorySnapshot)][-1]
    assert (history.size, history.index) == (800, 599 - 799)
    playback._on_scrub(SimHistorySnapshot(index=-700))  # Studio's scrubber: 0 is the last tick
    playback._on_single_step(messages.SingleStepEvent())
    t0 = time.monotonic()
    playback._on_step(messages.StepEvent(model=model, data=data))
    assert playback.row == 100 and data.time == pytest.approx(rec.state_time(100))
    run_now = messages.StepControlSnapshot(pause_state=sim.PauseState.UNPAUSED, speed=100.0)  # Run, real time
    playback._on_step_control(run_now)
    time.sleep(0.2)
    playback._on_step(messages.StepEvent(model=model, data=data))
    wall_ms = (time.monotonic() - t0) * 1000.0  # the playback's wall time is at most this (1 tick = 1 ms)
    assert 199 <= playback.row - 100 <= wall_ms + 1, (playback.row, wall_ms)


def test_force_arrows_start_under_each_loaded_foot_and_scale_with_the_force(run_dir):
    rec = load_recording(run_dir)
    row = rec.row_at(SHOW_S)
    loaded = np.linalg.norm(rec.grf_plant_w[row], axis=1) >= 1.0
    arrows = force_arrows(rec, row, radius_m=0.02, planned=False)
    assert len(arrows) == loaded.sum() > 0
    for geom, foot, force in zip(arrows, rec.feet_w[row + 1][loaded], rec.grf_plant_w[row][loaded], strict=True):
        np.testing.assert_allclose(geom.pos, foot - [0, 0, 0.02], atol=1e-6)  # an arrow's pos is its tail
        assert geom.size[2] == pytest.approx(np.linalg.norm(force) * FORCE_SCALE_M_PER_N, rel=1e-5)


# ------------------------------------------------------------------------------------------- the server
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _Server:
    """``python -m taslel_bench.view`` in a subprocess; its stdout (the URL) and stderr lines collected."""

    def __init__(self, run_dir: Path, home: Path, *extra: str) -> None:
        home.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "PYTHONPATH": str(ROOT), "HOME": str(home)}  # Studio's default layout, not the user's
        self.proc = subprocess.Popen([sys.executable, "-m", "taslel_bench.view", str(run_dir), "--no-browser",
                                      "--port", str(_free_port()), *extra], cwd=ROOT, env=env, text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
        self.out: list[str] = []
        self.err: list[str] = []
        for stream, lines in ((self.proc.stdout, self.out), (self.proc.stderr, self.err)):
            threading.Thread(target=lambda s=stream, ls=lines: ls.extend(s), daemon=True).start()

    def wait_for(self, pattern: re.Pattern[str] | str, lines: list[str], timeout_s: float = 60.0) -> re.Match[str]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for line in list(lines):
                if m := re.search(pattern, line):
                    return m
            assert self.proc.poll() is None, f"the viewer exited: {''.join(self.err)[-3000:]}"
            time.sleep(0.1)
        raise AssertionError(f"no {pattern!r} within {timeout_s} s: {''.join(self.err)[-3000:]}")

    def url(self) -> str:
        return self.wait_for(r"^http://127\.0\.0\.1:\d+/$", self.out).group(0)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.proc.wait(timeout=30)


def test_the_server_serves_the_page_on_loopback_and_ctrl_c_stops_it(run_dir, tmp_path):
    server = _Server(run_dir, tmp_path / "home")
    try:
        url = server.url()
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200 and b'<canvas id="canvas"' in page.read()
        server.wait_for(r"view: serving http://127\.0\.0\.1", server.err)
    finally:
        code = server.stop()
    assert code == 0, "".join(server.err)[-2000:]
    assert any("view: stopped" in line for line in server.err)
    with pytest.raises(ConnectionRefusedError):  # nothing listens on the port any more
        socket.create_connection(("127.0.0.1", int(url.rsplit(":", 1)[1].strip("/"))), timeout=5).close()


# ------------------------------------------------------------------------------------------- in Chromium
def _posed(run_dir: Path):
    """The run's plant posed at ``SHOW_S`` and MuJoCo's camera of the viewer (``MjvGLCamera``) for that state."""
    model, rec = plant_of_run(run_dir), load_recording(run_dir)
    data = mujoco.MjData(model)
    data.qpos[qpos_addresses(model)] = rec.state[rec.row_at(SHOW_S)]
    mujoco.mj_forward(model, data)
    cam, scene = mujoco.MjvCamera(), mujoco.MjvScene(model, 2000)
    track_trunk(model, cam)
    mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), None, cam, mujoco.mjtCatBit.mjCAT_ALL, scene)
    return model, data, scene.camera[0]


def _project(points_w: np.ndarray, eye, page: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Page pixels (x right, y down) of world points [m] seen by ``eye`` (MuJoCo's frustum: the model's vertical field
    of view, the page's aspect): Studio's client draws the scene over the whole page, its panels on top."""
    forward, up = np.array(eye.forward), np.array(eye.up)
    rel = np.atleast_2d(points_w) - np.array(eye.pos)
    depth = rel @ forward
    w, h = page
    ndc_x = (rel @ np.cross(forward, up)) / depth * eye.frustum_near / (eye.frustum_top * w / h)
    ndc_y = (rel @ up) / depth * eye.frustum_near / eye.frustum_top
    return (1 + ndc_x) * w / 2, (1 - ndc_y) * h / 2


def _robot_box_px(model, data, eye, page: tuple[int, int]) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) [px] around the projected corners of the robot geoms' bounding boxes."""
    trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
    robot = np.flatnonzero(model.body_rootid[model.geom_bodyid] == model.body_rootid[trunk])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    points = np.concatenate([data.geom_xpos[g] + (data.geom_xmat[g].reshape(3, 3) @ (
        model.geom_aabb[g, :3] + corners * model.geom_aabb[g, 3:]).T).T for g in robot])  # fmt: skip
    px, py = _project(points, eye, page)
    return int(px.min()), int(py.min()), int(np.ceil(px.max())), int(np.ceil(py.max()))


def _logs_in_view_px(model, data, eye, page: tuple[int, int]) -> list[tuple[int, int]]:
    """Page pixels of the middle of the top of each log (the scenario's obstacle geoms: above its centre, at the top
    of its bounding box) that falls in the 3D view's open middle (clear of Studio's panel, the Run window, the bars)."""
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    tops = []
    for g in range(model.ngeom):
        if (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "").startswith("obstacles"):
            offsets = (data.geom_xmat[g].reshape(3, 3) @ (model.geom_aabb[g, :3] + corners * model.geom_aabb[g, 3:]).T)
            tops.append(data.geom_xpos[g] + [0.0, 0.0, offsets[2].max()])
    px, py = _project(np.array(tops), eye, page)
    return [(int(x), int(y)) for x, y in zip(px, py, strict=True)
            if 200 < x < page[0] - 20 and 260 < y < page[1] - 80]  # fmt: skip


@pytest.mark.skipif(find_chromium() is None, reason="no Chromium on PATH (Debian: apt-get install -y chromium)")
def _screenshots(run_dir, folder) -> dict[str, np.ndarray]:
    """The page of the run with the robot and with it hidden, each a settled screenshot (saved for a look)."""
    servers = {name: _Server(run_dir, folder / name, "--time", str(SHOW_S), *extra)
               for name, extra in (("robot", ()), ("hidden", ("--hide-robot",)))}  # fmt: skip
    shots = {}
    try:
        with HeadlessChromium(*PAGE) as browser:
            for name, server in servers.items():
                browser.open(server.url())
                browser.wait_for_canvas()
                server.wait_for(READY, server.err)
                shots[name] = settled_screenshot(browser, timeout_s=40.0)
    finally:
        codes = [server.stop() for server in servers.values()]
    for name, image in shots.items():  # kept for a look when the test fails
        save_png(image, folder / f"{name}.png")
    assert codes == [0, 0]
    return shots


def _difference(shots, box) -> tuple[float, float]:
    """Shares of pixels that differ between the two pages inside the robot's box and away from it."""
    x0, y0, x1, y1 = box
    differs = np.abs(shots["robot"].astype(int) - shots["hidden"].astype(int)).max(axis=2) > PIXEL_DIFFERS
    differs = differs[:-STATUS_BAR_PX]
    mx, my = (x1 - x0) // 5, (y1 - y0) // 5  # a margin: shadows, anti-aliasing
    near = np.zeros_like(differs)
    near[max(y0 - my, 0):y1 + my, max(x0 - mx, 0):x1 + mx] = True
    return float(differs[y0:y1, x0:x1].mean()), float(differs[~near].mean())


def test_in_headless_chromium_the_robot_is_drawn_where_the_camera_puts_it(run_dir, tmp_path):
    model, data, eye = _posed(run_dir)
    x0, y0, x1, y1 = _robot_box_px(model, data, eye, PAGE)
    assert 0 < x0 < x1 < PAGE[0] and 0 < y0 < y1 < PAGE[1] - STATUS_BAR_PX  # on the page, not cut off
    # a page caught before it settled differs everywhere: up to 3 pairs of screenshots, the last one judged
    for attempt in range(3):
        shots = _screenshots(run_dir, tmp_path / f"attempt{attempt}")
        inside, outside = _difference(shots, (x0, y0, x1, y1))
        if inside > 0.2 and outside < 0.002:
            break
    assert inside > 0.2, f"the robot's box {x0, y0, x1, y1} differs from the empty scene on only {inside:.1%}"
    assert outside < 0.002, f"{outside:.2%} of the page outside the robot's box differs from the empty scene"
    logs = _logs_in_view_px(model, data, eye, PAGE)  # the run's terrain, seen from the recorded state
    r, g, b = (np.stack([shots["hidden"][y, x] for x, y in logs]).astype(int).T if logs else ([], [], []))
    assert logs and (np.asarray(r) - np.asarray(b) > 30).all(), f"logs at {logs} not drawn there: rgb {r, g, b}"
