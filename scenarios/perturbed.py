"""Plant perturbations the controller's model does not know about (payload, joint losses, weaker
motors, actuator delay): applied to the MuJoCo plant only, so the Pinocchio model is wrong the way a real
robot's is -- unless the ``model`` config group (:mod:`taslel_bench.robot.model_options`) tells the model the same
values: trunk mass scale, CoM shift, joint damping, armature, joint friction and payload have the same
meanings and units on both sides."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import mujoco
import numpy as np

from scenarios.flat import FlatGround
from scenarios.obstacle import checked_profile
from taslel_bench.interfaces import ClearanceProfile, a1, integer, number, number_or_list, numbers

MAX_SCALE = 10.0  # [-] mass and motor-strength factors
MAX_COM_SHIFT_M = 0.2  # [m] per axis (the trunk is 0.27 x 0.19 x 0.11 m)
MAX_JOINT_LOSS = 10.0  # [N·m·s/rad] damping, [N·m] dry friction (the motors give 33.5 N·m)
MAX_ARMATURE_KGM2 = 1.0  # [kg·m²] (real leg rotors reflect ~0.005-0.05 through their gearbox)
MAX_PAYLOAD_KG = 50.0  # [kg] (the A1 weighs 13.7 kg)
MAX_PAYLOAD_OFFSET_M = 0.5  # [m] per axis, trunk frame
MAX_DELAY_STEPS = 1000  # [physics steps]
PAYLOAD_BODY = "payload"


class PerturbedPlant(FlatGround):
    """Flat floor + plant changes. Scales are multiplicative on the URDF values; 1.0 / 0 = unchanged.

    * ``trunk_mass_scale`` (the trunk link's mass and inertia about its CoM scaled together),
      ``trunk_com_shift_m`` [m] in the trunk frame;
    * ``payload_mass_kg`` [kg]: a point mass fixed to the trunk at ``payload_pos_m`` [m, trunk frame];
    * ``joint_damping`` [N·m·s/rad], ``armature`` [kg·m²] and ``joint_frictionloss`` [N·m] added to the
      leg joints: one number for all 12 or 12 numbers in the core joint order (legs FL, FR, RL, RR);
    * ``motor_strength_scale`` (actuator gear: the torque the plant applies per commanded N·m);
    * ``actuator_delay_steps``: commands reach the plant this many physics steps late;
    * ``coefficients``: an optional virtual swing-foot profile z(s) as in ``obstacle`` (null: none).
    """

    def __init__(self, name: str = "perturbed", friction: float = 1.0, trunk_mass_scale: float = 1.0,
                 trunk_com_shift_m: Sequence[float] = (0.0, 0.0, 0.0),
                 joint_damping: float | Sequence[float] = 0.0,
                 joint_frictionloss: float | Sequence[float] = 0.0,
                 motor_strength_scale: float = 1.0, actuator_delay_steps: int = 0,
                 armature: float | Sequence[float] = 0.0, payload_mass_kg: float = 0.0,
                 payload_pos_m: Sequence[float] = (0.0, 0.0, 0.0),
                 coefficients: Sequence[float] | None = None) -> None:
        super().__init__(name=name, friction=friction)
        s = "scenario."
        self.trunk_mass_scale = number(s + "trunk_mass_scale", trunk_mass_scale, 0.0, MAX_SCALE, lo_open=True)
        shift = numbers(s + "trunk_com_shift_m", trunk_com_shift_m, -MAX_COM_SHIFT_M, MAX_COM_SHIFT_M,
                        length=3, unit="m", why="[x, y, z] in the trunk frame")
        self.trunk_com_shift_m = np.asarray(shift)
        n = a1.N_JOINTS
        self.joint_damping = number_or_list(s + "joint_damping", joint_damping, 0.0, MAX_JOINT_LOSS, length=n,
                                            unit="N·m·s/rad")
        self.joint_frictionloss = number_or_list(s + "joint_frictionloss", joint_frictionloss, 0.0,
                                                 MAX_JOINT_LOSS, length=n, unit="N·m")
        self.armature = number_or_list(s + "armature", armature, 0.0, MAX_ARMATURE_KGM2, length=n,
                                       unit="kg·m²")
        self.payload_mass_kg = number(s + "payload_mass_kg", payload_mass_kg, 0.0, MAX_PAYLOAD_KG, unit="kg")
        self.payload_pos_m = numbers(s + "payload_pos_m", payload_pos_m, -MAX_PAYLOAD_OFFSET_M,
                                     MAX_PAYLOAD_OFFSET_M, length=3, unit="m",
                                     why="[x, y, z] in the trunk frame")
        self.motor_strength_scale = number(s + "motor_strength_scale", motor_strength_scale, 0.0, MAX_SCALE,
                                           lo_open=True)
        self.actuator_delay_steps = integer(s + "actuator_delay_steps", actuator_delay_steps, 0,
                                            MAX_DELAY_STEPS, unit="physics steps")
        self._queue: deque[np.ndarray] = deque()
        # optional virtual obstacle under every swing foot (the paper's z(s)): clearance under mismatch
        self._profile = checked_profile(coefficients) if coefficients is not None else None

    def clearance_profile(self) -> ClearanceProfile | None:
        return self._profile

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        super().build(spec, rng)
        trunk = spec.body(a1.TRUNK_BODY)
        trunk.mass *= self.trunk_mass_scale
        trunk.inertia[:] = np.asarray(trunk.inertia) * self.trunk_mass_scale  # URDF import: fullinertia
        trunk.fullinertia[:] = np.asarray(trunk.fullinertia) * self.trunk_mass_scale
        trunk.ipos[:] = np.asarray(trunk.ipos) + self.trunk_com_shift_m
        if self.payload_mass_kg > 0.0:  # a body without joints: MuJoCo fuses it into the trunk (fusestatic)
            payload = trunk.add_body(name=PAYLOAD_BODY, pos=list(self.payload_pos_m))
            payload.explicitinertial = True
            payload.mass, payload.ipos = self.payload_mass_kg, [0.0] * 3
            payload.inertia = [0.0] * 3  # a point mass
        for i, name in enumerate(a1.JOINT_NAMES):
            joint = spec.joint(name)
            damping = np.array(joint.damping)  # MuJoCo >= 4: [linear, higher-order polynomial terms ...]
            damping[0] += self.joint_damping[i]  # the linear coefficient only: torque -d qdot
            joint.damping = damping
            joint.frictionloss += self.joint_frictionloss[i]
            joint.armature += self.armature[i]
        for act in spec.actuators:
            act.gear[0] *= self.motor_strength_scale

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        if self.actuator_delay_steps == 0:
            return
        if not self._queue:  # first call: the plant starts with the first command, then lags
            self._queue.extend(data.ctrl.copy() for _ in range(self.actuator_delay_steps))
        self._queue.append(data.ctrl.copy())
        data.ctrl[:] = self._queue.popleft()
