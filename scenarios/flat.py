"""Flat ground with one Coulomb friction coefficient (``flat``, ``low_friction``)."""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.interfaces import MAX_FRICTION, ClearanceProfile, RoundObstacle
from taslel_bench.util.fields import number


def friction_coefficient(path: str, value: object) -> float:
    """A Coulomb coefficient from the config, in (0, MAX_FRICTION] (raises naming ``path``)."""
    return number(path, value, 0.0, MAX_FRICTION, lo_open=True)


class FlatGround:
    """The default floor of the plant with friction ``friction`` [-] for every foot contact."""

    def __init__(self, name: str = "flat", friction: float = 1.0) -> None:
        self.name = name
        self.friction = friction_coefficient("scenario.friction", friction)

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        spec.geom("floor").friction[0] = self.friction

    def friction_at(self, xy_in_world: np.ndarray) -> float:
        return self.friction

    def clearance_profile(self) -> ClearanceProfile | None:
        return None

    def obstacles(self) -> tuple[RoundObstacle, ...]:
        return ()

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        return None
