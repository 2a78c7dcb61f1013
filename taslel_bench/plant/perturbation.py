"""One vocabulary for how the MuJoCo plant differs from the robot's URDF, and one implementation of each edit.

:class:`PlantPerturbation` is what ``scenario=perturbed``/``payload`` configure, what the estimators' domain
randomisation draws per episode, and -- with the same field names, meanings and units -- what the ``model``
config group tells the controller's model (:class:`taslel_bench.robot.model_options.ModelOptions`), so a
perturbation the model knows is ``scenario.joint_damping=1.5 model.joint_damping=1.5``. All edits act on the
plant's ``MjSpec`` before it is compiled (:meth:`PlantPerturbation.apply`); the actuator delay acts on the
commands during the run (:class:`ActuatorDelay`).

Fields (1.0 / 0 = unchanged): ``trunk_mass_scale`` [-] (the trunk link's mass and inertia about its CoM
scaled together), ``trunk_com_shift_m`` [m, trunk frame], ``payload_mass_kg`` [kg] at ``payload_pos_m``
[m, trunk frame] (a point mass fixed to the trunk), ``joint_damping`` [N·m·s/rad], ``armature`` [kg·m²] and
``joint_frictionloss`` [N·m] added to the leg joints (one number for all 12 or 12 in the core joint order),
``motor_strength_scale`` [-] (torque delivered per commanded N·m), ``actuator_delay_steps`` [physics steps].
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, fields

import mujoco
import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.fields import integer, number, number_or_list, numbers

MAX_SCALE = 10.0  # [-] mass and motor-strength factors
MAX_COM_SHIFT_M = 0.2  # [m] per axis (the trunk is 0.27 x 0.19 x 0.11 m)
MAX_JOINT_DAMPING = 10.0  # [N·m·s/rad]
MAX_JOINT_FRICTIONLOSS_NM = 10.0  # [N·m]
MAX_ARMATURE_KGM2 = 1.0  # [kg·m²] (real leg rotors reflect ~0.005-0.05 through their gearbox)
MAX_PAYLOAD_KG = 50.0  # [kg] (the A1 weighs 13.7 kg)
MAX_PAYLOAD_OFFSET_M = 0.5  # [m] per axis, trunk frame
MAX_DELAY_STEPS = 1000  # [physics steps]
PAYLOAD_BODY = "payload"
JOINT_RULE = "one number for all 12 joints or 12 in the core order (legs FL, FR, RL, RR)"
Vector3 = tuple[float, float, float]
JointValues = tuple[float, ...]  # 12 values, core joint order


def check_trunk_and_joints(prefix: str, values: dict) -> dict:
    """The fields the plant and the controller's model share, checked and normalised (joint values as 12-tuples);
    a bad value raises naming ``<prefix>.<field>``. Fields absent from ``values`` are not returned."""
    p, n, out = f"{prefix}.", quad.N_JOINTS, {}
    rules = {
        "trunk_mass_scale": lambda v: number(p + "trunk_mass_scale", v, 0.0, MAX_SCALE, lo_open=True),
        "trunk_com_shift_m": lambda v: numbers(p + "trunk_com_shift_m", v, -MAX_COM_SHIFT_M, MAX_COM_SHIFT_M,
                                               length=3, unit="m", why="[x, y, z] in the trunk frame"),
        "payload_mass_kg": lambda v: number(p + "payload_mass_kg", v, 0.0, MAX_PAYLOAD_KG, unit="kg"),
        "payload_pos_m": lambda v: numbers(p + "payload_pos_m", v, -MAX_PAYLOAD_OFFSET_M, MAX_PAYLOAD_OFFSET_M,
                                           length=3, unit="m", why="[x, y, z] in the trunk frame"),
        "joint_damping": lambda v: number_or_list(p + "joint_damping", v, 0.0, MAX_JOINT_DAMPING, length=n,
                                                  unit="N·m·s/rad", why=JOINT_RULE),
        "armature": lambda v: number_or_list(p + "armature", v, 0.0, MAX_ARMATURE_KGM2, length=n, unit="kg·m²",
                                             why=JOINT_RULE),
        "joint_frictionloss": lambda v: number_or_list(p + "joint_frictionloss", v, 0.0,
                                                       MAX_JOINT_FRICTIONLOSS_NM, length=n, unit="N·m",
                                                       why=JOINT_RULE),
    }
    for key, rule in rules.items():
        if key in values:
            out[key] = rule(values[key])
    return out


@dataclass(frozen=True)
class PlantPerturbation:
    trunk_mass_scale: float = 1.0
    trunk_com_shift_m: Vector3 = (0.0, 0.0, 0.0)
    payload_mass_kg: float = 0.0
    payload_pos_m: Vector3 = (0.0, 0.0, 0.0)
    joint_damping: JointValues = (0.0,) * quad.N_JOINTS
    armature: JointValues = (0.0,) * quad.N_JOINTS
    joint_frictionloss: JointValues = (0.0,) * quad.N_JOINTS
    motor_strength_scale: float = 1.0
    actuator_delay_steps: int = 0

    @classmethod
    def checked(cls, prefix: str, **values) -> PlantPerturbation:
        """From config values (joint fields: one number or 12), each checked; errors name ``<prefix>.<field>``."""
        valid = [f.name for f in fields(cls)]
        if unknown := sorted(set(values) - set(valid)):
            raise ValueError(f"{prefix}.{unknown[0]}: unknown perturbation field; valid: {', '.join(valid)}")
        out = check_trunk_and_joints(prefix, values)
        if "motor_strength_scale" in values:
            out["motor_strength_scale"] = number(f"{prefix}.motor_strength_scale", values["motor_strength_scale"],
                                                 0.0, MAX_SCALE, lo_open=True)
        if "actuator_delay_steps" in values:
            out["actuator_delay_steps"] = integer(f"{prefix}.actuator_delay_steps", values["actuator_delay_steps"],
                                                  0, MAX_DELAY_STEPS, unit="physics steps")
        return cls(**out)

    def apply(self, spec: mujoco.MjSpec) -> None:
        """Edit the plant spec (before compiling): trunk mass, inertia and CoM, the payload body, the leg
        joints' damping, friction loss and armature, the actuators' gear."""
        trunk = spec.body(quad.TRUNK_BODY)
        trunk.mass *= self.trunk_mass_scale
        trunk.inertia[:] = np.asarray(trunk.inertia) * self.trunk_mass_scale  # URDF import: fullinertia
        trunk.fullinertia[:] = np.asarray(trunk.fullinertia) * self.trunk_mass_scale
        trunk.ipos[:] = np.asarray(trunk.ipos) + np.asarray(self.trunk_com_shift_m)
        if self.payload_mass_kg > 0.0:  # a body without joints: MuJoCo fuses it into the trunk (fusestatic)
            payload = trunk.add_body(name=PAYLOAD_BODY, pos=list(self.payload_pos_m))
            payload.explicitinertial = True
            payload.mass, payload.ipos = self.payload_mass_kg, [0.0] * 3
            payload.inertia = [0.0] * 3  # a point mass
        for i, name in enumerate(quad.JOINT_NAMES):
            joint = spec.joint(name)
            damping = np.array(joint.damping)  # MuJoCo >= 4: [linear, higher-order polynomial terms ...]
            damping[0] += self.joint_damping[i]  # the linear coefficient only: torque -d qdot
            joint.damping = damping
            joint.frictionloss += self.joint_frictionloss[i]
            joint.armature += self.armature[i]
        for act in spec.actuators:
            act.gear[0] *= self.motor_strength_scale


class ActuatorDelay:
    """Commands reach the plant ``steps`` physics steps late: call :meth:`apply` before every ``mj_step``
    (the plant starts with the first command, then lags)."""

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self._queue: deque[np.ndarray] = deque()

    def reset(self) -> None:
        self._queue.clear()

    def apply(self, data: mujoco.MjData) -> None:
        if self.steps == 0:
            return
        if not self._queue:
            self._queue.extend(data.ctrl.copy() for _ in range(self.steps))
        self._queue.append(data.ctrl.copy())
        data.ctrl[:] = self._queue.popleft()


def as_joint_values(value: float | Sequence[float]) -> JointValues:
    """One number for every leg joint, or 12 in the core order, as 12 values."""
    if isinstance(value, (int, float)):
        return (float(value),) * quad.N_JOINTS
    return tuple(float(v) for v in value)
