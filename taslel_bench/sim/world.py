"""A world with nothing happening in it: a terrain, optionally the paper's virtual profile, optionally a plant
perturbation. The :class:`taslel_bench.interfaces.Scenario` of the loops that build their own plant (estimator
data collection, in-loop studies) through :mod:`taslel_bench.api`; benchmark runs get theirs from the
``scenario`` axis."""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from taslel_bench.plant.perturbation import PlantPerturbation
from taslel_bench.terrain.profile import ClearanceProfile
from taslel_bench.terrain.terrain import Terrain


@dataclass
class StaticWorld:
    terrain: Terrain = field(default_factory=Terrain)
    profile: ClearanceProfile | None = None
    perturbation: PlantPerturbation = field(default_factory=PlantPerturbation)
    name: str = "static"

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        self.perturbation.apply(spec)

    def clearance_profile(self) -> ClearanceProfile | None:
        return self.profile

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        return None
