"""Run status: a run whose filter failed, or whose filter reported success while its own safety condition
did not hold, must not end plainly ``ok``.

``status`` is ``error`` (the episode could not run to its end), ``degraded`` (it ran, but one of the limits
below was crossed; ``degraded_reasons`` says which, with the measured value) or ``ok``. Limits come from
the ``health`` block of the config.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class HealthLimits:
    qp_failed_rate_max: float = 0.05  # [-] share of filtered ticks whose QP failed (fallback torque applied)
    barrier_negative_rate_max: float = 0.05  # [-] share of swing ticks with the filter's h < 0 while solved
    barrier_psi_realized_negative_rate_max: float = 0.05  # [-] swing ticks whose realised ECBF condition < 0
    demand_beyond_cone_rate_max: float = 0.01  # [-] filter-loaded feet planned beyond the true cone, worst 0.5 s
    residual_alarm_rate_max: float = 0.05  # [-] walking ticks with a model residual beyond the bounds below
    residual_trunk_force_n_max: float = 5.0  # [N] per-tick bound on |trunk-force residual|
    residual_joint_nm_max: float = 2.0  # [N·m] per-tick bound on the largest joint residual


# summary key -> (limit attribute, what crossing it means)
CHECKS = {
    "qp_failed_rate": ("qp_failed_rate_max", "QP failed (fallback torques)"),
    "barrier_negative_rate": ("barrier_negative_rate_max",
                              "filter's own barrier h < 0 on swing ticks while the QP reported solved"),
    "barrier_psi_realized_negative_rate": ("barrier_psi_realized_negative_rate_max",
                                           "the barrier evolved worse than the filter planned"),
    "filter_demand_beyond_cone_rate_worst_window": ("demand_beyond_cone_rate_max",
                                                    "filter planned forces outside the true cone (worst 0.5 s)"),
    "residual_alarm_rate": ("residual_alarm_rate_max",
                            "the controller's model disagrees with what the plant did"),
}


def assess(summary: dict[str, object], limits: HealthLimits) -> tuple[str, str]:
    """(status, reasons) for a summary whose episode ended with ``summary["status"]``."""
    if summary.get("status") == "error":
        return "error", ""
    reasons = []
    for key, (attr, meaning) in CHECKS.items():
        value = summary.get(key)
        limit = getattr(limits, attr)
        if isinstance(value, (int, float)) and math.isfinite(value) and value > limit:
            reasons.append(f"{key}={value:.3g} > {limit:g} ({meaning})")
    return ("degraded" if reasons else "ok"), "; ".join(reasons)
