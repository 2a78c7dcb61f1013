"""The viewer side: a MuJoCo Studio viewer plugin that adds the run to Studio's page.

* a camera tracking the trunk (:data:`VIEW_CAMERA`: the videos' angles, a little further away);
* arrows at the feet, drawn as Studio "extra geoms" of the shown tick: MuJoCo's contact force on each foot (blue,
  recorded) and the filter's planned contact force (orange, recorded), :data:`FORCE_SCALE_M_PER_N` per newton,
  from the bottom of the foot sphere, world axes;
* a "Run" window: the run's labels, status and verdict, the shown time, a timeline of the whole run with the
  stand phase and the events (fall, trips, QP failures, alarms) marked, which scrubs on click or drag, and one
  button per event that jumps to it.

The window and the arrows follow the tick the viewer shows (its ``data.time``, set by
:class:`taslel_bench.view.playback.RecordingPlayback`); seeking sends Studio's own history scrub request.
"""

from __future__ import annotations

import sys

import mujoco
import numpy as np
from mujoco.studio import (
    messages,
    plugin,
    ux,  # pyright: ignore[reportAttributeAccessIssue] compiled, set up by mujoco.studio
)
from mujoco.studio.app import InitEvent
from mujoco.studio.dear_imgui import dear_imgui as imgui
from mujoco.studio.sim_history import SimHistorySnapshot

from taslel_bench.plant.contacts import foot_radius_m
from taslel_bench.record.video import FORCE_SCALE_M_PER_N, verdict_text
from taslel_bench.robot import quadruped as quad
from taslel_bench.view.recording import Recording, RunEvent

MIN_ARROW_N = 1.0  # [N] smaller forces get no arrow
ARROW_WIDTH_M = 0.01  # [m]
PLANT_RGBA = (0.15, 0.45, 0.95, 1.0)  # MuJoCo's contact force (as in the videos and the Foxglove scene)
PLANNED_RGBA = (1.0, 0.55, 0.1, 1.0)  # the filter's planned force (as in the Foxglove scene)
EVENT_RGBA = {"fall": (0.95, 0.2, 0.2, 1.0), "trip": (1.0, 0.6, 0.1, 1.0), "qp_failure": (0.85, 0.3, 0.95, 1.0),
              "error": (0.95, 0.2, 0.2, 1.0), "alarm": (0.95, 0.85, 0.2, 1.0)}  # fmt: skip
OTHER_RGBA = (0.8, 0.8, 0.8, 1.0)
TIMELINE_H_PX = 26.0
MAX_EVENT_BUTTONS = 40  # the list shows the first ones; the timeline marks them all
RUN_WINDOW_PX = (520, 250)  # [px] the Run window's size when it first appears: top right, left of Studio's axes
RUN_WINDOW_TOP_PX, RUN_WINDOW_RIGHT_MARGIN_PX = 30.0, 110.0  # [px] (the scene's middle, the robot, stays clear)
READY_FRAMES = 30  # frames built for a browser before the page counts as drawn (about 0.5 s at 60 Hz)
VIEW_CAMERA = {"distance": 2.0, "azimuth": 130.0, "elevation": -18.0}  # [m], [deg], [deg] tracking the trunk


def force_arrows(rec: Recording, row: int, radius_m: float, plant: bool = True, planned: bool = True) -> list:
    """``mujoco.MjvGeom`` arrows of row ``row``: the forces of its tick, from the bottom of each foot sphere of its
    state (``radius_m`` [m] below the centre) along the force, :data:`FORCE_SCALE_M_PER_N` [m/N], world axes;
    forces under :data:`MIN_ARROW_N` or nan skipped."""
    sets = [(rec.grf_plant_w[row], PLANT_RGBA)] if plant else []
    sets += [(rec.grf_planned_w[row], PLANNED_RGBA)] if planned else []
    out = []
    for forces, rgba in sets:
        for foot, force in zip(rec.feet_shown_w(row), forces, strict=True):
            norm = float(np.linalg.norm(force))
            if not np.isfinite(norm) or norm < MIN_ARROW_N:
                continue
            tail = foot - np.array([0.0, 0.0, radius_m])
            geom = mujoco.MjvGeom()
            mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), np.zeros(3), np.zeros(9),
                                np.array(rgba, np.float32))  # fmt: skip
            head = tail + force * FORCE_SCALE_M_PER_N
            mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_ARROW, ARROW_WIDTH_M, tail, head)
            out.append(geom)
    return out


