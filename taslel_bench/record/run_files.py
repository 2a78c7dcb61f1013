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
from typing import Any, cast

import pandas as pd

from taslel_bench.record.run_lock import RunFolderLocked, RunLock

SUMMARY = "summary.json"
STEPS = "steps.parquet"
EVENTS = "events.json"
OVERRIDE_SEPARATOR = "\n"  # between the overrides kept in a summary (values may hold commas and spaces)


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp_path)`` then rename to ``path`` (same folder, atomic on POSIX). An OSError (a full
    disk) is raised naming ``path``, not the temporary file."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        if exc.filename not in (None, str(tmp), tmp):
            raise
        reason = exc.strerror or " ".join(str(exc).split())
        raise OSError(exc.errno, reason, str(path)) from exc
    finally:
        if tmp.exists():
            tmp.unlink()


def _json_safe(value: Any) -> Any:
    if isinstance(value, float) and math.isnan(value):
        return None  # None = "not measured"; +-inf (e.g. "never settled") stays Infinity
    if hasattr(value, "item"):  # numpy scalars (np.float64 is a float too: cast, pyright would say float has none)
        return _json_safe(cast(Any, value).item())
    return value


def write_json(path: Path, data: object) -> None:
    def dump(tmp: Path) -> None:
        payload = {k: _json_safe(v) for k, v in data.items()} if isinstance(data, dict) else data
        tmp.write_text(json.dumps(payload, indent=2, default=str) + "\n")

    atomic_write(path, dump)


def write_parquet(path: Path, frame: pd.DataFrame) -> None:
    atomic_write(path, lambda tmp: frame.to_parquet(tmp, index=False))


def read_summary(run_dir: Path) -> dict | None:
    """``run_dir/summary.json`` as a dict, None if absent, unreadable, truncated or not a JSON object."""
    p = Path(run_dir) / SUMMARY
    try:
        data = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def completed_summary(run_dir: Path) -> dict | None:
    """The summary of a finished run in ``run_dir`` whose result files are all there as written (see
    :func:`folder_state`), else None."""
    summary, problem = folder_state(run_dir)
    return summary if summary is not None and not problem else None


SUPERSEDED = "superseded"
RESULT_FILES = (SUMMARY, STEPS, EVENTS, "episode.mcap", "episode.partial.mcap", "config.yaml", "traceback.txt",
                "qps.npz", "video.mp4")
MANIFEST_KEY = "result_files"  # in summary.json: {file name: size [bytes]} of the files the run wrote


def present_results(run_dir: Path) -> list[str]:
    """Names of the result files in ``run_dir``."""
    return [name for name in RESULT_FILES if (Path(run_dir) / name).exists()]


def manifest(run_dir: Path) -> dict[str, int]:
    """``{name: size [bytes]}`` of the result files now in ``run_dir`` (summary.json itself excluded): written
    into the summary, so a later reader can tell a complete set from a damaged one."""
    return {name: (Path(run_dir) / name).stat().st_size for name in present_results(run_dir) if name != SUMMARY}


def folder_state(run_dir: Path) -> tuple[dict | None, str]:
    """(readable summary or None, what is wrong with the folder's result files: "" when they are a complete
    set as written, "empty" when there are none). The set must match the summary's manifest: every listed
    file present with its size, no other result file (e.g. an old traceback.txt); a summary without a
    manifest (older runs) needs steps.parquet."""
    run_dir = Path(run_dir)
    present = present_results(run_dir)
    if not present:
        return None, "empty"
    summary = read_summary(run_dir)
    if SUMMARY not in present:
        return None, "no-summary"  # killed before the end (or the summary was deleted)
    if summary is None:
        return None, "summary-unreadable"
    listed = summary.get(MANIFEST_KEY)
    if not isinstance(listed, dict):
        return summary, "" if STEPS in present else f"missing-{STEPS}"
    for name, size in listed.items():
        path = run_dir / name
        if not path.is_file():
            return summary, f"missing-{name}"
        if path.stat().st_size != size:
            return summary, f"size-{name}"
    extra = [name for name in present if name != SUMMARY and name not in listed]
    return summary, f"extra-{extra[0]}" if extra else ""


def supersede(run_dir: Path, tag: str) -> Path | None:
    """Move the result files of ``run_dir`` into ``run_dir/superseded/<time>_<tag>/`` (never overwrite a
    result: a rerun into the folder first puts the old one aside). Returns that folder, None if empty."""
    present = [run_dir / name for name in present_results(run_dir)]
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


def write_error_folder(out_dir: Path, summary: dict, tb: str) -> None:
    """Write an error ``summary`` (and ``traceback.txt``) into ``out_dir`` under its lock, a result already
    there put aside first; a folder locked by a live writer is not touched."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        lock = RunLock(out_dir).acquire()
    except RunFolderLocked:
        return
    try:
        moved = supersede(out_dir, "before-error")  # a result in the folder is put aside, not overwritten
        if moved is not None:
            summary["superseded"] = str(moved.relative_to(out_dir))
        atomic_write(out_dir / "traceback.txt", lambda p: p.write_text(tb))
        summary[MANIFEST_KEY] = manifest(out_dir)
        write_json(out_dir / SUMMARY, summary)
    finally:
        lock.release()
