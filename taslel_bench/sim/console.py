"""Compact terminal output of a run summary (rich table), then the verdict's and the health check's reasons in
full, one a line (a table cell would cut them at the terminal's width)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

REASON_KEYS = ("unsafe_reasons", "degraded_reasons")  # "; "-joined reasons, printed in full below the table
KEY_METRICS = (
    "status", "safe", "fell", "time_to_fall_s", "fall_reason", "distance_m",
    "mean_speed_mps",
    "real_time_factor", "tick_us_median", "intervention_nm_mean", "u_nom_nm_mean", "qp_failed_rate",
    "qp_solve_us_median", "qp_solve_us_p99", "grf_mae_z_n", "grf_mae_z_n_stance", "friction_cone_edge_rate",
    "filter_demand_beyond_cone_rate", "slip_mps_mean", "sliding_distance_m", "clearance_violation_rate",
    "clearance_min_m", "trips", "barrier_negative_rate", "estimator_mae",
)
# what the plant is against what the controller's model believes (taslel_bench.plant.comparison) and how wrong
# the model was in the episode (taslel_bench.metrics.residuals)
MODEL_METRICS = (
    "plant_total_mass_kg", "model_total_mass_kg", "model_minus_plant_com_stand_m",
    "plant_joint_damping_nms_per_rad_max", "model_joint_damping_nms_per_rad_max", "plant_joint_armature_kgm2_max",
    "model_joint_armature_kgm2_max", "plant_joint_frictionloss_nm_max", "model_joint_frictionloss_nm_max",
    "plant_integrator", "residual_trunk_force_n_rms", "residual_joint_nm_rms", "residual_alarm_rate",
)


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "—" if v is None else str(v)


def reason_lines(summary: dict) -> list[str]:
    """``unsafe: <reason>`` and ``degraded: <reason>``, one line per reason, nothing cut."""
    lines = []
    for key, label in zip(REASON_KEYS, ("unsafe", "degraded"), strict=True):
        text = summary.get(key)
        if isinstance(text, str) and text:
            lines.extend(f"{label}: {part}" for part in text.split("; ") if part)
    return lines


def print_summary(summary: dict, out_dir: Path) -> None:
    title = f"{summary.get('scenario')} · solver={summary.get('solver')} · estimator={summary.get('estimator')}"
    title += f" · seed={summary.get('seed')}"
    table = Table(title=title, show_header=True, header_style="bold")
    table.add_column("metric", overflow="fold")
    table.add_column("value", justify="right", overflow="fold")
    for k in (*KEY_METRICS, *MODEL_METRICS):
        if k in summary and summary[k] not in ("", None):
            table.add_row(k, _fmt(summary[k]))
    if summary.get("message"):
        table.add_row("message", str(summary["message"]))
    console = Console(stderr=False)
    console.print(table)
    for line in reason_lines(summary):
        console.print(line, soft_wrap=True, highlight=False, markup=False)
    console.print(f"run folder: {out_dir}")
    if summary.get("skipped"):
        console.print("already complete, skipped (force=true reruns it)")
