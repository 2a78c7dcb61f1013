"""Sweep aggregation: every run folder's ``summary.json`` -> one ``summary.parquet`` row per run, failed
runs included, then the report. Called by Hydra at the end of a multirun (:class:`SweepCallback`, which
gets no job results: it reads the sweep folder) and usable on any folder of runs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from taslel_bench.record import run_files
from taslel_bench.record.run_files import OVERRIDE_SEPARATOR
from taslel_bench.record.run_lock import live_holder

SUMMARY_TABLE = "summary.parquet"
RUNNING = "running"  # status of a job whose run folder a live process holds (a report rebuilt mid-sweep)
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
    """A job folder without a summary: running (a live process holds its run.lock) or crashed before
    finishing; say which, with what is known."""
    row: dict[str, Any] = {"status": "error", "message": "job left no summary.json (crashed or killed)"}
    holder = live_holder(run_dir)
    if holder is not None:
        row = {"status": RUNNING, "message": f"running: run.lock held by {holder}"}
    overrides = run_dir / ".hydra" / "overrides.yaml"
    try:
        text = overrides.read_text() if overrides.is_file() else ""
    except (OSError, UnicodeDecodeError):
        text = ""
    if text:
        items = [line.strip().lstrip("- ").strip() for line in text.splitlines()]
        items = [item for item in items if "=" in item]
        row["overrides"] = OVERRIDE_SEPARATOR.join(sorted(items))
        for item in items:
            key, value = item.split("=", 1)
            key = OVERRIDE_COLUMNS.get(key, key)
            if key in AXES or key in OVERRIDE_COLUMNS.values():
                row[key] = _typed(key, value)
    tb = run_dir / "traceback.txt"
    try:
        if holder is None and tb.is_file() and tb.read_text().strip():
            row["message"] = tb.read_text().strip().splitlines()[-1]
    except (OSError, UnicodeDecodeError):
        pass
    return row


def _typed(column: str, value: str) -> Any:
    """An override's value as its summary column holds it (numbers for numeric columns)."""
    if column not in NUMERIC_COLUMNS:
        return value
    try:
        return int(value) if column == "seed" else float(value)
    except ValueError:
        return value


def _unreadable(run_dir: Path, summary: dict) -> str:
    """What makes a finished run's files unusable ("" if nothing): a result set that does not match its
    manifest (a file missing, truncated or extra), a steps.parquet whose footer cannot be read, a config.yaml
    that is not YAML. The message names the file."""
    import pyarrow.parquet as pq

    _, problem = run_files.folder_state(run_dir)
    if problem:
        kind, _, name = problem.partition("-")
        what = {"missing": "is missing", "size": "does not have the size the run wrote (truncated or replaced)",
                "extra": "is not part of the run's result"}.get(kind, problem)  # fmt: skip
        return f"{run_dir / name}: {what}"
    steps, config = run_dir / run_files.STEPS, run_dir / "config.yaml"
    for path, read in ((steps, lambda p: pq.ParquetFile(p).metadata), (config, _yaml_mapping)):
        try:
            if path.is_file():
                read(path)
        except Exception as exc:  # ArrowInvalid, yaml errors, OSError: the row names the file
            return f"{path}: unreadable ({type(exc).__name__}: {(str(exc).splitlines() or [''])[0]})"
    return ""


def _yaml_mapping(path: Path) -> dict:
    import yaml

    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict):
        raise TypeError(f"holds a {type(data).__name__}, not a YAML mapping")
    return data


