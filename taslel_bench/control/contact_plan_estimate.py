"""A contact plan without a gait clock: stance and swing estimated from what a real robot measures.

A learned policy has no schedule, so the safety filter's stance set and the swing-foot barrier's phase must come
from an estimate. Signals, all on a real quadruped's low-level state:

* **joint torques** (the torques applied on the previous control tick: motor currents on a real robot);
* **leg kinematics** from the **joint encoders** (each leg's foot Jacobian, :func:`leg_chain.feet_and_jacobians`);
* **IMU attitude** (the trunk's orientation, to turn a force in trunk axes into world axes).

Per leg, with the leg taken as massless and still (its own weight and acceleration neglected: a stance leg's
torques are dominated by the ground reaction), the torque balance ``tau_leg = -J_leg^T f`` gives the ground's
force on the foot ``f = -J_leg^-T tau_leg`` (trunk axes), rotated to world axes by the IMU attitude. Its vertical
part ``f_z`` [N] decides, with hysteresis and a minimum duration in each state:

* a swing foot whose ``f_z`` exceeds ``touchdown_force_n`` after at least ``min_swing_s`` in the air has landed;
* a stance foot whose ``f_z`` falls below ``liftoff_force_n`` after at least ``min_stance_s`` has lifted off.

The swing phase of a swing foot is the time since its lift-off over the policy's expected swing duration
(``swing_s``, measured on flat ground when the policy was trained), capped at 1; 0 in stance. Its rate is
``1 / swing_s``. There is no gait phase (``phi`` is NaN).

Leg order: the core's (:data:`taslel_bench.robot.quadruped.LEGS`); units: N, s, rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from taslel_bench.control.plan import ContactPlan
from taslel_bench.robot import leg_chain
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription
from taslel_bench.util.jit import kernel


@dataclass(frozen=True)
class PlanEstimateSettings:
    touchdown_force_n: float = 30.0  # [N] estimated vertical ground force above which a swing foot has landed
    liftoff_force_n: float = 12.0  # [N] below which a stance foot has lifted off
    min_stance_s: float = 0.04  # [s] a stance lasts at least this long (debounce)
    min_swing_s: float = 0.04  # [s] a swing lasts at least this long (debounce)


def quat_xyzw_to_matrix(quat_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrix (world <- trunk) of a unit quaternion (x, y, z, w) (Pinocchio's order)."""
    x, y, z, w = (float(c) for c in quat_xyzw)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])  # fmt: skip


