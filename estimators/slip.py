"""Per-foot slip detection from proprioception: leg kinematics, joint torques and the trunk IMU.

What a real A1 measures is enough (:class:`taslel_bench.interfaces.Proprioception` with its ``imu``): no
plant contact flag, no true velocity. Every control tick:

1. **Leg kinematics** (the robot's chain, :mod:`taslel_bench.robot.leg_chain`; default the A1's,
   :data:`estimators.legs.TRAINED_ROBOT`): each foot's position ``p_i`` and velocity ``J_i qd_i`` relative to the
   trunk, trunk axes; the ground force the joint torques balance, ``f_i = -J_i^-T tau_i``
   (quasi-static leg), rotated to world axes by the IMU attitude ``R``. A foot is *loaded* when that force's
   world-z component exceeds ``contact_force_n``.
2. **Trunk velocity** (:class:`TrunkVelocityObserver`, world axes): the accelerometer integrated
   (``v += dt (R a + g)``), pulled towards the leg odometry of the loaded feet that hold -- past their
   landing (``touchdown_s``), not slipping, and not more than 4 x ``speed_mps`` off the prediction this
   tick -- (``-R (omega x p_i + J_i qd_i)``, their median) with time constant ``velocity_tau_s``.
3. **Foot velocity in the world**: ``v_i = v_trunk + R (omega x p_i + J_i qd_i)``. A loaded foot *slips*
   when either rule fires:

   * slow (mild, sustained slips; ``slow``): its horizontal speed averaged over its last ``average_ticks`` ticks
     exceeds ``speed_mps`` for ``confirm_ticks`` consecutive ticks, after the first ``touchdown_s`` of its
     stance (the landing transient, which slides on any floor; the average starts after it);
   * fast (a foot sliding away as it lands): its speed exceeds ``fast_speed_mps`` on ``fast_confirm_ticks``
     consecutive ticks after the first ``fast_touchdown_s`` of its stance.

Each loaded foot's torque-implied force ratio ``|f_xy| / f_z`` is reported (``ratio``): while a foot slides,
the ground's force ratio equals the friction coefficient, but through a quasi-static leg it reads high
(median 0.25-0.34 on a 0.2 floor, ``studies/notes/estimators/round8.md``), so :mod:`estimators.slip_bound`
uses it only behind a scale < 1, or not at all.

Frames: ``_b`` trunk axes, ``_w`` world axes (z up). Units: m, m/s, N, s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators import legs, slip_kernel
from taslel_bench import api
from taslel_bench.api import RobotDescription, leg_chain
from taslel_bench.interfaces import ImuSample, Proprioception, integer, number


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
    # subtract the legs' own weight (URDF link masses, trunk attitude from the IMU) from the joint torques before
    # the quasi-static force: the ratio's median error on support ticks of flat floors +0.044..+0.053 ->
    # +0.005..+0.010, p90 0.07-0.08 -> 0.024-0.034 (studies/estimator_probe_signal.py); off: the detector without it
    leg_gravity: bool = False

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
    """State of the trunk velocity observer (module doc, step 2; updated by :func:`estimators.slip_kernel.tick`):
    velocity [m/s] and dead-reckoned position [m] in world axes (origin: where it started)."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = float(tau_s)  # [s] leg-odometry correction time constant
        self.reset()

    def reset(self) -> None:
        self.v_w = np.zeros(3)  # [m/s]
        self.p_w = np.zeros(3)  # [m]
        self.started = False  # set by the first tick with holding feet


@dataclass
class FootState:
    """One tick of :class:`SlipDetector`'s output, LEGS order."""

    loaded: np.ndarray  # (4,) bool: torque-implied normal force above the threshold
    slipping: np.ndarray  # (4,) bool: confirmed slip this tick
    speed_mps: np.ndarray  # (4,) [m/s] horizontal foot speed in the world (this tick)
    ratio: np.ndarray  # (4,) [-] torque-implied |f_xy| / f_z (nan unloaded)
    feet_w: np.ndarray  # (4, 3) [m] foot positions, world axes, dead-reckoned (origin: the episode start)
    heading_w: np.ndarray  # (2,) unit horizontal direction of travel (world), (1, 0) at rest


