"""What an episode leaves: its trace and how it ended (the harness's view; the metrics judge it)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from taslel_bench.record.trace import EpisodeTrace


@dataclass
class EpisodeResult:
    trace: EpisodeTrace
    status: str = "ok"  # "ok" or "error" (the episode could not run to its end)
    message: str = ""
    fell: bool = False
    time_to_fall_s: float = math.nan  # [s] episode time of the first physics state past a fall threshold
    fall_reason: str = ""
    n_ticks: int = 0
    wall_time_s: float = 0.0  # [s] the episode loop, recording excluded
    extras: dict[str, object] = field(default_factory=dict)  # warmup_s, recording_s, residuals_s, fall_term ...
