"""The run's outcome, beside its health: ``safe`` (bool) and ``unsafe_reasons`` in ``summary.json``.

``status`` (:mod:`taslel_bench.metrics.health`) says whether the harness and the filter worked; the verdict
says whether the robot came through safely. It is computed by the same rules with the filter on or off, from
plant measurements (a metric the run does not have, e.g. the filter's planned forces with the filter off, is
not a reason). A run is unsafe when it fell, or crossed one of the ``safety`` limits of the config
(:class:`SafetyLimits`, with their defaults and ranges). A run that ended in an error is not
judged: ``safe`` is False with the reason ``not_judged``.

Each reason is a :class:`Reason` value (tag, summary key, measured, limit); ``summary.json`` keeps them as text
(``unsafe_reasons``: ``<tag>: <key>=<measured> > <limit> (<meaning>)`` joined by "; ") and their tags
(``unsafe_reason_tags``: comma-joined), which is what the report counts (:data:`REASON_TAGS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from taslel_bench.util.params import param


@dataclass(frozen=True)
class SafetyLimits:
    """The ``safety`` block of the run config: the limits of the verdict (rates over the worst 0.5 s window of the
    walk, so a local event counts; a fall is always unsafe)."""

    trips_max: int = param(0, "trips allowed per run (a foot in the air striking a flank, or scuffing a walkable "
                                  "surface in the first half of its swing; a leg link touching an obstacle; a landing "
                                  "on a walkable surface later in the swing is a touchdown)", lo=0, hi=10_000)
    cone_edge_rate_worst_window_max: float = param(
        0.25, "share of loaded contacts at |f_t| >= 0.98 mu f_n (sliding) in any 0.5 s", lo=0.0, hi=1.0)
    clearance_violation_rate_worst_window_max: float = param(
        0.10, "share of swing ticks > 1 mm below the clearance profile in any 0.5 s", lo=0.0, hi=1.0)
    clearance_violation_depth_max_m: float = param(
        0.01, "deepest swing-foot violation of the clearance profile", unit="m", lo=0.0, hi=0.5)
    demand_beyond_cone_rate_worst_window_max: float = param(
        0.01, "share of filter-loaded feet planned outside the true cone in any 0.5 s", lo=0.0, hi=1.0)


# tag -> (summary key, limit attribute, what crossing it means); ``fell`` and ``not_judged`` have no limit
CHECKS = {
    "tripped": ("trips", "trips_max", "strikes and scuffs of a foot in the air, leg links touching an obstacle"),
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


@dataclass(frozen=True)
class Reason:
    """Why a run is unsafe: a tag of :data:`REASON_TAGS`, the summary key read, its value and the limit it crossed
    (nan where the reason has no limit: a fall, a run not judged), and what crossing it means."""

    tag: str
    key: str
    measured: float
    limit: float
    meaning: str

    @property
    def text(self) -> str:
        """``<tag>: <key>=<measured> > <limit> (<meaning>)`` (a fall: ``fell: at <t> s (<how>)``)."""
        if self.tag == "fell":
            return f"fell: at {self.measured:.2f} s ({self.meaning})"
        if self.tag == "not_judged":
            return f"not_judged: {self.meaning}"
        return f"{self.tag}: {self.key}={self.measured:.3g} > {self.limit:g} ({self.meaning})"


def judge(summary: dict[str, Any], limits: SafetyLimits) -> tuple[bool, str]:
    """(safe, reasons joined by "; ") of a run's summary: the text of :func:`reasons`."""
    found = reasons(summary, limits)
    return not found, "; ".join(r.text for r in found)


def reasons(summary: dict[str, Any], limits: SafetyLimits) -> list[Reason]:
    """Why the run of ``summary`` (``status``, ``fell`` and the keys of CHECKS) is unsafe; empty if it is safe."""
    if summary.get("status") == "error":
        return [Reason("not_judged", "status", math.nan, math.nan, "the episode ended in an error")]
    found = []
    if summary.get("fell"):
        found.append(Reason("fell", "time_to_fall_s", float(summary.get("time_to_fall_s", math.nan)), math.nan,
                            str(summary.get("fall_reason", ""))))
    for tag, (key, attr, meaning) in CHECKS.items():
        value = summary.get(key)
        limit = getattr(limits, attr)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > limit:
            found.append(Reason(tag, key, float(value), float(limit), meaning))
    return found


def reason_tags(reasons: object, tags: object = None) -> list[str]:
    """The tags of a run's unsafe reasons: ``unsafe_reason_tags`` (``tags``, comma-joined) where the summary has
    it, else read from an older summary's ``unsafe_reasons`` text (empty for a safe run or a missing value)."""
    if isinstance(tags, str):
        return [t for t in tags.split(",") if t]
    if not isinstance(reasons, str) or not reasons:
        return []
    return [part.split(":", 1)[0].strip() for part in reasons.split("; ") if ":" in part]
