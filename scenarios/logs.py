"""A row of logs lying across the path: real geometry in the plant that a swing foot can trip on.

Each log is a cylinder with its axis along world y, partly sunk into the floor (its top ``height_m`` above
the floor). The plant gets them as capsules (exact sphere-capsule contact); the safety filter gets the same
geometry as its swing-foot obstacle barrier (the Euclidean clearance of the foot sphere,
:class:`taslel_bench.terrain.parts.Log`), so a violated clearance is a real contact: a trip.
The paper's virtual phase profile z(s) can be added on top (``coefficients``); by default there is none.
"""

from __future__ import annotations

from collections.abc import Sequence

from scenarios.flat import FlatGround
from scenarios.obstacle import checked_profile
from taslel_bench.interfaces import ClearanceProfile, Log, Plane, Terrain, integer, number


class LogRow(FlatGround):
    """Flat floor with ``count`` logs of radius ``radius_m`` [m] whose tops are ``height_m`` [m] above the
    floor, the first at world x = ``first_x_m`` [m], then every ``spacing_m`` [m]; ``half_width_m`` [m] is
    half their length along y. The robot starts at x = 0 facing +x."""

    def __init__(self, name: str = "logs", friction: float = 1.0, height_m: float = 0.06, radius_m: float = 0.1,
                 first_x_m: float = 0.6, spacing_m: float = 0.7, count: int = 8, half_width_m: float = 0.5,
                 coefficients: Sequence[float] | None = None, **plant) -> None:  # fmt: skip
        super().__init__(name=name, friction=friction, **plant)
        radius = number("scenario.radius_m", radius_m, 0.0, 1.0, lo_open=True, unit="m")
        height = number("scenario.height_m", height_m, 0.0, 2.0 * radius, lo_open=True, unit="m",
                        why="the log lies on the floor, sunk to height_m - radius_m")
        first = number("scenario.first_x_m", first_x_m, 0.35 + radius, 50.0, unit="m",
                       why="clear of the standing robot's feet: >= 0.35 m + radius_m")
        spacing = number("scenario.spacing_m", spacing_m, 2.0 * radius, 10.0, lo_open=True, unit="m",
                         why="logs must not overlap: > 2 radius_m")
        n = integer("scenario.count", count, 1, 200)
        half = number("scenario.half_width_m", half_width_m, 0.2, 5.0, unit="m")
        logs = tuple(Log(x_m=first + i * spacing, z_m=height - radius, radius_m=radius, half_width_m=half,
                         friction=self.friction) for i in range(n))
        self.terrain = Terrain((Plane(self.friction), *logs))
        self._profile = checked_profile(coefficients) if coefficients is not None else None

    def clearance_profile(self) -> ClearanceProfile | None:
        return self._profile
