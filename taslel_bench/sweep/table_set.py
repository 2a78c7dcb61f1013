"""A sweep's table files as one set: ``summary.parquet``, ``table.csv``, ``table.tex`` and ``report.md``.

Each file is written atomically (renamed into place), but four renames are not one: a sweep or a report
rebuild killed between them leaves a new ``summary.parquet`` beside an old ``report.md``. So the writer
first removes the set's record ``table_set.json``, writes the files, then writes the record last, with
each file's size and sha256. A reader (:func:`set_problem`) can tell a complete set (the record is there
and every file matches it) from an incomplete one (no record: the writing did not finish; a file that does
not match: written by something else since), and says which.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
from pathlib import Path

from taslel_bench.record import run_files

RECORD = "table_set.json"
SET_FILES = ("summary.parquet", "table.csv", "table.tex", "report.md")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def begin(sweep_dir: Path) -> None:
    """Mark the set as being written (its record removed) before any of its files is replaced."""
    (Path(sweep_dir) / RECORD).unlink(missing_ok=True)


def seal(sweep_dir: Path, runs: int) -> None:
    """Record the set as complete: each file's size and sha256 (written last, atomically)."""
    sweep_dir = Path(sweep_dir)
    files = {name: {"bytes": (sweep_dir / name).stat().st_size, "sha256": _sha256(sweep_dir / name)}
             for name in SET_FILES if (sweep_dir / name).is_file()}  # fmt: skip
    record = {"written": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"), "runs": runs, "files": files}
    run_files.atomic_write(sweep_dir / RECORD, lambda p: p.write_text(json.dumps(record, indent=2) + "\n"))


def set_problem(sweep_dir: Path) -> str:
    """"" when the folder's table files are one complete set, else what is wrong (naming the file)."""
    sweep_dir = Path(sweep_dir)
    present = [name for name in SET_FILES if (sweep_dir / name).is_file()]
    if not present:
        return ""
    try:
        record = json.loads((sweep_dir / RECORD).read_text())
        files = record["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return (f"{sweep_dir / RECORD} is missing or unreadable: the table files ({', '.join(present)}) are not "
                f"known to be one set (a sweep or report killed while writing them); rebuild them with "
                f"python -m taslel_bench.report {sweep_dir}")  # fmt: skip
    for name in SET_FILES:
        path = sweep_dir / name
        if name in files and (not path.is_file() or _sha256(path) != files[name].get("sha256")):
            return f"{path} is not the file of the set recorded in {RECORD} (changed or missing since)"
        if name not in files and path.is_file():
            return f"{path} is not part of the set recorded in {RECORD}"
    return ""


__all__ = ["RECORD", "SET_FILES", "begin", "seal", "set_problem"]
