"""The Hydra callback that ends a multirun: aggregate the sweep folder into one table, write the report, and
decide the sweep's exit code (``python -m taslel_bench`` exits with :func:`exit_code`).

Hydra turns an exception of a callback into a UserWarning and exits 0, so this callback never raises: a
failure to write the table or the report is one line on stderr and exit code 1. The table always has a row
per job: the jobs that could not leave a readable summary (a dead worker, a full disk) come from the
launcher's record (:data:`taslel_bench.sweep.jobs.JOB_OUTCOMES`)."""

from __future__ import annotations

import errno
import sys
from pathlib import Path
from typing import Any

import pandas as pd
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from taslel_bench.sweep import table_set
from taslel_bench.sweep.aggregate import SUMMARY_TABLE, aggregate, collect
from taslel_bench.sweep.jobs import JOB_OUTCOMES
from taslel_bench.sweep.report import write_report
from taslel_bench.sweep.stills import MAX_STRIPS
from taslel_bench.sweep.trackers import check_settings, log_sweep

EXIT_OK, EXIT_RUNS_FAILED = 0, 1
_state: dict[str, Any] = {"ended": False, "code": EXIT_OK}


def sweep_ended() -> bool:
    """A multirun's callback ran in this process."""
    return bool(_state["ended"])


def exit_code() -> int:
    """0: every run ok and table + report written; 1: a run error or degraded, or a table/report failure."""
    return int(_state["code"])


def _one_line(what: str, exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return f"error: disk full: could not write {what} ({exc.filename or ''}: {exc.strerror})"
    return f"error: could not write {what}: {type(exc).__name__}: {exc}"


def status_line(frame: pd.DataFrame) -> str:
    """``N runs (c with errors) [a ok, b degraded, c error]`` of a table."""
    counts = frame["status"].value_counts().to_dict() if "status" in frame else {}
    parts = ", ".join(f"{n} {status}" for status, n in sorted(counts.items()))
    return f"{len(frame)} runs ({counts.get('error', 0)} with errors) [{parts or 'none'}]"


def print_failed_rows(frame: pd.DataFrame) -> None:
    """One line per run that is not ok (its folder and message)."""
    if "status" not in frame:
        return
    for _, row in frame[frame["status"] != "ok"].iterrows():
        reason = row.get("degraded_reasons") if row.get("status") == "degraded" else row.get("message")
        print(f"  {row.get('status')}: {row.get('run_dir')}: {reason}")


class SweepCallback(Callback):
    """Hydra callback: aggregate the sweep folder and write the report when a multirun ends.
    ``max_still_strips`` (``hydra.callbacks.sweep_report.max_still_strips``): falls and trips drawn as still
    strips in the report, ~3 s each (:mod:`taslel_bench.sweep.stills`)."""

    def __init__(self, max_still_strips: int = MAX_STRIPS) -> None:
        self.max_still_strips = int(max_still_strips)

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        """Refuse a bad ``tracker.*`` value before any job runs."""
        if config.get("tracker") is not None:
            check_settings(config.tracker)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        _state["ended"] = True
        try:
            _state["code"] = self._end(config)
        except Exception as exc:  # never only a warning: say it and exit non-zero
            print(f"error: the sweep's end failed: {type(exc).__name__}: {exc}", file=sys.stderr)
            _state["code"] = EXIT_RUNS_FAILED

    def _end(self, config: DictConfig) -> int:
        sweep_dir = Path(config.hydra.sweep.dir)
        frame = collect(sweep_dir, dict(JOB_OUTCOMES))
        code = EXIT_OK if "status" in frame and (frame["status"] == "ok").all() and len(frame) else EXIT_RUNS_FAILED
        try:
            table_set.begin(sweep_dir)  # summary.parquet, table.csv/.tex and report.md: one set
            aggregate(sweep_dir, dict(JOB_OUTCOMES), frame=frame)
            report = write_report(sweep_dir, frame, max_stills=self.max_still_strips)
            table_set.seal(sweep_dir, len(frame))
        except Exception as exc:  # the table is still printed below
            print(_one_line(f"the sweep's table or report in {sweep_dir}", exc), file=sys.stderr)
            print(f"sweep: {status_line(frame)} (table not written)")
            print_failed_rows(frame)
            return EXIT_RUNS_FAILED
        print(f"sweep: {status_line(frame)} -> {sweep_dir / SUMMARY_TABLE}, {report}")
        print_failed_rows(frame)
        tracker = config.get("tracker")
        if tracker is not None and tracker.get("name", "none") != "none" and not frame.empty:
            parent = log_sweep(tracker, sweep_dir, frame)
            print(f"tracker {tracker.name}: {len(frame)} runs under parent run {parent} "
                  f"({tracker.get('uri') or 'outputs/mlflow.db'})")
        return code