def track_trunk(model, camera) -> None:
    """Point ``camera`` (an ``MjvCamera``) at the trunk: MuJoCo's tracking camera (it looks at the trunk's subtree
    centre of mass) at :data:`VIEW_CAMERA`'s distance [m], azimuth and elevation [deg] (the videos' angles, further
    away: the page is larger)."""
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
    camera.distance, camera.azimuth, camera.elevation = (
        VIEW_CAMERA["distance"], VIEW_CAMERA["azimuth"], VIEW_CAMERA["elevation"])  # fmt: skip


def _u32(rgba: tuple[float, float, float, float]) -> int:
    return imgui.ColorConvertFloat4ToU32(imgui.Vec4(*rgba))


class RunPanel(plugin.ViewerPlugin):
    """The run's camera, force arrows and "Run" window in Studio's viewer (see the module doc)."""

    def __init__(self, recording: Recording, title: str) -> None:
        self.rec, self.title = recording, title
        self.show_plant, self.show_planned = True, True
        self.gui_frames = 0  # frames built for a connected browser (the page is up once this counts)
        self._app = None
        self._radius_m = 0.02
        self._sought = -1

    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_app_init(self, event: InitEvent) -> None:
        self._app = event.app

    @messages.handler(priority=0)  # after Studio's App has reset its camera for the new model
    def _on_post_model(self, event: messages.PostModelEvent) -> None:
        self._radius_m = foot_radius_m(event.model)
        track_trunk(event.model, self.viewer.camera)
        if self._app is not None:
            self._app.ux_state.camera_index = ux.TRACKING_CAMERA_IDX

    def row(self) -> int:
        """The row of the tick the viewer shows."""
        return self.rec.row_at(float(self.viewer.data.time))

    @messages.handler(priority=messages.Priority.LIBRARY)
    def _on_update(self, _: messages.UpdateEvent) -> None:
        self.viewer.extra_geoms[:] = force_arrows(self.rec, self.row(), self._radius_m, self.show_plant,
                                                  self.show_planned)  # fmt: skip

    def seek(self, row: int) -> None:
        """Ask the sim side to show row ``row`` (Studio's history scrub request; the replay pauses)."""
        row = int(np.clip(row, 0, self.rec.n - 1))
        if row != self._sought or row != self.row():
            self.viewer.send_to_sim(SimHistorySnapshot(index=row - (self.rec.n - 1)))
            self._sought = row

    @messages.handler(priority=messages.Priority.LIBRARY)
    def _on_build_gui(self, _: messages.BuildGuiEvent) -> None:
        self.gui_frames += 1
        if self.gui_frames == READY_FRAMES:
            size = imgui.GetIO().DisplaySize
            print(f"view: a browser shows the page ({size.x:.0f}x{size.y:.0f} px)", file=sys.stderr, flush=True)
        right = imgui.GetIO().DisplaySize.x - RUN_WINDOW_RIGHT_MARGIN_PX
        imgui.SetNextWindowPos(imgui.Vec2(right, RUN_WINDOW_TOP_PX), imgui.Cond.FirstUseEver, imgui.Vec2(1, 0))
        imgui.SetNextWindowSize(imgui.Vec2(*RUN_WINDOW_PX), imgui.Cond.FirstUseEver)
        expanded, _open = imgui.Begin("Run", None, int(imgui.WindowFlags.NoSavedSettings))
        if expanded:
            self._header()
            self._timeline()
            self._toggles()
            self._event_buttons()
        imgui.End()

    def _header(self) -> None:
        rec, row = self.rec, self.row()
        imgui.TextUnformatted(self.title)
        status = rec.summary.get("status", "running or stopped (no summary.json)")
        imgui.TextUnformatted(f"status: {status}    {verdict_text(rec.summary)}"[:160])
        phase = "stand" if rec.t_s[row] < rec.stand_s else "walking"
        imgui.TextUnformatted(f"t = {rec.state_time(row):7.3f} s of {rec.state_time(rec.n - 1):.3f} s   "
                              f"(tick {row + 1} / {rec.n}, {phase})")  # fmt: skip

    def _timeline(self) -> None:
        """The run from its first to its last tick: stand phase shaded, events as ticks, the shown tick as a line;
        click or drag to seek."""
        rec = self.rec
        width = max(imgui.GetContentRegionAvail().x, 50.0)
        p0 = imgui.GetCursorScreenPos()
        imgui.InvisibleButton("##run_timeline", imgui.Vec2(width, TIMELINE_H_PX))
        t0, t1 = float(rec.t_s[0]), rec.state_time(rec.n - 1)

        def x_of(t: float) -> float:
            return p0.x + (t - t0) / max(t1 - t0, 1e-9) * width

        if imgui.IsItemActive():
            t = t0 + (imgui.GetMousePos().x - p0.x) / width * (t1 - t0)
            self.seek(rec.row_at(t))
        draw, y0, y1 = imgui.GetWindowDrawList(), p0.y, p0.y + TIMELINE_H_PX
        draw.AddRectFilled(imgui.Vec2(p0.x, y0), imgui.Vec2(p0.x + width, y1), _u32((0.18, 0.18, 0.2, 1.0)))
        draw.AddRectFilled(imgui.Vec2(p0.x, y0), imgui.Vec2(x_of(rec.stand_s), y1), _u32((0.3, 0.3, 0.34, 1.0)))
        for e in rec.events:
            x, top = x_of(e.t_s), y0 if e.kind in ("fall", "error", "qp_failure") else y0 + TIMELINE_H_PX / 3
            draw.AddLine(imgui.Vec2(x, top), imgui.Vec2(x, y1), _u32(EVENT_RGBA.get(e.kind, OTHER_RGBA)), 2.0)
        x = x_of(rec.state_time(self.row()))
        draw.AddLine(imgui.Vec2(x, y0 - 3), imgui.Vec2(x, y1 + 3), _u32((1.0, 1.0, 1.0, 1.0)), 2.0)

    def _toggles(self) -> None:
        _, self.show_plant = imgui.Checkbox("contact force (MuJoCo, blue)", self.show_plant)
        imgui.SameLine()
        _, self.show_planned = imgui.Checkbox("planned force (filter, orange)", self.show_planned)
        imgui.SameLine()
        imgui.TextDisabled(f"{FORCE_SCALE_M_PER_N * 1000:g} mm/N")

    def _event_buttons(self) -> None:
        events = self.rec.events
        if not events:
            imgui.TextDisabled("no events (no fall, trip, QP failure or alarm)")
            return
        counts = {k: sum(e.kind == k for e in events) for k in dict.fromkeys(e.kind for e in events)}
        imgui.TextUnformatted("events: " + ", ".join(f"{n} {k}" for k, n in counts.items()) + " (click: go there)")
        if imgui.BeginChild("##run_events", imgui.Vec2(0, 0)):
            for i, e in enumerate(events[:MAX_EVENT_BUTTONS]):
                if imgui.SmallButton(f"{e.t_s:7.3f} s##ev{i}"):
                    self.seek(self.rec.row_of_tick(e.t_s))
                imgui.SameLine()
                imgui.TextColored(imgui.Vec4(*EVENT_RGBA.get(e.kind, OTHER_RGBA)), _event_line(e))
            if len(events) > MAX_EVENT_BUTTONS:
                imgui.TextDisabled(f"... {len(events) - MAX_EVENT_BUTTONS} more (on the timeline)")
        imgui.EndChild()


def _event_line(e: RunEvent) -> str:
    return f"{e.kind}: {e.text}"[:100]
