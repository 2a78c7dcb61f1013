"""Headless Chromium driven over the DevTools protocol (a WebSocket; the ``websockets`` package MuJoCo Studio
already needs): open a page, wait for its canvas, take screenshots. Used for a screenshot of the viewer and by its
test.

WebGL in headless Chromium on a machine without a GPU needs SwiftShader (a CPU implementation): the flags are
:data:`CHROMIUM_FLAGS` (``--use-angle=swiftshader --enable-unsafe-swiftshader``; without the second one Chromium
refuses SwiftShader for WebGL).
"""

from __future__ import annotations

import base64
import contextlib
import io
import itertools
import json
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--no-first-run", "--no-default-browser-check", "--mute-audio",
                  "--disable-extensions", "--hide-scrollbars")  # fmt: skip
DEVTOOLS_LINE = re.compile(r"DevTools listening on (ws://\S+)")
CANVAS_JS = "(() => { const c = document.getElementById('canvas'); return !!c && c.width > 0 && c.height > 0; })()"


class BrowserError(RuntimeError):
    """Chromium is missing, did not start, or a page did not come up in time."""


def find_chromium() -> str | None:
    """Path of a Chromium (``$CHROMIUM`` if set, else the first of :data:`CHROMIUM_NAMES` on PATH), or None."""
    env = os.environ.get("CHROMIUM")
    if env:
        return env if shutil.which(env) else None
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


class HeadlessChromium:
    """One headless Chromium with one page of ``width`` x ``height`` CSS pixels (device scale 1)."""

    def __init__(self, width: int = 1200, height: int = 800, start_timeout_s: float = 30.0) -> None:
        exe = find_chromium()
        if exe is None:
            raise BrowserError(f"no Chromium found (tried $CHROMIUM and {', '.join(CHROMIUM_NAMES)} on PATH); "
                               "Debian: apt-get install -y chromium")  # fmt: skip
        self.profile = tempfile.mkdtemp(prefix="taslel_view_chromium_")
        cmd = [exe, *CHROMIUM_FLAGS, "--remote-debugging-port=0", f"--user-data-dir={self.profile}",
               f"--window-size={width},{height}", "about:blank"]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.log: list[str] = []
        self._stack = contextlib.ExitStack()  # the DevTools WebSocket
        try:
            self.ws = self._connect(start_timeout_s)
            self._ids = itertools.count(1)
            target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
            self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
            metrics = {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False}
            self.call("Emulation.setDeviceMetricsOverride", metrics, page=True)
        except BaseException:
            self.close()
            raise

    def _connect(self, timeout_s: float):
        """Read Chromium's stderr (in a thread, kept in :attr:`log`) until it names its DevTools socket."""
        from websockets.sync.client import connect

        found: list[str] = []
        seen = threading.Event()

        def read() -> None:
            assert self.proc.stderr is not None
            for line in self.proc.stderr:
                self.log.append(line.rstrip())
                m = DEVTOOLS_LINE.search(line)
                if m and not found:
                    found.append(m.group(1))
                    seen.set()

        threading.Thread(target=read, daemon=True).start()
        if not seen.wait(timeout_s):
            raise BrowserError(f"Chromium did not open its DevTools socket within {timeout_s:g} s: "
                               + " | ".join(self.log[-5:]))  # fmt: skip
        return self._stack.enter_context(connect(found[0], max_size=None, open_timeout=timeout_s))

    def call(self, method: str, params: dict[str, Any] | None = None, page: bool = False) -> dict[str, Any]:
        """One DevTools command (``page``: to the page's session), its result; events in between are dropped."""
        msg_id = next(self._ids)
        msg: dict[str, Any] = {"id": msg_id, "method": method, "params": params or {}}
        if page:
            msg["sessionId"] = self.session
        self.ws.send(json.dumps(msg))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == msg_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error']}")
                return reply["result"]

    def open(self, url: str) -> None:
        self.call("Page.navigate", {"url": url}, page=True)

    def evaluate(self, expression: str) -> Any:
        result = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True}, page=True)
        return result.get("result", {}).get("value")

    def screenshot(self) -> np.ndarray:
        """The page as an (height, width, 3) uint8 RGB image."""
        from PIL import Image

        data = base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"}, page=True)["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))

    def wait_for_canvas(self, timeout_s: float = 30.0) -> None:
        """Wait until the page has a ``<canvas id="canvas">`` with a size (the Studio client's)."""
        deadline = time.monotonic() + timeout_s
        while not self.evaluate(CANVAS_JS):
            if time.monotonic() > deadline:
                raise BrowserError(f"no canvas on the page within {timeout_s:g} s")
            time.sleep(0.2)

    def close(self) -> None:
        self._stack.close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> HeadlessChromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def changed_fraction(a: np.ndarray, b: np.ndarray, threshold: int = 24) -> float:
    """Fraction of pixels whose largest channel difference exceeds ``threshold`` (of 255)."""
    return float((np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=2) > threshold).mean())


def settled_screenshot(browser: HeadlessChromium, ready: Callable[[], bool] = lambda: True, timeout_s: float = 60.0,
                       interval_s: float = 1.0, bottom_px: int = 40) -> np.ndarray:  # fmt: skip
    """A screenshot once ``ready()`` holds and two screenshots ``interval_s`` apart agree (fewer than 0.1 % of the
    pixels above the bottom ``bottom_px``, the client's status bar with its frame counter, changed)."""
    deadline = time.monotonic() + timeout_s
    while not ready():
        if time.monotonic() > deadline:
            raise BrowserError(f"the viewer did not draw for the browser within {timeout_s:g} s")
        time.sleep(0.2)
    last = browser.screenshot()
    while True:
        time.sleep(interval_s)
        image = browser.screenshot()
        if changed_fraction(last[:-bottom_px], image[:-bottom_px]) < 1e-3:
            return image
        if time.monotonic() > deadline:
            raise BrowserError(f"the page did not settle within {timeout_s:g} s")
        last = image


def save_png(image: np.ndarray, path: Path) -> Path:
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path, format="PNG")
    return path
