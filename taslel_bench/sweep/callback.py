"""The Hydra callback that ends a multirun: aggregate the sweep folder into one table, write the report."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from taslel_bench.sweep.aggregate import SUMMARY_TABLE, aggregate
from taslel_bench.sweep.report import write_report


class SweepCallback(Callback):
    """Hydra callback: aggregate the sweep folder and write the report when a multirun ends."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        frame = aggregate(sweep_dir)
        report = write_report(sweep_dir, frame)
        n_err = int((frame.get("status") == "error").sum()) if not frame.empty else 0
        print(f"sweep: {len(frame)} runs ({n_err} with errors) -> {sweep_dir / SUMMARY_TABLE}, {report}")
