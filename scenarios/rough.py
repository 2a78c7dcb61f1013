"""Rough ground (``rough``): a MuJoCo heightfield with seeded random relief of +-``amplitude_m`` over the
walking area, flat where the robot stands. The plant and the terrain object share the triangulated surface
(:class:`taslel_bench.interfaces.HeightField`). The field is an obstacle in the terrain's sense, so a swing
foot or lower leg touching it (outside the schedule's stance) counts as a trip; the floor (z = 0) stays under
and beyond it."""

from __future__ import annotations

import numpy as np

from scenarios.flat import FlatGround
from taslel_bench.interfaces import OBSTACLE, HeightField, Plane, Terrain, integer, number, rough_heights

FLAT_BEHIND_M = 1.0  # [m] the field starts this far behind the robot (flat, z = 0, under the stand)


class RoughGround(FlatGround):
    """Heightfield over world x in [-1 m, ``start_x_m`` + ``length_m``] (flat up to ``start_x_m``), |y| <=
    ``half_width_m`` [m],
    grid ``spacing_m`` [m]; relief = uniform noise smoothed over ``smoothing_cells`` cells, largest magnitude
    ``amplitude_m`` [m], drawn from ``seed`` (None: from the terrain's generator when the plant is built, a
    stream of the run seed) — blended in from 0 over the
    first ``ramp_m`` [m]. The floor (z = 0) is sunk to -``amplitude_m`` - 1 mm below the field."""

    def __init__(self, name: str = "rough", friction: float = 1.0, amplitude_m: float = 0.03, spacing_m: float = 0.05,
                 start_x_m: float = 0.3, length_m: float = 6.0, half_width_m: float = 1.0, ramp_m: float = 0.4,
                 smoothing_cells: int = 1, seed: int | None = None, **plant) -> None:  # fmt: skip
        super().__init__(name=name, friction=friction, **plant)
        self.amplitude_m = number("scenario.amplitude_m", amplitude_m, 0.0, 0.15, lo_open=True, unit="m")
        spacing = number("scenario.spacing_m", spacing_m, 0.01, 0.5, unit="m")
        start = number("scenario.start_x_m", start_x_m, 0.25, 50.0, unit="m", why="clear of the standing robot")
        length = number("scenario.length_m", length_m, 0.5, 50.0, unit="m")
        half = number("scenario.half_width_m", half_width_m, 0.3, 5.0, unit="m")
        ramp = number("scenario.ramp_m", ramp_m, 0.0, 5.0, unit="m")
        k = integer("scenario.smoothing_cells", smoothing_cells, 0, 10)
        x_lo, x_hi = -FLAT_BEHIND_M, start + length  # [m] the field, flat from x_lo to start
        ncol, nrow = round((x_hi - x_lo) / spacing) + 1, round(2 * half / spacing) + 1
        flat, blend, amp = round((start - x_lo) / spacing), round(ramp / spacing), self.amplitude_m

        def draw(rng: np.random.Generator) -> np.ndarray:
            return rough_heights(rng, nrow, ncol, amp, k, flat, blend)

        heights = (
            draw(np.random.default_rng(integer("scenario.seed", seed, 0, 2**31 - 1))) if seed is not None else None
        )
        field = HeightField(heights, draw=draw, centre_x_m=(x_lo + x_hi) / 2.0, centre_y_m=0.0,
                            half_x_m=(x_hi - x_lo) / 2.0, half_y_m=half, friction=self.friction,
                            role=OBSTACLE)  # fmt: skip
        self.terrain = Terrain((SunkFloor(self.friction, -self.amplitude_m - 1e-3), field))


class SunkFloor(Plane):
    """The plant's floor moved down to z = ``z_m`` [m] (under a heightfield whose relief dips below 0)."""

    def __init__(self, friction: float, z_m: float) -> None:
        super().__init__(friction)
        object.__setattr__(self, "z_m", float(z_m))

    def add_to(self, spec, body, name, rng) -> None:
        super().add_to(spec, body, name, rng)
        spec.geom("floor").pos[2] = self.z_m

    def top_z(self, x: float, y: float) -> float:
        return self.z_m

    def sphere_distance(self, centres, radius):
        d, n, p = super().sphere_distance(centres, radius)
        p[:, 2] = self.z_m
        return d - self.z_m, n, p
