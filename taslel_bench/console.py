"""Compact terminal output of a run summary (rich table)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

KEY_METRICS = (
    "status", "fell", "time_to_fall_s", "distance_m", "mean_speed_mps", "real_time_factor", "tick_us_median",
    "intervention_nm_mean", "qp_failed_rate", "qp_solve_us_median", "qp_solve_us_p99", "grf_mae_z_n",
    "grf_mae_xy_n", "friction_ratio_p95", "slip_mps_mean", "clearance_violation_rate", "clearance_min_m",
    "estimator_mae",
)


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "—" if v is None else str(v)


def print_summary(summary: dict, out_dir: Path) -> None:
    title = f"{summary.get('scenario')} · solver={summary.get('solver')} · estimator={summary.get('estimator')}"
    title += f" · seed={summary.get('seed')}"
    table = Table(title=title, show_header=True, header_style="bold")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for k in KEY_METRICS:
        if k in summary:
            table.add_row(k, _fmt(summary[k]))
    if summary.get("message"):
        table.add_row("message", str(summary["message"]))
    console = Console(stderr=False)
    console.print(table)
    console.print(f"run folder: {out_dir}")
    if summary.get("skipped"):
        console.print("already complete, skipped (force=true reruns it)")
