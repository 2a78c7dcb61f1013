"""``python -m taslel_bench.render <run folder> [--out video.mp4] [--fps 30] [--width 480] [--height 360]``:
render a run's MP4 from its steps.parquet (:mod:`taslel_bench.record.video`). Headless: ``MUJOCO_GL=egl``
(the default here) or ``MUJOCO_GL=osmesa``."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported: it reads the variable then

from taslel_bench.gl_hint import import_mujoco_or_exit

import_mujoco_or_exit()  # MUJOCO_GL naming a library that cannot be loaded: one line, not a traceback

from taslel_bench.record.video_cli import main  # noqa: E402 - MUJOCO_GL is set and checked first

if __name__ == "__main__":
    main()
