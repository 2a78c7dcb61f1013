"""What every nominal controller gives the rest of a run: joint torques and its *contact plan*.

The safety filter, the contact estimate, the metrics and the recordings read the plan the controller produced at
each tick (recorded in the trace), never the controller's configuration. A controller with a gait clock (the trot)
plans stance and swing from it; one without a clock (a learned policy) plans them from a contact estimate
(:mod:`taslel_bench.control.contact_plan_estimate`).

Arrays are in the core's leg order (:data:`taslel_bench.robot.quadruped.LEGS`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from taslel_bench.robot.description import RobotDescription


@dataclass
class ContactPlan:
    """The controller's plan at one instant."""

    phi: float  # [-] gait phase in [0, 1) (nan for a controller without a gait clock)
    phi_dot: float  # [1/s] its rate
    in_stance: np.ndarray  # bool (4,): the stance set the controller plans
    swing_phase: np.ndarray  # [-] (4,) progress of each swing in [0, 1]; 0 for stance legs (the ECBF's phase)
    swing_phase_rate: float  # [1/s] d(swing_phase)/dt during swing


@runtime_checkable
class NominalControl(Protocol):
    """A nominal controller as the episode uses it (the trot: :class:`taslel_bench.control.nominal.NominalController`).

    ``compute`` gets the episode time [s], the joint angles [rad] and velocities [rad/s] in core order, the
    trunk pose (position [m], quaternion xyzw; Pinocchio's), the trunk velocity (Pinocchio's: linear [m/s] and
    angular [rad/s], trunk axes) and the torques applied on the previous tick [N·m], and returns the nominal torques
    [N·m] (12,). It is called before :meth:`contact_plan` of the same tick."""

    robot: RobotDescription
    stand_duration_s: float  # [s] the initial stand before walking

    @property
    def stand_height_m(self) -> float: ...  # [m] hip joint -> foot centre in the stand configuration

    @property
    def commanded_speed_mps(self) -> float: ...  # [m/s] the forward speed it is asked for (0: standing)

    @property
    def stance_swing_s(self) -> tuple[float, float]: ...  # [s] the stance and swing durations it plans (or expects)

    def compute(self, t: float, q_joints: np.ndarray, qd_joints: np.ndarray, base_pose: np.ndarray | None = None,
                base_velocity: np.ndarray | None = None, tau_applied: np.ndarray | None = None) -> np.ndarray: ...

    def contact_plan(self, t: float) -> ContactPlan: ...

    def stand_configuration(self) -> np.ndarray: ...

    def reset(self) -> None: ...


def compute_of(controller: NominalControl) -> Callable[..., np.ndarray]:
    """``controller.compute`` called with the six arguments of :class:`NominalControl` (time, joint angles and
    rates, trunk pose, trunk velocity, torques applied on the previous tick). A controller written for the first
    four only (``compute(t, q_joints, qd_joints, base_pose=None)``) is called with those: it keeps working."""
    compute = controller.compute
    params = inspect.signature(compute).parameters.values()
    if any(p.kind is inspect.Parameter.VAR_POSITIONAL for p in params) or len(params) >= 6:
        return compute
    return lambda t, q_joints, qd_joints, base_pose=None, base_velocity=None, tau_applied=None: compute(
        t, q_joints, qd_joints, base_pose)
