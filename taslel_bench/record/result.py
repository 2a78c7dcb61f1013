"""What an episode leaves: its trace and how it ended (the harness's view; the metrics judge it)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from taslel_bench.record.trace import EpisodeTrace


@dataclass
class EpisodeResult:
    trace: EpisodeTrace | None  # None: an episode run without one (Episode(trace=False))
    status: str = "ok"  # "ok" or "error" (the episode could not run to its end)
    message: str = ""
    fell: bool = False
    time_to_fall_s: float = math.nan  # [s] episode time of the first physics state past a fall threshold
    fall_reason: str = ""
    n_ticks: int = 0
    wall_time_s: float = 0.0  # [s] the episode loop, recording excluded
    extras: dict[str, Any] = field(default_factory=dict)  # warmup_s, recording_s, residuals_s, fall_term ...

    def traced(self) -> EpisodeTrace:
        """The episode's trace; ValueError for an episode run without one."""
        if self.trace is None:
            raise ValueError("the episode was run without a trace (Episode(trace=False))")
        return self.trace