class LegGravity:
    """Joint torques [N·m] (12, core order) that hold the legs' own links against gravity at joint angles q and
    trunk attitude ``quat_wxyz`` (the robot URDF's link masses, Pinocchio's generalized gravity, its joint rows;
    None: the A1, :data:`estimators.legs.TRAINED_ROBOT`)."""

    def __init__(self, robot: RobotDescription | None = None) -> None:
        import pinocchio as pin

        self._pin = pin
        robot = robot if robot is not None else api.load_robot(legs.TRAINED_ROBOT)
        self.model = pin.buildModelFromUrdf(str(robot.urdf_path), pin.JointModelFreeFlyer())
        self.data = self.model.createData()
        self._q = np.zeros(self.model.nq)

    def torques(self, q_joints: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
        w, x, y, z = quat_wxyz
        self._q[3:7] = (x, y, z, w)
        self._q[7:] = q_joints
        return self._pin.computeGeneralizedGravity(self.model, self.data, self._q)[6:]


class SlipDetector:
    """Per-foot slip from proprioception (module doc). Call :meth:`step` every control tick; the arithmetic
    runs in :func:`estimators.slip_kernel.tick`. ``robot``: whose legs (None: the A1,
    :data:`estimators.legs.TRAINED_ROBOT`)."""

    def __init__(self, settings: SlipSettings | None = None, robot: RobotDescription | None = None) -> None:
        self.s = settings if settings is not None else SlipSettings()
        self.velocity = TrunkVelocityObserver(self.s.velocity_tau_s)
        s = self.s
        self._gravity = LegGravity(robot) if s.leg_gravity else None
        self._chain = legs.chain_table(robot)
        self._feet_b = np.zeros((4, 3))  # [m] this tick's foot positions, trunk axes
        self._jac = np.zeros((4, 3, 3))  # [m/rad] this tick's leg Jacobians, trunk axes
        self._prm = np.zeros(slip_kernel.N_PARAMS)
        self._prm[[slip_kernel.P_CONTACT, slip_kernel.P_TOUCHDOWN, slip_kernel.P_SPEED, slip_kernel.P_AVERAGE,
                   slip_kernel.P_CONFIRM, slip_kernel.P_FAST_TOUCHDOWN, slip_kernel.P_FAST_SPEED,
                   slip_kernel.P_FAST_CONFIRM, slip_kernel.P_TAU, slip_kernel.P_SLOW]] = (
            s.contact_force_n, s.touchdown_s, s.speed_mps, s.average_ticks, s.confirm_ticks, s.fast_touchdown_s,
            s.fast_speed_mps, s.fast_confirm_ticks, s.velocity_tau_s, float(bool(s.slow)))
        self.reset()

    def reset(self) -> None:
        self.velocity.reset()
        self._t_prev: float | None = None
        self._loaded_since = np.full(4, np.inf)  # [s] start of each foot's current stance (inf: unloaded)
        self._above = np.zeros(4, np.int64)  # consecutive ticks the mean speed was above the slip speed
        self._above_fast = np.zeros(4, np.int64)  # consecutive ticks above the fast rule's speed
        self._speeds = np.zeros((self.s.average_ticks, 4))  # [m/s] ring of the judged ticks' speeds
        self._judged = np.zeros(4, np.int64)  # judged ticks of each foot's current stance
        self._heading = np.array([1.0, 0.0])

    def step(self, obs: Proprioception) -> FootState:
        """This tick's feet (needs ``obs.imu``)."""
        imu: ImuSample | None = obs.imu
        if imu is None:
            raise ValueError("SlipDetector needs the trunk IMU (Proprioception.imu)")
        dt = 0.0 if self._t_prev is None else obs.t_s - self._t_prev
        self._t_prev = obs.t_s
        out = FootState(np.zeros(4, bool), np.zeros(4, bool), np.zeros(4), np.zeros(4), np.zeros((4, 3)),
                        self._heading)
        v = self.velocity
        tau = np.asarray(obs.tau_joints, float)
        if self._gravity is not None:
            tau = tau - self._gravity.torques(obs.q_joints, imu.quat_wxyz)
        leg_chain.feet_and_jacobians_into(self._chain, np.asarray(obs.q_joints, float), self._feet_b, self._jac)
        v.started = slip_kernel.tick(
            self._feet_b, self._jac, np.asarray(obs.qd_joints, float), tau,
            np.asarray(imu.quat_wxyz, float), np.asarray(imu.gyro_in_base, float),
            np.asarray(imu.accel_in_base, float), float(obs.t_s), float(dt), self._prm, v.started, v.v_w, v.p_w,
            self._heading, self._loaded_since, self._judged, self._speeds, self._above, self._above_fast,
            out.loaded, out.slipping, out.speed_mps, out.ratio, out.feet_w)
        out.heading_w = self._heading.copy()
        return out
