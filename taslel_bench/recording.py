"""Run-folder files: ``summary.json``, ``steps.parquet``, ``events.json`` (and ``episode.mcap``, see
:mod:`taslel_bench.mcap_log`). Every file is written to a temporary name and renamed into place, so a run
folder never holds a half-written result; an existing complete result is never overwritten silently."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path

import pandas as pd

SUMMARY = "summary.json"
STEPS = "steps.parquet"
EVENTS = "events.json"


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
    """The summary of a finished run in ``run_dir`` (status ok or error, all files present), else None."""
    p = run_dir / SUMMARY
    if not p.is_file() or not (run_dir / STEPS).is_file():
        return None
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError:
        return None
