"""Run-folder files: ``summary.json``, ``steps.parquet``, ``events.json`` (and ``episode.mcap``, see
:mod:`taslel_bench.record.mcap`). Every file is written to a temporary name and renamed into place, so a run
folder never holds a half-written result; an existing complete result is never overwritten silently."""

from __future__ import annotations

import datetime as dt
import json
import math
import os
from collections.abc import Callable
from pathlib import Path

import pandas as pd

SUMMARY = "summary.json"
STEPS = "steps.parquet"
EVENTS = "events.json"
OVERRIDE_SEPARATOR = "\n"  # between the overrides kept in a summary (values may hold commas and spaces)


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write(tmp_path)`` then rename to ``path`` (same folder, atomic on POSIX)."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _json_safe(value: object) -> object:
    if isinstance(value, float) and math.isnan(value):
        return None  # None = "not measured"; +-inf (e.g. "never settled") stays Infinity
    if hasattr(value, "item"):
        return _json_safe(value.item())
    return value


def write_json(path: Path, data: object) -> None:
    def dump(tmp: Path) -> None:
        if isinstance(data, dict):
            payload = {k: _json_safe(v) for k, v in data.items()}
        else:
            payload = data
        tmp.write_text(json.dumps(payload, indent=2, default=str) + "\n")

    atomic_write(path, dump)


def write_parquet(path: Path, frame: pd.DataFrame) -> None:
    atomic_write(path, lambda tmp: frame.to_parquet(tmp, index=False))


def completed_summary(run_dir: Path) -> dict | None:
    """The summary of a finished run in ``run_dir`` (status ok, degraded or error, all files present),
    else None."""
    p = run_dir / SUMMARY
    if not p.is_file() or not (run_dir / STEPS).is_file():
        return None
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError:
        return None


SUPERSEDED = "superseded"
RESULT_FILES = (SUMMARY, STEPS, EVENTS, "episode.mcap", "episode.partial.mcap", "config.yaml", "traceback.txt", "qps.npz",
                "video.mp4")


def supersede(run_dir: Path, tag: str) -> Path | None:
    """Move the result files of ``run_dir`` into ``run_dir/superseded/<time>_<tag>/`` (never overwrite a
    result: a rerun into the folder first puts the old one aside). Returns that folder, None if empty."""
    present = [run_dir / name for name in RESULT_FILES if (run_dir / name).exists()]
    if not present:
        return None
    dest = run_dir / SUPERSEDED / f"{dt.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}_{tag}"
    dest.mkdir(parents=True)
    for path in present:
        os.replace(path, dest / path.name)
    return dest


def remove_stale(run_dir: Path, partial_names: tuple[str, ...] = ()) -> list[str]:
    """Delete what a killed run left behind in ``run_dir`` (``.<name>.tmp-<pid>`` files of interrupted
    writes, and ``partial_names`` such as a streamed ``episode.partial.mcap``); returns their names."""
    stale = [p for p in run_dir.glob(".*.tmp-*") if p.is_file()]
    stale += [run_dir / name for name in partial_names if (run_dir / name).is_file()]
    for path in stale:
        path.unlink()
    return sorted(p.name for p in stale)
