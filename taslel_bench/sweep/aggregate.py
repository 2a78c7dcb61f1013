"""Sweep aggregation: every run folder's ``summary.json`` -> one ``summary.parquet`` row per run, failed
runs included, then the report. Called by Hydra at the end of a multirun (:class:`SweepCallback`, which
gets no job results: it reads the sweep folder) and usable on any folder of runs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd

from taslel_bench.record import run_files
from taslel_bench.record.run_files import OVERRIDE_SEPARATOR

SUMMARY_TABLE = "summary.parquet"
AXES = ("scenario", "solver", "estimator", "seed")
# swept override -> summary column (and its type, for the rows of crashed jobs)
OVERRIDE_COLUMNS = {"filter.formulation": "filter_formulation",
                    "filter.contact_velocity_gain": "filter_contact_velocity_gain"}  # fmt: skip
NUMERIC_COLUMNS = ("seed", "filter_contact_velocity_gain")


def run_folders(sweep_dir: Path) -> list[Path]:
    """Folders under ``sweep_dir`` that hold a job (its ``summary.json`` or Hydra's ``.hydra``); results put
    aside by a rerun (``<run>/superseded/...``) are not runs of this sweep."""
    found = {p.parent for p in sweep_dir.rglob("summary.json")}
    found |= {p.parent.parent for p in sweep_dir.rglob(".hydra/config.yaml")}
    return sorted(d for d in found if run_files.SUPERSEDED not in d.relative_to(sweep_dir).parts)


def _row_for_unfinished(run_dir: Path) -> dict[str, Any]:
    """A job folder without a summary: it crashed before finishing; say so, with what is known."""
    row: dict[str, Any] = {"status": "error", "message": "job left no summary.json (crashed or killed)"}
    overrides = run_dir / ".hydra" / "overrides.yaml"
    if overrides.is_file():
        items = [line.strip().lstrip("- ").strip() for line in overrides.read_text().splitlines()]
        items = [item for item in items if "=" in item]
        row["overrides"] = OVERRIDE_SEPARATOR.join(sorted(items))
        for item in items:
            key, value = item.split("=", 1)
            key = OVERRIDE_COLUMNS.get(key, key)
            if key in AXES or key in OVERRIDE_COLUMNS.values():
                row[key] = _typed(key, value)
    tb = run_dir / "traceback.txt"
    if tb.is_file():
        row["message"] = tb.read_text().strip().splitlines()[-1]
    return row


def _typed(column: str, value: str) -> Any:
    """An override's value as its summary column holds it (numbers for numeric columns)."""
    if column not in NUMERIC_COLUMNS:
        return value
    try:
        return int(value) if column == "seed" else float(value)
    except ValueError:
        return value


def aggregate(sweep_dir: Path) -> pd.DataFrame:
    """Write ``summary.parquet`` in ``sweep_dir`` (atomically) and return it."""
    sweep_dir = Path(sweep_dir)
    rows = []
    for run_dir in run_folders(sweep_dir):
        summary_path = run_dir / run_files.SUMMARY
        try:
            row = json.loads(summary_path.read_text()) if summary_path.is_file() else _row_for_unfinished(run_dir)
        except json.JSONDecodeError as exc:
            row = {"status": "error", "message": f"unreadable summary.json: {exc}"}
        row.pop("skipped", None)
        row["run_dir"] = str(run_dir.relative_to(sweep_dir))
        rows.append(row)
    frame = expand_overrides(pd.DataFrame(rows))
    if not frame.empty:
        frame = frame.sort_values([c for c in (*AXES, "run_dir") if c in frame.columns]).reset_index(drop=True)
    run_files.write_parquet(sweep_dir / SUMMARY_TABLE, frame)
    return frame




def parse_overrides(text: object) -> dict[str, str]:
    """``{key: value}`` of a summary's ``overrides`` text; the key without Hydra's ``+``/``~``/``++``."""
    if not isinstance(text, str):
        return {}
    items = (item.split("=", 1) for item in text.split(OVERRIDE_SEPARATOR) if "=" in item)
    return {key.lstrip("+~"): value for key, value in items}


def override_keys(frame: pd.DataFrame) -> list[str]:
    """The columns :func:`expand_overrides` made (keys overridden in some run, not already a column)."""
    if "overrides" not in frame.columns:
        return []
    keys = {k for text in frame["overrides"] for k in parse_overrides(text)}
    return sorted(k for k in keys if k in frame.columns and k not in AXES and k not in OVERRIDE_COLUMNS)


def expand_overrides(frame: pd.DataFrame) -> pd.DataFrame:
    """One column per overridden config key that is not already a column (``scenario.friction``,
    ``filter.enabled``, ``mismatch_plant``, ...), holding the override's value as text: the report groups
    rows by every override that varies across the sweep. Runs without the override get "" (the default)."""
    if "overrides" not in frame.columns:
        return frame
    parsed = [parse_overrides(text) for text in frame["overrides"]]
    for key in sorted({k for p in parsed for k in p}):
        if key in AXES or key in frame.columns or OVERRIDE_COLUMNS.get(key) in frame.columns:
            continue
        frame[key] = [p.get(key, "") for p in parsed]
    return frame
