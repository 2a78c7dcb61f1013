"""Per-foot slip detection from proprioception: leg kinematics, joint torques and the trunk IMU.

What a real A1 measures is enough (:class:`taslel_bench.interfaces.Proprioception` with its ``imu``): no
plant contact flag, no true velocity. Every control tick:

1. **Leg kinematics** (:mod:`estimators.legs`): each foot's position ``p_i`` and velocity ``J_i qd_i``
   relative to the trunk, trunk axes; the ground force the joint torques balance, ``f_i = -J_i^-T tau_i``
   (quasi-static leg), rotated to world axes by the IMU attitude ``R``. A foot is *loaded* when that force's
   world-z component exceeds ``contact_force_n``.
2. **Trunk velocity** (:class:`TrunkVelocityObserver`, world axes): the accelerometer integrated
   (``v += dt (R a + g)``), pulled towards the leg odometry of the loaded feet that hold
   (``-R (omega x p_i + J_i qd_i)``, their median) with time constant ``velocity_tau_s``; a foot whose
   velocity this tick is more than 4 x ``speed_mps`` off the prediction is left out.
3. **Foot velocity in the world**: ``v_i = v_trunk + R (omega x p_i + J_i qd_i)``. A loaded foot *slips*
   when either rule fires:

   * slow (mild, sustained slips; ``slow``): its horizontal speed averaged over its last ``average_ticks`` ticks
     exceeds ``speed_mps`` for ``confirm_ticks`` consecutive ticks, after the first ``touchdown_s`` of its
     stance (the landing transient, which slides on any floor; the average starts after it);
   * fast (a foot sliding away as it lands): its speed exceeds ``fast_speed_mps`` on ``fast_confirm_ticks``
     consecutive ticks after the first ``fast_touchdown_s`` of its stance.

The slipping feet's torque-implied force ratio ``|f_xy| / f_z`` during the slip is kept (``ratio``): while a
foot slides, the ground's force ratio equals the friction coefficient, so it measures mu (the quasi-static
leg makes it noisy: :mod:`estimators.slip_bound` uses it only through a robust statistic).

Frames: ``_b`` trunk axes, ``_w`` world axes (z up). Units: m, m/s, N, s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.legs import feet_and_jacobians, foot_forces_from_torques
from taslel_bench.interfaces import ImuSample, Proprioception, integer, number

GRAVITY_W = np.array([0.0, 0.0, -9.81])  # [m/s²] world axes


def quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    """World <- trunk rotation (3, 3) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@dataclass
class SlipSettings:
    """Thresholds of :class:`SlipDetector` (chosen on validation worlds: ``studies/notes/estimators/round8.md``)."""

    contact_force_n: float = 20.0  # [N] torque-implied normal force of a loaded foot
    slow: bool = True  # the slow rule on (off: the fast rule only)
    touchdown_s: float = 0.03  # [s] start of a stance not judged (landing transient)
    speed_mps: float = 0.065  # [m/s] mean horizontal foot speed of a slip (world)
    average_ticks: int = 10  # ticks of the mean (a full window of judged ticks is needed)
    confirm_ticks: int = 1  # consecutive ticks above the speed
    fast_touchdown_s: float = 0.01  # [s] fast rule: start of a stance not judged
    fast_speed_mps: float = 0.25  # [m/s] fast rule: horizontal foot speed of a slip (world)
    fast_confirm_ticks: int = 3  # fast rule: consecutive ticks above it
    velocity_tau_s: float = 0.1  # [s] leg-odometry correction time constant of the trunk velocity

    def __post_init__(self) -> None:
        number("estimator.slip.contact_force_n", self.contact_force_n, 0.0, 500.0, lo_open=True, unit="N")
        number("estimator.slip.touchdown_s", self.touchdown_s, 0.0, 0.5, unit="s")
        number("estimator.slip.speed_mps", self.speed_mps, 0.0, 10.0, lo_open=True, unit="m/s")
        integer("estimator.slip.average_ticks", self.average_ticks, 1)
        integer("estimator.slip.confirm_ticks", self.confirm_ticks, 1)
        number("estimator.slip.fast_touchdown_s", self.fast_touchdown_s, 0.0, 0.5, unit="s")
        number("estimator.slip.fast_speed_mps", self.fast_speed_mps, 0.0, 10.0, lo_open=True, unit="m/s")
        integer("estimator.slip.fast_confirm_ticks", self.fast_confirm_ticks, 1)
        number("estimator.slip.velocity_tau_s", self.velocity_tau_s, 0.0, 10.0, lo_open=True, unit="s")


class TrunkVelocityObserver:
    """Trunk velocity [m/s] and position [m] in world axes from the IMU and the holding feet's odometry."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = float(tau_s)
        self.reset()

    def reset(self) -> None:
        self.v_w = np.zeros(3)  # [m/s]
        self.p_w = np.zeros(3)  # [m] dead reckoning from the start of the episode (origin: the start)
        self.started = False

    def predict(self, rot_w_b: np.ndarray, accel_b: np.ndarray, dt: float) -> None:
        """Integrate the accelerometer's specific force [m/s²] over ``dt`` [s]."""
        if self.started:
            self.v_w += dt * (rot_w_b @ accel_b + GRAVITY_W)
            self.p_w += dt * self.v_w

    def correct(self, odometry_w: np.ndarray, holding: np.ndarray, dt: float) -> None:
        """Pull the velocity towards the odometry (4, 3) [m/s] of the ``holding`` feet (their median: one
        slipping foot among three or four is outvoted; none: no pull); the first call with holding feet sets
        it."""
        if not holding.any():
            return
        v_odo = np.median(odometry_w[holding], axis=0)
        if not self.started:
            self.v_w[:], self.started = v_odo, True
            return
        self.v_w += min(1.0, dt / self.tau_s) * (v_odo - self.v_w)


