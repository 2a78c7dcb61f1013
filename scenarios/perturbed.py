"""Plant perturbations the controller's model does not know about (payload, joint losses, weaker
motors, actuator delay): applied to the MuJoCo plant only, so the Pinocchio model is wrong the way a real
robot's is -- unless the ``model`` config group (:mod:`taslel_bench.robot.model_options`) tells the model the same
values: trunk mass scale, CoM shift, joint damping, armature, joint friction and payload have the same
meanings and units on both sides."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from scenarios.flat import FlatGround
from scenarios.obstacle import checked_profile
from taslel_bench.interfaces import ActuatorDelay, ClearanceProfile, PlantPerturbation


class PerturbedPlant(FlatGround):
    """Flat floor + plant changes (:class:`taslel_bench.interfaces.PlantPerturbation`: the fields, their
    units and ranges, and the one implementation of each edit), plus ``coefficients``: an optional virtual
    swing-foot profile z(s) as in ``obstacle`` (null: none)."""

    def __init__(self, name: str = "perturbed", friction: float = 1.0, trunk_mass_scale: float = 1.0,
                 trunk_com_shift_m: Sequence[float] = (0.0, 0.0, 0.0),
                 joint_damping: float | Sequence[float] = 0.05,
                 joint_frictionloss: float | Sequence[float] = 0.1,
                 motor_strength_scale: float = 0.9, actuator_delay_steps: int = 2,
                 armature: float | Sequence[float] = 0.0, payload_mass_kg: float = 0.0,
                 payload_pos_m: Sequence[float] = (0.0, 0.0, 0.0),
                 coefficients: Sequence[float] | None = None) -> None:
        super().__init__(name=name, friction=friction)
        self.perturbation = PlantPerturbation.checked(
            "scenario", trunk_mass_scale=trunk_mass_scale, trunk_com_shift_m=trunk_com_shift_m,
            joint_damping=joint_damping, joint_frictionloss=joint_frictionloss, armature=armature,
            payload_mass_kg=payload_mass_kg, payload_pos_m=payload_pos_m,
            motor_strength_scale=motor_strength_scale, actuator_delay_steps=actuator_delay_steps)
        self._delay = ActuatorDelay(self.perturbation.actuator_delay_steps)
        # optional virtual obstacle under every swing foot (the paper's z(s)): clearance under mismatch
        self._profile = checked_profile(coefficients) if coefficients is not None else None

    def clearance_profile(self) -> ClearanceProfile | None:
        return self._profile

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        self.perturbation.apply(spec)

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        self._delay.apply(data)
