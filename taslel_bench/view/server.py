"""MuJoCo Studio's web viewer serving one recorded run on one network interface (127.0.0.1 by default).

Studio's ``WebViewer`` binds every interface (``'::'``) with no option to choose; :class:`InterfaceWebViewer` binds
the one it is given instead. The rest is Studio's: the page, the WebAssembly client, the model download and the
state stream on one port; its ``App`` plugin (menus, the Options panel with Run/Pause, speed and the timeline
scrubber); with :class:`taslel_bench.view.playback.RecordingPlayback` in place of its stepping and history plugins
and :class:`taslel_bench.view.panel.RunPanel` for the run's camera, arrows and window.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco.studio import app as studio_app
from mujoco.studio import endpoints, launch_thread, viewer_handle, viewer_protocol, web_viewer

from taslel_bench.view.panel import RunPanel
from taslel_bench.view.playback import RecordingPlayback
from taslel_bench.view.recording import Recording

START_TIMEOUT_S = 30.0  # [s] the viewer thread binds its port and starts serving within this


class InterfaceWebViewer(web_viewer.WebViewer):
    """Studio's web viewer bound to :attr:`bind_host` (``WebViewer.__init__`` sets ``self._host = '::'`` and binds
    it at once; here that attribute reads the chosen interface and the assignment is ignored)."""

    bind_host = "127.0.0.1"

    @property
    def _host(self) -> str:  # pyright: ignore[reportIncompatibleVariableOverride] Studio assigns a plain attribute
        return self.bind_host

    @_host.setter
    def _host(self, value: str) -> None:
        pass


@dataclass
class Served:
    """A running viewer: its URL, the sim-side handle (call :func:`pump` on the thread that made it) and plugins."""

    url: str
    port: int
    handle: viewer_handle.ViewerHandle
    panel: RunPanel
    playback: RecordingPlayback


def hide_robot(model) -> None:
    """Make every geom of the robot (the trunk's tree) fully transparent: the scene without the robot, for a
    reference image. Visual only (``geom_rgba``); collisions and the recorded states are unchanged."""
    trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "trunk")
    robot = model.body_rootid[model.geom_bodyid] == model.body_rootid[trunk]
    model.geom_rgba[robot, 3] = 0.0
    model.geom_matid[robot] = -1  # a material's colour would override the geom's


@contextmanager
def serve(model, rec: Recording, *, port: int = 0, host: str = "127.0.0.1", start_row: int = 0,
          play: bool = False, title: str = "", open_browser: bool = False) -> Iterator[Served]:  # fmt: skip
    """Serve ``rec`` on ``model`` (the run's plant) at ``http://host:port/`` (port 0: Studio's choice, the first
    free port from 8080) while the ``with`` block runs; closed (port released) when it ends, also on Ctrl-C."""
    panel = RunPanel(rec, title)
    playback = RecordingPlayback(rec, start_row=start_row, play=play)
    config = viewer_protocol.ViewerConfig(title=f"taslel_bench: {title}"[:120], gfx="web", http_port=int(port),
                                          open_browser=open_browser)  # fmt: skip
    started: dict[str, int] = {}
    ready = threading.Event()

    class Viewer(InterfaceWebViewer):
        bind_host = host

    def target(endpoint: endpoints.ViewerEndpoint) -> None:
        viewer = Viewer(config, endpoint, plugins=[studio_app.App(studio_app.Config(show_inspector=False)), panel])
        started["port"] = viewer.port
        ready.set()
        viewer_protocol.run_viewer_loop(viewer)

    handle = launch_thread.launch_thread(target, sim_plugins=[playback])
    try:
        _wait_started(handle, ready)
        data = mujoco.MjData(model)
        handle.set_model(model, data=data)
        shown = "localhost" if host in ("::", "0.0.0.0") else host
        yield Served(f"http://{shown}:{started['port']}/", started["port"], handle, panel, playback)
    finally:
        handle.close()


def _wait_started(handle: viewer_handle.ViewerHandle, ready: threading.Event) -> None:
    """Wait until the viewer thread has bound its port; its error (a port in use) is raised here."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while not ready.wait(0.05):
        if not handle.is_running():  # the thread died: close() (in is_running) re-raised its error
            raise RuntimeError("the viewer stopped while starting")
        if time.monotonic() > deadline:
            raise TimeoutError(f"the viewer did not start serving within {START_TIMEOUT_S:g} s")


def pump(served: Served, until: threading.Event | None = None) -> None:
    """Run the sim side (the replay) until the viewer closes or ``until`` is set; Ctrl-C propagates."""
    while served.handle.is_running() and not (until is not None and until.is_set()):
        served.handle.sync()


def start_row_of(rec: Recording, t_s: float | None) -> int:
    """The row shown first: the tick whose state time is nearest ``t_s`` [s] (None: the first tick)."""
    return 0 if t_s is None else int(np.clip(rec.row_at(float(t_s)), 0, rec.n - 1))
