"""``python -m taslel_bench.view <run folder>``: the recorded run replayed in MuJoCo Studio's web viewer.

Prints the viewer's URL (``http://127.0.0.1:<port>/``) on stdout, progress and Studio's own messages on stderr, and
serves until Ctrl-C (or SIGTERM), which stops it cleanly (exit 0). ``--screenshot out.png`` instead opens the page in
headless Chromium, saves what it shows, and exits. Exit codes: 0 served and stopped / screenshot written, 1 the
viewer or the browser failed, 2 bad input (not a run folder, a run whose plant cannot be rebuilt, a port in use), 130
Ctrl-C before the viewer served.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
import threading
import webbrowser
from pathlib import Path
from typing import TextIO

USAGE_EXAMPLE = "python -m taslel_bench.view outputs/runs/<date>/<time>   (a folder printed as `run folder:`)"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m taslel_bench.view", epilog=f"example: {USAGE_EXAMPLE}",
                                 description="Replay a recorded run in MuJoCo Studio's web viewer (served on "
                                             "127.0.0.1): the run's own plant posed tick by tick from steps.parquet, "
                                             "Studio's Run/Pause, speed and timeline scrubber, contact-force and "
                                             "planned-force arrows, the run's events on a timeline.")  # fmt: skip
    ap.add_argument("run_dir", type=Path, help="a run folder (config.yaml and steps.parquet)")
    ap.add_argument("--port", type=int, default=0, help="TCP port (default 0: the first free port from 8080)")
    ap.add_argument("--host", default="127.0.0.1",
                    help="interface to bind (default 127.0.0.1: this machine only; '::' binds every interface, "
                         "with no authentication)")  # fmt: skip
    ap.add_argument("--time", type=float, default=None, help="simulated time [s] shown first (default: the start)")
    ap.add_argument("--play", action="store_true", help="start playing (default: paused; press Run)")
    ap.add_argument("--no-browser", action="store_true",
                    help="do not open a browser tab (none is opened without a display)")
    ap.add_argument("--screenshot", type=Path, default=None, metavar="PNG",
                    help="open the page in headless Chromium, save a screenshot there, exit")  # fmt: skip
    ap.add_argument("--width", type=int, default=1200, help="screenshot width [px]")
    ap.add_argument("--height", type=int, default=800, help="screenshot height [px]")
    ap.add_argument("--hide-robot", action="store_true", help="draw the scene without the robot (a reference image)")
    ap.add_argument("--timeout", type=float, default=120.0, help="screenshot: give up after this many seconds")
    args = ap.parse_args(argv)
    if not 0 <= args.port <= 65535:
        ap.error(f"--port {args.port}: a TCP port is 0..65535 (0: the first free one from 8080)")
    if args.width < 64 or args.height < 64:
        ap.error(f"--width/--height {args.width}x{args.height}: at least 64x64 px")
    return args


def progress(message: str) -> None:
    print(f"view: {message}", file=sys.stderr, flush=True)


def title_of(run_dir: Path, summary: dict) -> str:
    """The run folder's name and its axes (from the summary)."""
    axes = [f"{k}={summary[k]}" for k in ("scenario", "solver", "estimator", "seed") if k in summary]
    return f"{run_dir.resolve().name}" + (f"  ({', '.join(axes)})" if axes else "")


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    url_out: TextIO = sys.stdout
    sys.stdout = sys.stderr  # Studio prints its banner and notices with print(): stdout carries the URL alone
    try:
        if args.screenshot is None:
            sys.exit(run(args, url_out))
        with tempfile.TemporaryDirectory(prefix="taslel_view_home_") as home:
            os.environ["HOME"] = home  # Studio reads and saves its layout in $HOME/.mujoco.ini: its default layout
            sys.exit(run(args, url_out))
    except KeyboardInterrupt:  # before the viewer served (reading the run, building the plant)
        progress("interrupted")
        sys.exit(130)


