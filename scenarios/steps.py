"""Steps across the path: boxes up and down (``steps``). Real geometry in the plant; the boxes are obstacles in
the terrain's sense (a swing foot or a lower leg touching one is a trip, as on the logs), and the filter's
terrain barriers get the same boxes."""

from __future__ import annotations

from scenarios.flat import FlatGround
from taslel_bench.interfaces import OBSTACLE, Box, Plane, Terrain, integer, number


class Steps(FlatGround):
    """Flat floor, then ``count_up`` steps of ``height_m`` [m] each, ``depth_m`` [m] deep, starting at world
    x = ``first_x_m`` [m], then as many steps back down to the floor; ``half_width_m`` [m] half their
    extent along y. Each step is one box from the floor to its top (heights h, 2h, ..., then down)."""

    def __init__(self, name: str = "steps", friction: float = 1.0, height_m: float = 0.05, depth_m: float = 0.6,
                 first_x_m: float = 0.8, count_up: int = 2, half_width_m: float = 0.8, **plant) -> None:  # fmt: skip
        super().__init__(name=name, friction=friction, **plant)
        self.height_m = number("scenario.height_m", height_m, 0.0, 0.3, lo_open=True, unit="m")
        depth = number("scenario.depth_m", depth_m, 0.2, 5.0, unit="m", why="a foot (0.04 m) and a stride fit")
        first = number("scenario.first_x_m", first_x_m, 0.4, 50.0, unit="m",
                       why="clear of the standing robot's feet: >= 0.4 m")
        n_up = integer("scenario.count_up", count_up, 1, 20)
        half = number("scenario.half_width_m", half_width_m, 0.3, 5.0, unit="m")
        levels = [k * self.height_m for k in range(1, n_up + 1)] + [k * self.height_m for k in range(n_up - 1, 0, -1)]
        boxes = tuple(Box(centre_m=(first + (i + 0.5) * depth, 0.0, z / 2.0), half_size_m=(depth / 2.0, half, z / 2.0),
                          friction=self.friction, role=OBSTACLE) for i, z in enumerate(levels))  # fmt: skip
        self.terrain = Terrain((Plane(self.friction), *boxes))
