"""The command line of :mod:`taslel_bench.render`: arguments, checks of the run folder, the render."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from taslel_bench.record import run_files


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="Render a run folder's video (MP4) from its steps.parquet.")
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--out", type=Path, default=None, help="default: <run folder>/video.mp4")
    ap.add_argument("--fps", type=float, default=30.0, help="frames per second of simulated time")
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--start", type=float, default=0.0, help="simulated time of the first frame [s]")
    ap.add_argument("--end", type=float, default=None, help="simulated time of the last frame [s]")
    args = ap.parse_args(argv)
    missing = [name for name in (run_files.STEPS, "config.yaml") if not (args.run_dir / name).is_file()]
    if missing:
        sys.exit(f"error: {args.run_dir} is not a run folder: no {', '.join(missing)}")
    from taslel_bench.record.video import GLUnavailable, render_video

    t = time.perf_counter()
    try:
        path, n = render_video(args.run_dir, args.out, fps=args.fps, width=args.width, height=args.height,
                               t0_s=args.start, t1_s=args.end)
    except GLUnavailable as exc:
        sys.exit(f"error: {exc}")
    wall = time.perf_counter() - t
    print(f"{path}: {n} frames at {args.fps:g} fps, {path.stat().st_size / 1e6:.2f} MB, rendered in {wall:.1f} s "
          f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')}, load {os.getloadavg()[0]:.2f})")
