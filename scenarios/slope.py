"""An incline up the path (``slope``): flat floor, a plane rising at ``angle_deg`` over ``run_m``, then a flat
plateau at the top. Real geometry in the plant (a pitched box and a box) and in the terrain object; both are
obstacles in the terrain's sense (a swing foot touching the incline is a trip, the filter's terrain barriers
keep the feet and shins clear of it)."""

from __future__ import annotations

from scenarios.flat import FlatGround
from taslel_bench.interfaces import OBSTACLE, Box, Plane, Ramp, Terrain, number


class Slope(FlatGround):
    """Floor up to world x = ``start_x_m`` [m], an incline of ``angle_deg`` [deg] over a horizontal ``run_m``
    [m], a plateau ``plateau_m`` [m] long at the top; ``half_width_m`` [m] half their extent along y."""

    def __init__(self, name: str = "slope", friction: float = 1.0, angle_deg: float = 10.0, start_x_m: float = 0.6,
                 run_m: float = 2.0, plateau_m: float = 5.0, half_width_m: float = 1.0, **plant) -> None:  # fmt: skip
        super().__init__(name=name, friction=friction, **plant)
        self.angle_deg = number("scenario.angle_deg", angle_deg, 0.0, 30.0, lo_open=True, unit="deg",
                                why="an incline the trot can stand on")
        start = number("scenario.start_x_m", start_x_m, 0.4, 50.0, unit="m", why="clear of the standing robot")
        run = number("scenario.run_m", run_m, 0.2, 50.0, unit="m")
        plateau = number("scenario.plateau_m", plateau_m, 0.0, 100.0, unit="m")
        half = number("scenario.half_width_m", half_width_m, 0.3, 5.0, unit="m")
        ramp = Ramp(start_x_m=start, run_m=run, angle_deg=self.angle_deg, half_width_m=half, friction=self.friction,
                    role=OBSTACLE)
        parts = [Plane(self.friction), ramp]
        if plateau > 0.0:
            top = ramp.rise_m
            parts.append(Box(centre_m=(start + run + plateau / 2.0, 0.0, top / 2.0),
                             half_size_m=(plateau / 2.0, half, top / 2.0), friction=self.friction, role=OBSTACLE))
        self.terrain = Terrain(tuple(parts))
