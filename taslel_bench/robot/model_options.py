"""What the controller's model believes about the robot: edits of the Pinocchio model built from a URDF.

The same quantities, with the same meanings and units, perturb the MuJoCo plant in
:class:`scenarios.perturbed.PerturbedPlant`, so a plant perturbation and the matching model setting describe
the same physics (checked against MuJoCo in ``tests/test_model_options.py``):

* ``joint_damping`` d [N·m·s/rad]: viscous joint torque -d qdot (MuJoCo ``joint.damping``), added to the URDF's
  ``<dynamics damping>`` (as the plant perturbation adds to the plant's; 0 in the A1's URDF);
* ``armature`` [kg·m²]: rotor inertia added to the joint's diagonal entry of M (MuJoCo ``joint.armature``);
* ``joint_frictionloss`` F [N·m]: Coulomb joint friction of magnitude F opposing the joint velocity, added to the
  URDF's ``<dynamics friction>`` (Go1: 0.2 N·m)
  (MuJoCo ``joint.frictionloss``, a constraint there; the model uses the smooth disturbance
  F tanh(qdot / ``frictionloss_smoothing_radps``) in h);
* ``trunk_mass_scale`` [-]: the URDF ``trunk`` link's mass and rotational inertia (about its CoM) scaled
  together; fixed links fused into the trunk (the IMU) keep theirs;
* ``trunk_com_shift_m`` [m]: the trunk link's CoM moved by this vector, trunk frame (inertia about the CoM
  unchanged);
* ``payload_mass_kg`` at ``payload_pos_m`` [m, trunk frame]: a point mass fixed to the trunk.

Joint values are one number for all 12 leg joints or 12 numbers in the core order
(:data:`taslel_bench.robot.quadruped.JOINT_NAMES`: legs FL, FR, RL, RR; hip, thigh, calf).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from taslel_bench.robot import quadruped as quad

JointValue = float | Sequence[float]
ROOT_JOINT = 1  # Pinocchio index of the free flyer (0 is the universe)


@dataclass(frozen=True)
class ModelOptions:
    """The controller's model; the defaults are the URDF as is (see module doc for meanings and units)."""

    urdf: str | None = None  # None: the robot's URDF (the file the default plant is built from)
    joint_damping: JointValue = 0.0  # [N·m·s/rad]
    armature: JointValue = 0.0  # [kg·m²]
    joint_frictionloss: JointValue = 0.0  # [N·m]
    frictionloss_smoothing_radps: float = 0.05  # [rad/s] v_eps of F tanh(qdot / v_eps)
    trunk_mass_scale: float = 1.0  # [-]
    trunk_com_shift_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # [m] trunk frame
    payload_mass_kg: float = 0.0  # [kg]
    payload_pos_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # [m] trunk frame
    # [s] the discrete model of a simulator that integrates joint damping implicitly (MuJoCo's Euler,
    # implicit and implicitfast: v+ = v + dt (M + dt D)^-1 f): dt d is added to the joints' diagonal of M
    # with the damping; 0 = the continuous model
    implicit_damping_dt_s: float = 0.0

    def per_joint(self, name: str) -> np.ndarray:
        """The joint field ``name`` as 12 values in the core joint order."""
        return joint_vector(getattr(self, name), name)

    @property
    def edits_trunk(self) -> bool:
        """True when the trunk's inertia differs from the URDF's."""
        return self.trunk_mass_scale != 1.0 or any(self.trunk_com_shift_m) or self.payload_mass_kg != 0.0


def joint_vector(value: JointValue, name: str = "value") -> np.ndarray:
    """One number -> 12 equal values; 12 numbers -> them (core joint order); anything else raises."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(quad.N_JOINTS, float(arr))
    if arr.shape != (quad.N_JOINTS,):
        raise ValueError(f"{name}: one number or {quad.N_JOINTS} numbers (core joint order), got {value!r}")
    return arr.copy()


def trunk_link_inertia(model: pin.Model, trunk_link: str) -> tuple[pin.SE3, pin.Inertia]:
    """(placement of the trunk link's frame in the free flyer's frame, the trunk link's own inertia in its
    frame): the URDF ``trunk`` link alone, without the links fused into the free-flyer body (IMU, a massless
    root ``base``). With a root ``base`` link, Pinocchio keeps the trunk's inertia on the fixed joint that
    attaches it; when ``trunk`` is the root link, its inertia is the body's minus every fused fixed link's."""
    body = model.frames[model.getFrameId(trunk_link, pin.FrameType.BODY)]
    parent = model.frames[body.parentFrame]
    if parent.type == pin.FrameType.FIXED_JOINT:
        return parent.placement, parent.inertia
    params = model.inertias[ROOT_JOINT].toDynamicParameters()
    for f in model.frames:
        if f.parentJoint == ROOT_JOINT and f.type == pin.FrameType.FIXED_JOINT:
            params = params - f.placement.act(f.inertia).toDynamicParameters()
    return body.placement, body.placement.actInv(pin.Inertia.FromDynamicParameters(params))


def edit_trunk(model: pin.Model, options: ModelOptions, trunk_link: str) -> None:
    """Replace the trunk link's share of the free-flyer body's inertia by the scaled and shifted one and add
    the payload point mass (in place). Inertias add as their 10 dynamic parameters (mass, first moment,
    inertia about the frame origin), which are linear in the edits."""
    placement, own = trunk_link_inertia(model, trunk_link)
    s = options.trunk_mass_scale
    edited = pin.Inertia(
        own.mass * s, own.lever + np.asarray(options.trunk_com_shift_m, float), own.inertia * s
    )
    payload = pin.Inertia(options.payload_mass_kg, np.asarray(options.payload_pos_m, float), np.zeros((3, 3)))
    params = (
        model.inertias[ROOT_JOINT].toDynamicParameters()
        - placement.act(own).toDynamicParameters()
        + placement.act(edited).toDynamicParameters()
        + placement.act(payload).toDynamicParameters()
    )
    model.inertias[ROOT_JOINT] = pin.Inertia.FromDynamicParameters(params)


def apply(model: pin.Model, options: ModelOptions, trunk_link: str) -> None:
    """All edits of ``options`` on a freshly built Pinocchio model (joints in core order after the free
    flyer). Armature goes into Pinocchio's ``model.armature`` (its CRBA adds it to the diagonal of M);
    damping and friction, the URDF's ``<dynamics>`` plus the options' (as MuJoCo reads the URDF's into the plant
    and a plant perturbation adds to them), are stored in ``model.damping`` / ``model.friction`` (Pinocchio's ``nle``
    ignores them: :class:`taslel_bench.robot.model.RobotModel` adds them to h)."""
    if options.edits_trunk:
        edit_trunk(model, options, trunk_link)
    for attr, field in (("damping", "joint_damping"), ("friction", "joint_frictionloss")):
        values = np.array(getattr(model, attr))  # (nv,) a copy: assign the whole vector back
        values[6:] = values[6:] + options.per_joint(field)  # the URDF's (0 on the A1) plus the options'
        setattr(model, attr, values)
    armature = np.array(model.armature)
    armature[6:] = options.per_joint("armature")
    # implicit damping: (M + dt D) vdot + D v = f, dt D on the joint diagonal
    armature[6:] += options.implicit_damping_dt_s * np.array(model.damping)[6:]
    model.armature = armature