class ContactPlanEstimate:
    """The estimated plan of one robot (module doc); :meth:`update` once per control tick."""

    def __init__(self, robot: RobotDescription, swing_s: float, control_dt_s: float,
                 settings: PlanEstimateSettings | None = None) -> None:  # fmt: skip
        self.s = settings or PlanEstimateSettings()
        if not self.s.liftoff_force_n < self.s.touchdown_force_n:
            raise ValueError(f"liftoff_force_n={self.s.liftoff_force_n} must be below touchdown_force_n="
                             f"{self.s.touchdown_force_n} [N] (the hysteresis)")
        self._table = leg_chain.chain_table(robot)
        self.swing_s = float(swing_s)
        self.dt = float(control_dt_s)
        self._min_stance = round(self.s.min_stance_s / self.dt)
        self._min_swing = round(self.s.min_swing_s / self.dt)
        self.in_stance = np.ones(quad.N_LEGS, bool)
        self.ticks_in_state = np.zeros(quad.N_LEGS, np.int64)
        self.force_z = np.zeros(quad.N_LEGS)  # [N] the last estimate of each foot's vertical ground force
        self.plan = self._plan()

    def reset(self) -> None:
        """All feet in stance (the robot starts standing)."""
        self.in_stance[:] = True
        self.ticks_in_state[:] = 0
        self.force_z[:] = 0.0
        self.plan = self._plan()

    def foot_forces_in_world(self, q_joints: np.ndarray, tau_joints: np.ndarray, quat_xyzw: np.ndarray
                             ) -> np.ndarray:  # fmt: skip
        """(4, 3) [N] the ground's force on each foot estimated from joint torques, kinematics and attitude."""
        _, jac = leg_chain.feet_and_jacobians(self._table, np.asarray(q_joints, float))
        tau = np.asarray(tau_joints, float).reshape(quad.N_LEGS, 3)
        f_trunk = np.empty((quad.N_LEGS, 3))
        for i in range(quad.N_LEGS):
            try:
                f_trunk[i] = -np.linalg.solve(jac[i].T, tau[i])
            except np.linalg.LinAlgError:  # a singular leg (straight knee): no estimate, read as unloaded
                f_trunk[i] = 0.0
        return f_trunk @ quat_xyzw_to_matrix(quat_xyzw).T

    def update(self, q_joints: np.ndarray, tau_joints: np.ndarray, quat_xyzw: np.ndarray) -> ContactPlan:
        """This tick's plan from the encoders ``q_joints`` [rad] (12,), the torques applied on the previous tick
        ``tau_joints`` [N·m] (12,) and the trunk's attitude ``quat_xyzw`` (world <- trunk)."""
        _update(self._table, np.asarray(q_joints, float), np.asarray(tau_joints, float), np.asarray(quat_xyzw, float),
                self.s.touchdown_force_n, self.s.liftoff_force_n, self._min_stance, self._min_swing, self.force_z,
                self.in_stance, self.ticks_in_state)
        self.plan = self._plan()
        return self.plan

    def _plan(self) -> ContactPlan:
        phase = np.where(self.in_stance, 0.0, np.minimum(self.ticks_in_state * self.dt / self.swing_s, 1.0))
        return ContactPlan(phi=math.nan, phi_dot=0.0, in_stance=self.in_stance.copy(), swing_phase=phase,
                           swing_phase_rate=1.0 / self.swing_s)


@kernel
def _update(table, q, tau, quat, touchdown, liftoff, min_stance, min_swing, force_z, in_stance, ticks):
    """:meth:`ContactPlanEstimate.update` compiled, in place: per leg the vertical ground force in world axes
    ``-(J^-T tau)`` rotated by the attitude (0 for a singular leg), then the hysteresis."""
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)  # world z row of R
    for i in range(4):
        row = table[i]
        pose = leg_chain.leg_pose(row, q[3 * i], q[3 * i + 1], q[3 * i + 2], np.sin, np.cos)
        jx, jy, jz = leg_chain.foot_jacobian(row, pose)  # rows of J (d p / d q_leg), trunk axes
        # f solves J^T f = -tau: column c of J^T is row c of J; Cramer's rule on the 3x3 system
        a = np.empty((3, 3))
        for c in range(3):
            a[0, c], a[1, c], a[2, c] = jx[c], jy[c], jz[c]
        det = (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]) - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
               + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))
        fz_world = 0.0
        if abs(det) > 1e-12:
            b0, b1, b2 = -tau[3 * i], -tau[3 * i + 1], -tau[3 * i + 2]
            # J^T = a^T: solve a^T f = b
            m00, m01, m02 = a[0, 0], a[1, 0], a[2, 0]
            m10, m11, m12 = a[0, 1], a[1, 1], a[2, 1]
            m20, m21, m22 = a[0, 2], a[1, 2], a[2, 2]
            f0 = (b0 * (m11 * m22 - m12 * m21) - m01 * (b1 * m22 - m12 * b2) + m02 * (b1 * m21 - m11 * b2)) / det
            f1 = (m00 * (b1 * m22 - m12 * b2) - b0 * (m10 * m22 - m12 * m20) + m02 * (m10 * b2 - b1 * m20)) / det
            f2 = (m00 * (m11 * b2 - b1 * m21) - m01 * (m10 * b2 - b1 * m20) + b0 * (m10 * m21 - m11 * m20)) / det
            fz_world = r20 * f0 + r21 * f1 + r22 * f2
        force_z[i] = fz_world
        ticks[i] += 1
        if in_stance[i]:
            if fz_world < liftoff and ticks[i] >= min_stance:
                in_stance[i] = False
                ticks[i] = 0
        elif fz_world > touchdown and ticks[i] >= min_swing:
            in_stance[i] = True
            ticks[i] = 0
