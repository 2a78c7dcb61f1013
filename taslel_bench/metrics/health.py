"""Run status: ``degraded`` means the filter's guarantee was broken in this run; a run whose filter failed, or
whose filter promised something the plant did not do, must not end plainly ``ok``.

``status`` is ``error`` (the episode could not run to its end), ``degraded`` (it ran, but one of the guarantee
checks below crossed its limit; ``degraded_reasons`` says which, with the measured value) or ``ok``. The guarantee
checks compare what the filter promised with what the plant did: its QP solved, its own barriers held and held as
the plant moved (the realised ECBF condition), the forces it planned lay inside the true friction cone, a foot it
planned to hold inside the cone did not slide, a foot it loaded was on the ground. The model residual (the
controller's model against the plant's motion) is model error, not a broken guarantee: ``model_error_reasons``
says when it crosses its limits, and ``health.model_error_degrades=true`` makes it degrade the run as well.
Limits come from the ``health`` block of the config.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from taslel_bench.util.params import param


@dataclass(frozen=True)
class HealthLimits:
    """The ``health`` block of the run config: a run that crosses one of the guarantee limits ends ``degraded``;
    one that crosses a model-error limit says so in ``model_error_reasons``."""

    qp_failed_rate_max: float = param(0.05, "share of filtered ticks whose QP failed (fallback torques applied)",
                                      lo=0.0, hi=1.0)
    barrier_negative_rate_max: float = param(0.05, "share of swing ticks with the filter's own barrier h < 0 "
                                                   "while solved", lo=0.0, hi=1.0)
    barrier_psi_realized_negative_rate_max: float = param(0.05, "share of swing ticks whose realised ECBF "
                                                                "condition was < -2 m/s²", lo=0.0, hi=1.0)
    demand_beyond_cone_rate_max: float = param(0.01, "share of filter-loaded feet whose planned force leaves the "
                                                     "true friction cone (worst 0.5 s window)", lo=0.0, hi=1.0)
    promise_cone_edge_rate_max: float = param(
        0.37, "share of filter-loaded feet planned inside the true cone whose plant force sits at the cone's edge "
              "(worst 0.5 s window)", lo=0.0, hi=1.0)
    promise_stance_in_air_rate_max: float = param(
        0.21, "share of filter-loaded feet that carry no load in the plant (worst 0.5 s window)", lo=0.0, hi=1.0)
    residual_alarm_rate_max: float = param(0.05, "model error: share of walking ticks whose model residual exceeds "
                                                 "one of the two bounds below", lo=0.0, hi=1.0)
    residual_trunk_force_n_max: float = param(5.0, "bound on |M vdot + h - S u - J'f| over the trunk-force rows",
                                              unit="N", lo=0.0, lo_open=True)
    residual_joint_nm_max: float = param(2.0, "bound on the largest joint row of the same residual", unit="N·m",
                                         lo=0.0, lo_open=True)
    model_error_degrades: bool = param(False, "true: a model error (residual alarms) also ends the run degraded")


# summary key -> (limit attribute, what crossing it means): the filter's guarantee
GUARANTEE_CHECKS = {
    "qp_failed_rate": ("qp_failed_rate_max", "QP failed (fallback torques)"),
    "barrier_negative_rate": ("barrier_negative_rate_max",
                              "filter's own barrier h < 0 on swing ticks while the QP reported solved"),
    "barrier_psi_realized_negative_rate": ("barrier_psi_realized_negative_rate_max",
                                           "the barrier evolved worse than the filter planned"),
    "filter_demand_beyond_cone_rate_worst_window": ("demand_beyond_cone_rate_max",
                                                    "filter planned forces outside the true cone (worst 0.5 s)"),
    "filter_promise_cone_edge_rate_worst_window": ("promise_cone_edge_rate_max",
                                                   "feet planned inside the true cone slid (worst 0.5 s)"),
    "filter_promise_stance_in_air_rate_worst_window": ("promise_stance_in_air_rate_max",
                                                       "feet the filter loaded were in the air (worst 0.5 s)"),
}
# the controller's model against the plant: model error
MODEL_CHECKS = {
    "residual_alarm_rate": ("residual_alarm_rate_max", "the controller's model disagrees with what the plant did"),
}


def _crossed(summary: dict[str, object], limits: HealthLimits, checks: dict[str, tuple[str, str]]) -> list[str]:
    out = []
    for key, (attr, meaning) in checks.items():
        value, limit = summary.get(key), getattr(limits, attr)
        if isinstance(value, (int, float)) and math.isfinite(value) and value > limit:
            out.append(f"{key}={value:.3g} > {limit:g} ({meaning})")
    return out


def model_errors(summary: dict[str, object], limits: HealthLimits) -> str:
    """The model-error limits crossed, "; "-joined ("" when none)."""
    return "; ".join(_crossed(summary, limits, MODEL_CHECKS))


def assess(summary: dict[str, object], limits: HealthLimits) -> tuple[str, str]:
    """(status, degraded reasons) for a summary whose episode ended with ``summary["status"]``."""
    if summary.get("status") == "error":
        return "error", ""
    reasons = _crossed(summary, limits, GUARANTEE_CHECKS)
    if limits.model_error_degrades:
        reasons += _crossed(summary, limits, MODEL_CHECKS)
    return ("degraded" if reasons else "ok"), "; ".join(reasons)
