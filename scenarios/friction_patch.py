"""Floor whose friction changes part-way along the path (e.g. 0.8, then 0.2 from x = 1.2 m)."""

from __future__ import annotations

import mujoco
import numpy as np

from scenarios.flat import friction_coefficient
from taslel_bench.interfaces import ClearanceProfile, RoundObstacle
from taslel_bench.plant.build import add_terrain_geom
from taslel_bench.util.fields import number

HALF_LENGTH_M = 50.0  # [m] half-extent of each floor patch
THICKNESS_M = 0.1  # [m] patch boxes: top face at z = 0


class FrictionPatch:
    """Two floor patches: friction ``friction`` for world x < ``change_at_m``, ``friction_after`` beyond."""

    def __init__(self, name: str = "friction_patch", friction: float = 0.8, friction_after: float = 0.2,
                 change_at_m: float = 1.2) -> None:
        self.name = name
        self.friction = friction_coefficient("scenario.friction", friction)
        self.friction_after = friction_coefficient("scenario.friction_after", friction_after)
        self.change_at_m = number("scenario.change_at_m", change_at_m, -HALF_LENGTH_M, HALF_LENGTH_M,
                                  unit="m", why="the floor patches are 100 m long")

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        spec.delete(spec.geom("floor"))
        half = [HALF_LENGTH_M, HALF_LENGTH_M, THICKNESS_M / 2]
        x0 = self.change_at_m
        for name, mu, cx, rgba in (
            ("floor_before", self.friction, x0 - HALF_LENGTH_M, (0.55, 0.6, 0.65, 1.0)),
            ("floor_after", self.friction_after, x0 + HALF_LENGTH_M, (0.6, 0.75, 0.9, 1.0)),
        ):
            add_terrain_geom(spec, name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=half, friction=mu,
                                   pos=(cx, 0.0, -THICKNESS_M / 2), rgba=rgba)

    def friction_at(self, xy_in_world: np.ndarray) -> float:
        return self.friction if float(xy_in_world[0]) < self.change_at_m else self.friction_after

    def clearance_profile(self) -> ClearanceProfile | None:
        return None

    def obstacles(self) -> tuple[RoundObstacle, ...]:
        return ()

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        return None
