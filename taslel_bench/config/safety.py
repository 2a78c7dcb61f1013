"""The ``safety`` config group: the limits of the run's verdict (:mod:`taslel_bench.metrics.verdict`),
validated before anything is simulated (every field named with its value and the allowed range)."""

from __future__ import annotations

import dataclasses
from typing import Any

from omegaconf import DictConfig, OmegaConf

from taslel_bench.metrics.verdict import SafetyLimits
from taslel_bench.util.fields import fail, integer, number

MAX_TRIPS = 10_000
MAX_DEPTH_M = 0.5  # [m]
MAX_TOUCHDOWN_TOLERANCE_S = 0.1  # [s] half of the default swing


def safety_limits(cfg: DictConfig) -> SafetyLimits:
    """The ``safety`` block as :class:`SafetyLimits` (absent: the defaults); raises a ConfigError naming
    ``safety.<key>`` for an unknown key or a value out of range."""
    block = OmegaConf.select(cfg, "safety", default=None)
    if block is None:
        return SafetyLimits()
    if not isinstance(block, DictConfig):
        raise fail("safety", block, "must be a mapping of the verdict's limits")
    fields = {f.name for f in dataclasses.fields(SafetyLimits)}
    values: dict[str, Any] = {}  # int (trips_max) or float: SafetyLimits' fields
    for key, value in block.items():
        path = f"safety.{key}"
        if key not in fields:
            raise fail(path, value, f"unknown key; valid: {', '.join(sorted(fields))}")
        if key == "trips_max":
            values[key] = integer(path, value, 0, MAX_TRIPS)
        elif key.endswith("_s"):
            values[key] = number(path, value, 0.0, MAX_TOUCHDOWN_TOLERANCE_S, unit="s")
        elif key.endswith("_m"):
            values[key] = number(path, value, 0.0, MAX_DEPTH_M, unit="m")
        else:  # a rate
            values[key] = number(path, value, 0.0, 1.0)
    return SafetyLimits(**values)
