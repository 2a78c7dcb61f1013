"""Plant perturbations the controller's model does not know about (payload, joint losses, weaker
motors, actuator delay): applied to the MuJoCo plant only, so the Pinocchio model is wrong the way a real
robot's is."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import mujoco
import numpy as np

from scenarios.flat import FlatGround
from taslel_bench import robot
from taslel_bench.fields import integer, number, numbers

MAX_SCALE = 10.0  # [-] mass and motor-strength factors
MAX_COM_SHIFT_M = 0.2  # [m] per axis (the trunk is 0.27 x 0.19 x 0.11 m)
MAX_JOINT_LOSS = 10.0  # [N·m·s/rad] damping, [N·m] dry friction (the motors give 33.5 N·m)
MAX_DELAY_STEPS = 1000  # [physics steps]


class PerturbedPlant(FlatGround):
    """Flat floor + plant changes. Scales are multiplicative on the URDF values; 1.0 / 0 = unchanged.

    * ``trunk_mass_scale`` (payload: trunk mass and inertia scaled together), ``trunk_com_shift_m`` [m]
      in the trunk frame;
    * ``joint_damping`` [N·m·s/rad] and ``joint_frictionloss`` [N·m] added to every leg joint;
    * ``motor_strength_scale`` (actuator gear: the torque the plant applies per commanded N·m);
    * ``actuator_delay_steps``: commands reach the plant this many physics steps late.
    """

    def __init__(self, name: str = "perturbed", friction: float = 1.0, trunk_mass_scale: float = 1.0,
                 trunk_com_shift_m: Sequence[float] = (0.0, 0.0, 0.0), joint_damping: float = 0.0,
                 joint_frictionloss: float = 0.0, motor_strength_scale: float = 1.0,
                 actuator_delay_steps: int = 0) -> None:
        super().__init__(name=name, friction=friction)
        s = "scenario."
        self.trunk_mass_scale = number(s + "trunk_mass_scale", trunk_mass_scale, 0.0, MAX_SCALE, lo_open=True)
        shift = numbers(s + "trunk_com_shift_m", trunk_com_shift_m, -MAX_COM_SHIFT_M, MAX_COM_SHIFT_M,
                        length=3, unit="m", why="[x, y, z] in the trunk frame")
        self.trunk_com_shift_m = np.asarray(shift)
        self.joint_damping = number(s + "joint_damping", joint_damping, 0.0, MAX_JOINT_LOSS, unit="N·m·s/rad")
        self.joint_frictionloss = number(s + "joint_frictionloss", joint_frictionloss, 0.0, MAX_JOINT_LOSS,
                                         unit="N·m")
        self.motor_strength_scale = number(s + "motor_strength_scale", motor_strength_scale, 0.0, MAX_SCALE,
                                           lo_open=True)
        self.actuator_delay_steps = integer(s + "actuator_delay_steps", actuator_delay_steps, 0,
                                            MAX_DELAY_STEPS, unit="physics steps")
        self._queue: deque[np.ndarray] = deque()

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        super().build(spec, rng)
        trunk = spec.body(robot.TRUNK_BODY)
        trunk.mass *= self.trunk_mass_scale
        trunk.inertia[:] = np.asarray(trunk.inertia) * self.trunk_mass_scale  # URDF import: fullinertia
        trunk.fullinertia[:] = np.asarray(trunk.fullinertia) * self.trunk_mass_scale
        trunk.ipos[:] = np.asarray(trunk.ipos) + self.trunk_com_shift_m
        for name in robot.JOINT_NAMES:
            joint = spec.joint(name)
            joint.damping += self.joint_damping
            joint.frictionloss += self.joint_frictionloss
        for act in spec.actuators:
            act.gear[0] *= self.motor_strength_scale

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        if self.actuator_delay_steps == 0:
            return
        if not self._queue:  # first call: the plant starts with the first command, then lags
            self._queue.extend(data.ctrl.copy() for _ in range(self.actuator_delay_steps))
        self._queue.append(data.ctrl.copy())
        data.ctrl[:] = self._queue.popleft()
