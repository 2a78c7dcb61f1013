"""The Hydra callback that ends a multirun: aggregate the sweep folder into one table, write the report."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from taslel_bench.sweep.aggregate import SUMMARY_TABLE, aggregate
from taslel_bench.sweep.report import write_report
from taslel_bench.sweep.trackers import check_settings, log_sweep


class SweepCallback(Callback):
    """Hydra callback: aggregate the sweep folder and write the report when a multirun ends."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        """Refuse a bad ``tracker.*`` value before any job runs."""
        if config.get("tracker") is not None:
            check_settings(config.tracker)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        frame = aggregate(sweep_dir)
        report = write_report(sweep_dir, frame)
        n_err = int((frame.get("status") == "error").sum()) if not frame.empty else 0
        print(f"sweep: {len(frame)} runs ({n_err} with errors) -> {sweep_dir / SUMMARY_TABLE}, {report}")
        tracker = config.get("tracker")
        if tracker is not None and tracker.get("name", "none") != "none" and not frame.empty:
            parent = log_sweep(tracker, sweep_dir, frame)
            print(f"tracker {tracker.name}: {len(frame)} runs under parent run {parent} ({tracker.get('uri') or 'outputs/mlflow.db'})")
