"""The run's outcome, beside its health: ``safe`` (bool) and ``unsafe_reasons`` in ``summary.json``.

``status`` (:mod:`taslel_bench.metrics.health`) says whether the harness and the filter worked; the verdict
says whether the robot came through safely. It is computed by the same rules with the filter on or off, from
plant measurements (a metric the run does not have, e.g. the filter's planned forces with the filter off, is
not a reason). A run is unsafe when it fell, or crossed one of the ``safety`` limits of the config
(:class:`SafetyLimits`, defaults below and in ``conf/config.yaml``). A run that ended in an error is not
judged: ``safe`` is False with the reason ``not_judged``.

Each reason is ``<tag>: <measurement>``; the tags (:data:`REASON_TAGS`) are what the report counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class SafetyLimits:
    trips_max: int = 0  # [-] trips per run (a swing foot's or a leg link's new contact with an obstacle)
    # [s] > 0: a swing foot landing on an obstacle's top at most this long before its scheduled touchdown is an
    # early touchdown, not a trip (as on the floor): the check reads ``trips_beyond_touchdown_tolerance``
    # instead of ``trips``; 0: every trip counts
    trip_touchdown_tolerance_s: float = 0.0
    cone_edge_rate_worst_window_max: float = 0.25  # [-] loaded contacts at the cone edge, worst 0.5 s window
    clearance_violation_rate_worst_window_max: float = 0.10  # [-] swing ticks > 1 mm below z(s), worst window
    clearance_violation_depth_max_m: float = 0.01  # [m] deepest swing-foot violation of the profile z(s)
    demand_beyond_cone_rate_worst_window_max: float = 0.01  # [-] filter-loaded feet planned beyond the true cone


# tag -> (summary key, limit attribute, what crossing it means); ``fell`` and ``not_judged`` have no limit
CHECKS = {
    "tripped": ("trips", "trips_max", "new contacts of a swing foot or a leg link with an obstacle"),
    "cone_edge": ("friction_cone_edge_rate_worst_window", "cone_edge_rate_worst_window_max",
                  "loaded contacts at the friction-cone edge (sliding), worst 0.5 s"),
    "clearance": ("clearance_violation_rate_worst_window", "clearance_violation_rate_worst_window_max",
                  "swing ticks below the clearance profile, worst 0.5 s"),
    "clearance_depth": ("clearance_violation_depth_max_m", "clearance_violation_depth_max_m",
                        "deepest swing-foot violation of the clearance profile [m]"),
    "beyond_cone": ("filter_demand_beyond_cone_rate_worst_window", "demand_beyond_cone_rate_worst_window_max",
                    "planned contact forces outside the true friction cone, worst 0.5 s"),
}
REASON_TAGS = ("not_judged", "fell", *CHECKS)


def judge(summary: dict[str, object], limits: SafetyLimits) -> tuple[bool, str]:
    """(safe, reasons joined by "; ") of a run's summary (``status``, ``fell`` and the keys of CHECKS)."""
    if summary.get("status") == "error":
        return False, "not_judged: the episode ended in an error"
    reasons = []
    if summary.get("fell"):
        reasons.append(f"fell: at {float(summary.get('time_to_fall_s', math.nan)):.2f} s "
                       f"({summary.get('fall_reason', '')})")
    for tag, (key, attr, meaning) in CHECKS.items():
        if tag == "tripped" and limits.trip_touchdown_tolerance_s > 0.0:
            key = "trips_beyond_touchdown_tolerance"
            meaning += (f", top landings within {1e3 * limits.trip_touchdown_tolerance_s:g} ms of the scheduled "
                        f"touchdown not counted")
        value = summary.get(key)
        limit = getattr(limits, attr)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > limit:
            reasons.append(f"{tag}: {key}={value:.3g} > {limit:g} ({meaning})")
    return not reasons, "; ".join(reasons)


def reason_tags(reasons: object) -> list[str]:
    """The tags of an ``unsafe_reasons`` text (empty for a safe run or a missing value)."""
    if not isinstance(reasons, str) or not reasons:
        return []
    return [part.split(":", 1)[0].strip() for part in reasons.split("; ") if ":" in part]
