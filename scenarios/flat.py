"""Flat ground with one Coulomb friction coefficient (``flat``, ``low_friction``); the base of the other
scenarios (a world with nothing happening in it). Every scenario built on it takes the plant perturbation's
fields as well (``conf/mismatch_plant/``: joint damping, armature, friction loss, trunk mass and CoM, ...;
:class:`taslel_bench.interfaces.PlantPerturbation`), so a terrain world can run on the lossy plant; none given:
the plant is not edited."""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.interfaces import (
    MAX_FRICTION,
    ActuatorDelay,
    ClearanceProfile,
    Plane,
    PlantPerturbation,
    Terrain,
    number,
)


def friction_coefficient(path: str, value: object) -> float:
    """A Coulomb coefficient from the config, in (0, MAX_FRICTION] (raises naming ``path``)."""
    return number(path, value, 0.0, MAX_FRICTION, lo_open=True)


class FlatGround:
    """The plant's floor (z = 0) with friction ``friction`` [-] for every foot contact; ``plant``: plant
    perturbation fields (checked, errors name ``scenario.<field>``), applied to the plant only."""

    def __init__(self, name: str = "flat", friction: float = 1.0, **plant) -> None:
        self.name = name
        self.friction = friction_coefficient("scenario.friction", friction)
        self.terrain = Terrain((Plane(self.friction),))
        self.plant_perturbation = PlantPerturbation.checked("scenario", **plant) if plant else None
        delay = self.plant_perturbation.actuator_delay_steps if self.plant_perturbation else 0
        self._plant_delay = ActuatorDelay(delay) if delay else None

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        if self.plant_perturbation is not None:
            self.plant_perturbation.apply(spec)

    def clearance_profile(self) -> ClearanceProfile | None:
        return None

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        if self._plant_delay is not None:
            self._plant_delay.apply(data)