def _row(run_dir: Path, known: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The table row of one run folder; an unreadable summary or result file makes an error row naming it;
    ``known``: what the launcher saw each job of this sweep do, which wins over the folder (:func:`_outcome_row`)."""
    outcome = known.get(str(run_dir.absolute()))
    if outcome is None and live_holder(run_dir) is not None:
        return _row_for_unfinished(run_dir)  # a live job (a report rebuilt mid-sweep): running, whatever is there
    summary_path = run_dir / run_files.SUMMARY
    if not summary_path.is_file():
        row = dict(outcome or {}) or _row_for_unfinished(run_dir)
        row.setdefault("status", "error")
        return row
    row = run_files.read_summary(run_dir)
    if row is None:
        fallback = _row_for_unfinished(run_dir)
        fallback["message"] = f"{summary_path}: unreadable (truncated or not a JSON object)"
        return _outcome_row(run_dir, outcome, fallback) if outcome else fallback
    if outcome is not None:
        row = _outcome_row(run_dir, outcome, row)
    if row.get("status") in ("ok", "degraded") and (problem := _unreadable(run_dir, row)):
        row = {**row, "status_reported": row.get("status"), "status": "error", "message": problem}
    return row


def _outcome_row(run_dir: Path, outcome: dict[str, Any], folder_row: dict[str, Any]) -> dict[str, Any]:
    """The job's own outcome against the summary in its folder: a job that failed is an error row naming the
    folder and why, whatever summary the folder holds; a folder summary of another identity than the job's
    is never reported as the job's result."""
    job_sha, folder_sha = outcome.get("config_sha256"), folder_row.get("config_sha256")
    if job_sha and job_sha == folder_sha and outcome.get("status") == folder_row.get("status"):
        return folder_row  # the folder holds this job's own result
    if outcome.get("status") not in ("ok", "degraded"):
        row = dict(outcome)
        message = str(row.get("message", "the job failed"))
        row["message"] = message if str(run_dir) in message else f"{run_dir}: {message}"
        if folder_row.get("status") not in (None, "error"):  # an old result (an error summary is this job's own)
            row["message"] += (f" (the folder's summary.json, status {folder_row.get('status')}, config_sha256 "
                               f"{str(folder_row.get('config_sha256', 'unknown'))[:12]}, is not this job's result)")
        return row
    if job_sha and folder_sha != job_sha:
        return {**outcome, "status": "error", "status_reported": outcome.get("status"),
                "message": f"{run_dir / run_files.SUMMARY}: a run of another identity (config_sha256 "
                           f"{str(folder_sha)[:12]}) than this job's ({str(job_sha)[:12]}); not reported as this "
                           f"run"}  # fmt: skip
    return folder_row


def collect(sweep_dir: Path, known: dict[str, dict[str, Any]] | None = None) -> pd.DataFrame:
    """One row per run folder under ``sweep_dir`` (plus the ``known`` rows of jobs whose folder holds none),
    failed and unreadable runs included; never raises on one bad run."""
    sweep_dir = Path(sweep_dir)
    known = dict(known or {})
    rows = []
    folders = run_folders(sweep_dir)
    for run_dir in folders:
        row = _row(run_dir, known)
        row.pop("skipped", None)
        row.pop("identity", None)  # which files the identity hashed: in summary.json, not a table column
        row["run_dir"] = str(run_dir.relative_to(sweep_dir))
        rows.append(row)
    seen = {str(d.absolute()) for d in folders}
    for folder, row in known.items():  # a job that could not even create its folder
        if folder not in seen:
            rel = Path(folder).relative_to(sweep_dir.absolute()) if Path(folder).is_relative_to(sweep_dir.absolute()) \
                else Path(folder)
            rows.append({**row, "run_dir": str(rel)})
    frame = expand_overrides(pd.DataFrame(rows))
    if not frame.empty:
        frame = frame.sort_values([c for c in (*AXES, "run_dir") if c in frame.columns]).reset_index(drop=True)
    return frame


def aggregate(sweep_dir: Path, known: dict[str, dict[str, Any]] | None = None,
              frame: pd.DataFrame | None = None) -> pd.DataFrame:  # fmt: skip
    """Write ``summary.parquet`` in ``sweep_dir`` (atomically; ``frame``, else :func:`collect`) and return it."""
    sweep_dir = Path(sweep_dir)
    frame = collect(sweep_dir, known) if frame is None else frame
    run_files.write_parquet(sweep_dir / SUMMARY_TABLE, _parquet_safe(frame))
    return frame


def _parquet_safe(frame: pd.DataFrame) -> pd.DataFrame:
    """Columns of mixed Python types (a corrupt summary's odd values) as text, so the table can be written."""
    out = frame.copy()
    for col in out.columns:
        if out[col].dtype == object:
            kinds = {type(v) for v in out[col] if v is not None and not (isinstance(v, float) and pd.isna(v))}
            if len(kinds) > 1 or (kinds and not kinds <= {str, bool, int, float}):
                out[col] = [None if v is None else str(v) for v in out[col]]
    return out


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
