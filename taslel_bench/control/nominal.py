"""Nominal controller (paper, "Quadruped Implementation"): trot, open-loop feet, analytic IK, joint PD, for any
described robot (the IK from :class:`taslel_bench.robot.kinematics.LegKinematics`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taslel_bench.control.gait import GaitParams, TrotGait
from taslel_bench.control.plan import ContactPlan
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription, default_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.util.jit import kernel


@dataclass(frozen=True)
class PDGains:
    kp: float = 100.0  # [N·m/rad]
    kd: float = 3.0  # [N·m·s/rad]


class NominalController:
    """``u_nom = Kp (q_des - q) + Kd (qdot_des - qdot)``, clipped to the torque limit.

    ``q_des`` comes from IK of the gait's foot targets; ``qdot_des`` is its time derivative by a central
    difference over ``fd_dt_s`` (the IK is smooth within a gait phase). Set ``fd_dt_s`` to the control
    period: the IK at t + h is then reused as the IK at t - h of the next tick.

    The references are open loop and periodic in the gait time (period T). When T and the walking start
    are whole numbers of ``fd_dt_s`` (the default 0.4 s and 0.5 s at 1 kHz), the references of each tick of
    the first period are kept in a table and looked up afterwards: the tick then costs only the PD law.
    Looked-up values equal a fresh computation to float rounding (tested).
    """

    def __init__(
        self,
        gait: GaitParams,
        gains: PDGains,
        stand_duration_s: float = 0.5,
        fd_dt_s: float = 1e-3,
        robot: RobotDescription | None = None,
    ) -> None:
        """``robot``: whose legs (None: the default robot); its torque limits clip the PD law."""
        self.robot = robot = robot if robot is not None else default_robot()
        self.kinematics = LegKinematics(robot)
        self._legs_ik_list = self.kinematics.legs_ik_list
        self.gait = TrotGait(gait, self.kinematics.lateral_offsets_m())
        self.gains = gains
        self._kp, self._kd = float(gains.kp), float(gains.kd)  # [N·m/rad], [N·m·s/rad] read every tick
        self.stand_duration_s = stand_duration_s
        self.torque_limit_nm = robot.torque_limits  # [N·m] (12,) core order
        self.fd_dt_s = fd_dt_s
        # (q_des [rad], qd_des [rad/s]) in one array: a table row is copied in one operation; the two are its
        # rows (views: write them in place, never rebind them)
        self._references = np.zeros((2, quad.N_JOINTS))
        self.q_des, self.qd_des = self._references
        self._cache_t: float = float("nan")
        self._cache_list: list[float] = []
        # per-period reference table (see class doc): row j = (q_des, qd_des) at gait time j * fd_dt_s
        n_period = gait.period_s / fd_dt_s
        self._period_ticks = round(n_period) if abs(n_period - round(n_period)) < 1e-9 else 0
        self._table = np.zeros((max(self._period_ticks, 1), 2, quad.N_JOINTS))
        self._table_filled = np.zeros(max(self._period_ticks, 1), bool)
        self._gait_table: list[ContactPlan | None] = [None] * max(self._period_ticks, 1)
        self._stand_q: np.ndarray | None = None  # q_des while standing (the same IK every tick)
        self._stand_state: ContactPlan | None = None  # gait state while standing (all feet in stance)
        self.use_tables = True  # False: compute every tick's references afresh (tests compare the two)

    def __setstate__(self, state: dict) -> None:
        """Unpickling: q_des and qd_des are views of the references again (pickle copies them apart)."""
        self.__dict__.update(state)
        self.q_des, self.qd_des = self._references

    @property
    def stand_height_m(self) -> float:
        """[m] hip joint -> foot centre in the stand and in stance."""
        return self.gait.p.stand_height_m

    @property
    def commanded_speed_mps(self) -> float:
        """[m/s] the commanded forward speed (sets the step length)."""
        return self.gait.p.speed_mps

    @property
    def stance_swing_s(self) -> tuple[float, float]:
        """[s] the schedule's stance and swing durations (period x duty, period x (1 - duty))."""
        p = self.gait.p
        return p.period_s * p.duty, p.period_s * (1.0 - p.duty)

    def gait_time(self, t: float) -> float:
        """Time since walking started [s] (negative while standing)."""
        return t - self.stand_duration_s

    def contact_plan(self, t: float) -> ContactPlan:
        """Gait schedule at episode time ``t`` [s] (from the per-period table when on the tick grid; its
        arrays are then shared and read-only)."""
        if self.use_tables and t < self.stand_duration_s:  # standing: one constant state
            if self._stand_state is None:
                self._stand_state = self.gait.state(self.gait_time(t))
                self._stand_state.in_stance.flags.writeable = False
                self._stand_state.swing_phase.flags.writeable = False
            return self._stand_state
        if self._period_ticks and self.use_tables:
            x = self.gait_time(t) / self.fd_dt_s
            j = round(x)
            if j >= 0 and abs(x - j) < 1e-6:
                row = j % self._period_ticks
                gs = self._gait_table[row]
                if gs is None:
                    # exact gait time of the row: t - stand_duration would put a switch tick a rounding
                    # error before the switch (phase 0.9999999999999998 instead of 0)
                    gs = self._gait_table[row] = self.gait.state(row * self.fd_dt_s)
                    gs.in_stance.flags.writeable = False
                    gs.swing_phase.flags.writeable = False
                return gs
        return self.gait.state(self.gait_time(t))

    def desired_joints(self, t: float) -> np.ndarray:
        """IK of the gait's foot targets at episode time ``t`` [s] -> (12,) [rad]."""
        return np.array(self._desired_list(t))

    def _desired_list(self, t: float) -> list[float]:
        return self._legs_ik_list(self.gait.foot_targets_list(self.gait_time(t)))

    def compute(self, t: float, q_joints: np.ndarray, qd_joints: np.ndarray, base_pose: np.ndarray | None = None,
                base_velocity: np.ndarray | None = None, tau_applied: np.ndarray | None = None) -> np.ndarray:
        """Nominal torques [N·m] (12, core order) at episode time ``t`` [s] from joint state [rad, rad/s]
        (``base_pose``, ``base_velocity`` and ``tau_applied`` are not used: the paper's references are open loop)."""
        self.update_references(t)
        u = np.empty(quad.N_JOINTS)
        _pd(self._references, q_joints, qd_joints, self._kp, self._kd, self.torque_limit_nm, u)
        return u

    def update_references(self, t: float) -> None:
        """Set ``q_des`` [rad] and ``qd_des`` [rad/s] for episode time ``t`` [s] (table lookup once walking
        has gone one tick past its start, see class doc)."""
        if not self.use_tables:
            self._compute_references(t)
            return
        if self._standing(t):  # constant references
            if self._stand_q is None:
                self._compute_references(t)
                self._stand_q = self.q_des.copy()
            self.q_des[:] = self._stand_q
            self.qd_des[:] = 0.0
            return
        row = self._table_row(t)
        if row >= 0:
            if self._table_filled[row]:
                self._references[:] = self._table[row]  # (q_des, qd_des)
                return
            self._compute_references(t)
            self._table[row] = self._references
            self._table_filled[row] = True
            return
        self._compute_references(t)

    def _standing(self, t: float) -> bool:
        """Episode time ``t`` [s] gets the stand's references (half a tick before walking starts, or earlier)."""
        return self.gait_time(t + 0.5 * self.fd_dt_s) < 0.0

    def _table_row(self, t: float) -> int:
        """The row of the per-period table that walking episode time ``t`` [s] reads or fills: gait time on the
        ``fd_dt_s`` grid, at least one tick after walking starts; -1 for any other time (computed afresh)."""
        if not self._period_ticks:
            return -1
        x = self.gait_time(t) / self.fd_dt_s
        j = round(x)
        return j % self._period_ticks if j >= 1 and abs(x - j) < 1e-6 else -1

    def _compute_references(self, t: float) -> None:
        h = 0.5 * self.fd_dt_s
        t_minus = round(t - h, 9)
        # q_des(t - h) was this controller's q_des(t + h) one tick ago when ticks are fd_dt_s apart.
        before = self._cache_list if self._cache_t == t_minus else self._desired_list(t_minus)
        after = self._desired_list(t + h)
        self._cache_t, self._cache_list = round(t + h, 9), after
        self.q_des[:] = self._desired_list(t)
        self.qd_des[:] = after
        self.qd_des -= before
        self.qd_des *= 1.0 / self.fd_dt_s

    def reference_timeline(self, n_ticks: int, control_dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The references (q_des [rad], qd_des [rad/s], core order) :meth:`compute` uses on the ticks k = 0 ..
        ``n_ticks`` - 1 of one episode (episode time k x ``control_dt_s`` [s]), as (rows (n_rows, 2, 12), index
        (n_ticks,) int32): tick k uses ``rows[index[k]]``. Made by the same :meth:`update_references` calls, from
        this controller's state, as an episode's loop makes (so the controller is left as that loop leaves it).
        Once the per-period table is full, every later tick (when ticks are ``fd_dt_s`` apart) only looks a row up:
        the references then repeat every period and are indexed, not recomputed; a tick whose references equal
        the previous tick's (the stand) reuses its row."""
        if n_ticks < 0 or not control_dt_s > 0.0:
            raise ValueError(f"reference_timeline: n_ticks must be >= 0 and control_dt_s > 0 [s], got {n_ticks!r}, "
                             f"{control_dt_s!r}")
        period = self._period_ticks if self.use_tables and control_dt_s == self.fd_dt_s else 0
        rows: list[np.ndarray] = []
        index = np.empty(n_ticks, np.int32)
        for k in range(n_ticks):
            past_fill = period and k >= period and self._table_filled.all()
            if past_fill and self._table_row((k - period) * control_dt_s) >= 0:
                # tick k - period and every later tick read the full table: the references repeat every period
                index[k:] = index[k - period + np.arange(n_ticks - k) % period]
                break
            if k and self.use_tables and self._stand_q is not None and self._standing(k * control_dt_s):
                index[k] = index[k - 1]  # the stand's references again (update_references would copy them)
                continue
            self.update_references(k * control_dt_s)
            if not rows or rows[-1].tobytes() != self._references.tobytes():  # bitwise (0.0 and -0.0 differ)
                rows.append(self._references.copy())
            index[k] = len(rows) - 1
        return np.array(rows).reshape(-1, 2, quad.N_JOINTS), index

    def reset(self) -> None:
        """A new episode (the references are periodic tables: nothing to forget)."""

    def stand_configuration(self) -> np.ndarray:
        """Joint angles [rad] of the initial stand (nominal feet under the hips)."""
        return self.kinematics.legs_ik(self.gait.nominal_foot_in_hip)


@kernel
def _pd(references, q, qd, kp, kd, limit, u):
    """u = clip(kp (q_des - q) + kd (qd_des - qd), -limit, limit) [N·m] with (q_des, qd_des) = ``references`` and
    ``limit`` (12,) per joint."""
    for j in range(u.shape[0]):
        u[j] = min(max(kp * (references[0, j] - q[j]) + kd * (references[1, j] - qd[j]), -limit[j]), limit[j])


@kernel
def pd_rows(references, index, q, qd, kp, kd, limit, ids, u):
    """:func:`_pd` for each environment i of ``ids`` in a batch (the same compiled law, so the same torques as its
    own controller): u[i] [N·m] from the references ``references[index[i]]`` (2, 12), the joint state q[i], qd[i]
    [rad, rad/s], the gains kp[i], kd[i] and the limits limit[i] (12,) [N·m]."""
    for i in ids:
        _pd(references[index[i]], q[i], qd[i], kp[i], kd[i], limit[i], u[i])