def run(args: argparse.Namespace, url_out: TextIO) -> int:
    from taslel_bench.view.recording import NotARunFolder, load_recording

    try:
        progress(f"reading {args.run_dir}")
        rec = load_recording(args.run_dir)
    except NotARunFolder as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    progress(f"{rec.n} ticks, {rec.state_time(rec.n - 1):.3f} s; {len(rec.events)} events; rebuilding the plant "
             "from config.yaml")  # fmt: skip
    try:
        model = _plant(args.run_dir, args.hide_robot)
    except Exception as exc:  # the run's config names a part this checkout cannot build
        print(f"error: {args.run_dir / 'config.yaml'}: the run's plant could not be rebuilt "
              f"({type(exc).__name__}: {exc})", file=sys.stderr)  # fmt: skip
        return 2
    return _serve(args, rec, model, url_out)


def _plant(run_dir: Path, hidden: bool):
    from taslel_bench.record.video import plant_of_run
    from taslel_bench.view.server import hide_robot

    model = plant_of_run(run_dir)
    if hidden:
        hide_robot(model)
    return model


def _serve(args: argparse.Namespace, rec, model, url_out: TextIO) -> int:
    from taslel_bench.view.server import pump, serve, start_row_of

    signal.signal(signal.SIGTERM, _interrupt)  # SIGTERM stops it as Ctrl-C does
    # Ctrl-C (SIGINT) stops it even when started from a background job, whose SIGINT the shell set to ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with serve(model, rec, port=args.port, host=args.host, start_row=start_row_of(rec, args.time),
                   play=args.play, title=title_of(args.run_dir, rec.summary)) as served:  # fmt: skip
            print(served.url, file=url_out, flush=True)
            if args.screenshot is not None:
                return _screenshot(args, served)
            progress(f"serving {served.url} (Ctrl-C stops it)")
            _open_tab(served.url, args.no_browser)
            pump(served)
            return 0
    except KeyboardInterrupt:
        progress("stopped")
        return 130 if args.screenshot is not None else 0  # a screenshot cut short is not written
    except RuntimeError as exc:  # Studio: the port is in use
        print(f"error: {exc}", file=sys.stderr)
        return 2 if "in use" in str(exc) else 1


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _open_tab(url: str, disabled: bool) -> None:
    has_display = not sys.platform.startswith("linux") or os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if not disabled and has_display:
        threading.Thread(target=webbrowser.open, args=(url,), kwargs={"new": 2}, daemon=True).start()


def _screenshot(args: argparse.Namespace, served) -> int:
    """Open the page in headless Chromium while the replay runs here; save the settled page. Studio's layout is its
    default one (``main`` points Studio's settings file at a temporary folder in this mode)."""
    from taslel_bench.view.browser import BrowserError, HeadlessChromium, save_png, settled_screenshot
    from taslel_bench.view.panel import READY_FRAMES
    from taslel_bench.view.server import pump

    done, result = threading.Event(), {}

    def shoot(browser: HeadlessChromium) -> None:
        try:
            browser.open(served.url)
            browser.wait_for_canvas(args.timeout)
            ready = lambda: served.panel.gui_frames >= READY_FRAMES  # noqa: E731 - the page's UI is up and drawing
            result["path"] = save_png(settled_screenshot(browser, ready, args.timeout), args.screenshot)
        except Exception as exc:  # BrowserError, OSError, a closed DevTools socket: reported, Chromium closed below
            result["error"] = f"{type(exc).__name__}: {exc}"
        finally:
            done.set()

    progress(f"taking a screenshot of {served.url} with headless Chromium")
    try:
        browser = HeadlessChromium(args.width, args.height)
    except BrowserError as exc:
        print(f"error: screenshot: {exc}", file=sys.stderr)
        return 1
    with browser:  # closed here, on this thread, whatever stops the replay (Ctrl-C included)
        threading.Thread(target=shoot, args=(browser,), daemon=True).start()
        pump(served, until=done)
    if "error" in result:
        print(f"error: screenshot: {result['error']}", file=sys.stderr)
        return 1
    progress(f"wrote {result['path']}")
    return 0


if __name__ == "__main__":
    main()
