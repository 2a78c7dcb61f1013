"""Flat ground with one Coulomb friction coefficient (``flat``, ``low_friction``); the base of the other
scenarios (a world with nothing happening in it)."""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.interfaces import MAX_FRICTION, ClearanceProfile, Plane, Terrain, number


def friction_coefficient(path: str, value: object) -> float:
    """A Coulomb coefficient from the config, in (0, MAX_FRICTION] (raises naming ``path``)."""
    return number(path, value, 0.0, MAX_FRICTION, lo_open=True)


class FlatGround:
    """The plant's floor (z = 0) with friction ``friction`` [-] for every foot contact."""

    def __init__(self, name: str = "flat", friction: float = 1.0) -> None:
        self.name = name
        self.friction = friction_coefficient("scenario.friction", friction)
        self.terrain = Terrain((Plane(self.friction),))

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        return None

    def clearance_profile(self) -> ClearanceProfile | None:
        return None

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        return None
