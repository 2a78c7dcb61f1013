"""A row of logs lying across the path: real geometry in the plant that a swing foot can trip on.

Each log is a cylinder with its axis along world y, partly sunk into the floor (its top ``height_m`` above
the floor). The plant gets them as capsules (exact sphere-capsule contact); the safety filter gets the same
geometry as its swing-foot obstacle barrier (the Euclidean clearance of the foot sphere,
:class:`taslel_bench.interfaces.RoundObstacle`), so a violated clearance is a real contact: a trip.
The paper's virtual phase profile z(s) can be added on top (``coefficients``); by default there is none.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from scenarios.flat import FlatGround
from taslel_bench import plant
from taslel_bench.interfaces import ClearanceProfile, RoundObstacle


class LogRow(FlatGround):
    """Flat floor with ``count`` logs of radius ``radius_m`` [m] whose tops are ``height_m`` [m] above the
    floor, the first at world x = ``first_x_m`` [m], then every ``spacing_m`` [m]; ``half_width_m`` [m] is
    half their length along y. The robot starts at x = 0 facing +x."""

    def __init__(self, name: str = "logs", friction: float = 1.0, height_m: float = 0.06, radius_m: float = 0.1,
                 first_x_m: float = 0.6, spacing_m: float = 0.7, count: int = 8, half_width_m: float = 0.5,
                 coefficients: Sequence[float] | None = None) -> None:  # fmt: skip
        super().__init__(name=name, friction=friction)
        rules = {
            "height_m": (height_m, 0.0 < height_m <= 2.0 * radius_m, "must be in (0, 2 radius_m] (log on the floor)"),
            "radius_m": (radius_m, 0.0 < radius_m <= 1.0, "must be in (0, 1] m"),
            "first_x_m": (first_x_m, first_x_m >= 0.35 + radius_m, "must be >= 0.35 m + radius_m (clear of the "
                          "standing robot's feet)"),
            "spacing_m": (spacing_m, spacing_m > 2.0 * radius_m, "must be > 2 radius_m (logs must not overlap)"),
            "count": (count, int(count) == count and 1 <= count <= 200, "must be an integer in [1, 200]"),
            "half_width_m": (half_width_m, 0.2 <= half_width_m <= 5.0, "must be in [0.2, 5] m"),
        }
        for key, (value, ok, rule) in rules.items():
            if not (np.isfinite(float(value)) and ok):
                raise ValueError(f"scenario.{key}={value!r}: {rule}")
        z_centre = height_m - radius_m
        self._obstacles = tuple(
            RoundObstacle(x_m=float(first_x_m + i * spacing_m), z_m=float(z_centre), radius_m=float(radius_m),
                          half_width_m=float(half_width_m))
            for i in range(int(count))
        )
        self._profile = ClearanceProfile(tuple(float(c) for c in coefficients)) if coefficients else None

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        super().build(spec, rng)
        plant.add_round_obstacles(spec, self._obstacles, self.friction)

    def clearance_profile(self) -> ClearanceProfile | None:
        return self._profile

    def obstacles(self) -> tuple[RoundObstacle, ...]:
        return self._obstacles
