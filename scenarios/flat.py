"""Flat ground with one Coulomb friction coefficient (``flat``, ``low_friction``)."""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.interfaces import ClearanceProfile, RoundObstacle


class FlatGround:
    """The default floor of the plant with friction ``friction`` [-] for every foot contact."""

    def __init__(self, name: str = "flat", friction: float = 1.0) -> None:
        if not friction > 0.0:
            raise ValueError(f"scenario.friction must be > 0, got {friction!r}")
        self.name = name
        self.friction = float(friction)

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
