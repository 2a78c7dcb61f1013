"""Floor whose friction changes part-way along the path (e.g. 0.8, then 0.2 from x = 1.2 m)."""

from __future__ import annotations

from scenarios.flat import FlatGround, friction_coefficient
from taslel_bench.interfaces import FrictionStrips, Terrain, number

HALF_LENGTH_M = 50.0  # [m] half-extent of each floor patch
THICKNESS_M = 0.1  # [m] patch boxes: top face at z = 0


class FrictionPatch(FlatGround):
    """Two floor strips: friction ``friction`` for world x < ``change_at_m``, ``friction_after`` beyond."""

    def __init__(self, name: str = "friction_patch", friction: float = 0.8, friction_after: float = 0.2,
                 change_at_m: float = 1.2, **plant) -> None:
        super().__init__(name=name, friction=friction, **plant)
        self.friction_after = friction_coefficient("scenario.friction_after", friction_after)
        self.change_at_m = number("scenario.change_at_m", change_at_m, -HALF_LENGTH_M, HALF_LENGTH_M,
                                  unit="m", why="the floor patches are 100 m long")
        self.terrain = Terrain((FrictionStrips((self.change_at_m,), (self.friction, self.friction_after),
                                               HALF_LENGTH_M, THICKNESS_M),))