@dataclass
class FootState:
    """One tick of :class:`SlipDetector`'s output, LEGS order."""

    loaded: np.ndarray  # (4,) bool: torque-implied normal force above the threshold
    slipping: np.ndarray  # (4,) bool: confirmed slip this tick
    speed_mps: np.ndarray  # (4,) [m/s] horizontal foot speed in the world (this tick)
    ratio: np.ndarray  # (4,) [-] torque-implied |f_xy| / f_z (nan unloaded)
    feet_w: np.ndarray  # (4, 3) [m] foot positions, world axes, dead-reckoned (origin: the episode start)
    heading_w: np.ndarray  # (2,) unit horizontal direction of travel (world), (1, 0) at rest


class SlipDetector:
    """Per-foot slip from proprioception (module doc). Call :meth:`step` every control tick."""

    def __init__(self, settings: SlipSettings | None = None) -> None:
        self.s = settings if settings is not None else SlipSettings()
        self.velocity = TrunkVelocityObserver(self.s.velocity_tau_s)
        self.reset()

    def reset(self) -> None:
        self.velocity.reset()
        self._t_prev: float | None = None
        self._loaded_since = np.full(4, np.inf)  # [s] start of each foot's current stance (inf: unloaded)
        self._above = np.zeros(4, int)  # consecutive ticks the mean speed was above the slip speed
        self._above_fast = np.zeros(4, int)  # consecutive ticks above the fast rule's speed
        self._speeds = np.zeros((self.s.average_ticks, 4))  # [m/s] ring of the judged ticks' speeds
        self._judged = np.zeros(4, int)  # judged ticks of each foot's current stance
        self._slipping = np.zeros(4, bool)
        self._heading = np.array([1.0, 0.0])

    def step(self, obs: Proprioception) -> FootState:
        """This tick's feet (needs ``obs.imu``)."""
        imu: ImuSample | None = obs.imu
        if imu is None:
            raise ValueError("SlipDetector needs the trunk IMU (Proprioception.imu)")
        dt = 0.0 if self._t_prev is None else obs.t_s - self._t_prev
        self._t_prev = obs.t_s
        rot = quat_wxyz_to_matrix(np.asarray(imu.quat_wxyz, float))
        p_b, jac = feet_and_jacobians(obs.q_joints)
        vrel_b = np.cross(imu.gyro_in_base, p_b) + np.einsum("lij,lj->li", jac, np.reshape(obs.qd_joints, (4, 3)))
        f_w = foot_forces_from_torques(jac, obs.tau_joints) @ rot.T
        loaded = f_w[:, 2] > self.s.contact_force_n
        ratio = np.where(loaded, np.hypot(f_w[:, 0], f_w[:, 1]) / np.maximum(f_w[:, 2], 1e-9), np.nan)
        self.velocity.predict(rot, np.asarray(imu.accel_in_base, float), dt)
        vrel_w = vrel_b @ rot.T
        speed = np.hypot(*(self.velocity.v_w[:2] + vrel_w[:, :2]).T) if self.velocity.started else np.zeros(4)
        self._loaded_since = np.where(loaded, np.minimum(self._loaded_since, obs.t_s), np.inf)
        judged = loaded & (obs.t_s - self._loaded_since >= self.s.touchdown_s - 1e-9)
        self._judged = np.where(judged, self._judged + 1, 0)
        idx = np.flatnonzero(judged)
        self._speeds[(self._judged[idx] - 1) % self.s.average_ticks, idx] = speed[idx]
        mean = self._speeds.mean(axis=0)
        fast = (self._judged >= self.s.average_ticks) & (mean > self.s.speed_mps) & bool(self.s.slow)
        self._above = np.where(fast, self._above + 1, 0)
        quick = loaded & (obs.t_s - self._loaded_since >= self.s.fast_touchdown_s - 1e-9) & \
            (speed > self.s.fast_speed_mps)
        self._above_fast = np.where(quick, self._above_fast + 1, 0)
        self._slipping = (self._above >= self.s.confirm_ticks) | (self._above_fast >= self.s.fast_confirm_ticks)
        # odometry from the feet that hold: judged (past the landing), no slip, not fast this tick
        self.velocity.correct(-vrel_w, judged & ~fast & (speed < 4 * self.s.speed_mps), dt)
        v_xy = self.velocity.v_w[:2]
        if np.hypot(*v_xy) > 0.05:  # [m/s] below that the heading keeps its last value
            self._heading = v_xy / np.hypot(*v_xy)
        feet_w = self.velocity.p_w + p_b @ rot.T
        return FootState(loaded, self._slipping.copy(), speed, ratio, feet_w, self._heading.copy())
