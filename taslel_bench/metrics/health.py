"""Run status: a run whose filter failed, or whose filter reported success while its own safety condition
did not hold, must not end plainly ``ok``.

``status`` is ``error`` (the episode could not run to its end), ``degraded`` (it ran, but one of the limits
below was crossed; ``degraded_reasons`` says which, with the measured value) or ``ok``. Limits come from
the ``health`` block of the config.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from taslel_bench.util.params import param


@dataclass(frozen=True)
class HealthLimits:
    """The ``health`` block of the run config: a run that crosses one of these ends ``degraded``, not ``ok``."""

    qp_failed_rate_max: float = param(0.05, "share of filtered ticks whose QP failed (fallback torques applied)",
                                      lo=0.0, hi=1.0)
    barrier_negative_rate_max: float = param(0.05, "share of swing ticks with the filter's own barrier h < 0 "
                                                   "while solved", lo=0.0, hi=1.0)
    barrier_psi_realized_negative_rate_max: float = param(0.05, "share of swing ticks whose realised ECBF "
                                                                "condition was < -2 m/s²", lo=0.0, hi=1.0)
    demand_beyond_cone_rate_max: float = param(0.01, "share of filter-loaded feet whose planned force leaves the "
                                                     "true friction cone (worst 0.5 s window)", lo=0.0, hi=1.0)
    residual_alarm_rate_max: float = param(0.05, "share of walking ticks whose model residual exceeds one of the "
                                                 "two bounds below", lo=0.0, hi=1.0)
    residual_trunk_force_n_max: float = param(5.0, "bound on |M vdot + h - S u - J'f| over the trunk-force rows",
                                              unit="N", lo=0.0, lo_open=True)
    residual_joint_nm_max: float = param(2.0, "bound on the largest joint row of the same residual", unit="N·m",
                                         lo=0.0, lo_open=True)


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
