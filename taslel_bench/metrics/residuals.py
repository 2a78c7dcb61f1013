"""How wrong is the controller's model? Residuals of the model against what the plant did, per tick,
computed after the episode from the recorded plant states (outside the control loop).

For tick k (start state x_k = (q_k, v_k), applied torque u_k, next recorded state x_{k+1}):

* **dynamics residual** r_k = M(q_k) vdot_k + h(q_k, v_k) - S u_k - sum_i Jc_i(q_k)' f_i,k  (18 rows, the
  model's M, h, Jacobians; vdot_k the plant's realised acceleration (v_{k+1} - v_k) / dt in Pinocchio's
  convention; f_i,k the force (and torque) MuJoCo applied on foot i, world axes, at the centroid of its
  contact points, from the foot's contact sensor). Rows 0:3 are the trunk force [N] and 3:6 the trunk torque [N·m] in
  trunk axes, 6: the joints [N·m], core order. Zero up to rounding when the model is the plant (MuJoCo integrates
  v_{k+1} = v_k + dt qacc_k); a damping, armature, friction, mass or actuator the model lacks shows here.
  Exact for one physics step per control tick; with more, f is the last step's force (approximate).
* **foot acceleration error** [m/s²]: the filter's predicted J vdot_filter + J̇v minus the realised
  J vdot_k + J̇v of each foot-sphere centre (world axes), on ticks the filter solved.
* **barrier evolution**: the ECBF condition psi = hdot_e + a2 h_e [m/s²] the filter planned against the
  one realised, (h_e,{k+1} - h_e,k) / dt + a2 h_e,k from the filter's own barrier values on consecutive
  swing ticks of the same foot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
import pinocchio as pin

from taslel_bench.metrics.stream import Reducer
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.record.trace import EpisodeTrace
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.model import RobotModel


@dataclass(frozen=True)
class ResidualSetup:
    bridge: StateBridge
    model: RobotModel  # the controller's model (the filter's equations of motion)
    initial_qpos: np.ndarray  # MuJoCo state before tick 0
    initial_qvel: np.ndarray
    control_dt_s: float  # [s]
    alpha2: float = 20.0  # [1/s] the ECBF's a2 (barrier evolution)


def _skew(d: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])


def compute(trace: EpisodeTrace, setup: ResidualSetup) -> None:
    """Fill ``trace.model_residual`` (n, 18), ``trace.foot_acc_error_w`` (n, 4, 3) and
    every barrier family's ``psi_realized_mps2`` (n, 4) (nan where undefined)."""
    compute_rows(trace, setup, trace.n - trace.offset, setup.initial_qpos, setup.initial_qvel)


def compute_rows(trace: EpisodeTrace, setup: ResidualSetup, n: int, qpos_before: np.ndarray,
                 qvel_before: np.ndarray) -> None:
    """:func:`compute` for the first ``n`` rows of the trace's current chunk: ``q*_before`` is the MuJoCo
    state before its first row (the last row of the previous chunk); a row after them, if recorded, gives
    the last row's realised barrier condition (the same numbers as over the whole episode)."""
    br, m, dt = setup.bridge, setup.model, setup.control_dt_s
    qpos = np.vstack([qpos_before[None], trace.qpos_mj[:n]])  # state before tick k: row k
    qvel = np.vstack([qvel_before[None], trace.qvel_mj[:n]])
    residual = np.full((n, quad.NV), np.nan)
    acc_error = np.full((n, quad.N_LEGS, 3), np.nan)
    q_all, v_all = np.zeros((n, quad.NQ)), np.zeros((n, quad.NV))
    for k in range(n):
        br.state_pin(qpos[k], qvel[k], q_all[k], v_all[k])
    vdot_all = realised_acceleration(br, qpos, qvel, v_all, dt)
    plant_side = trace.contact_reader().from_sensor_log(trace.sensordata_mj[:n])
    forces = plant_side["forces_in_world"]  # [N] on each foot, world axes (MuJoCo's, last physics step)
    torques = plant_side["torques_in_world"]  # [N·m] about the contact point
    points = plant_side["contact_point_in_world"]  # [m] force-weighted centroid of the foot's contacts
    loaded = cast(np.ndarray, np.abs(forces).sum(axis=2) > 0.0)  # (n, 4) (numpy's stub: bool | array)
    u_in_v = np.zeros((n, quad.NV))
    u_in_v[:, 6:] = trace.u[:n]  # S u: the torques act on the joint rows
    filtered = cast(np.ndarray, np.isfinite(trace.vdot_filter[:n]).all(axis=1))  # (n,) (numpy's stub: bool | array)
    local = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for k in range(n):
        m.update(q_all[k], v_all[k])
        tau = m.M @ vdot_all[k] + m.h - u_in_v[k]
        for i in np.flatnonzero(loaded[k]):  # J(point)' f + J_rot' torque, the point on the foot's body
            jac = pin.getFrameJacobian(m.model, m.data, m.foot_frame_ids[i], local)
            offset = _skew(points[k, i] - m.foot_pos_in_world[i])
            tau -= (jac[:3] - offset @ jac[3:]).T @ forces[k, i] + jac[3:].T @ torques[k, i]
        residual[k] = tau
        if filtered[k]:
            acc_error[k] = m.foot_jac_in_world @ (trace.vdot_filter[k] - vdot_all[k])
    trace.model_residual = residual
    trace.foot_acc_error_w = acc_error
    ahead = min(n + 1, trace.n - trace.offset)  # the next row, where it is recorded
    for log in trace.barriers.values():
        log.psi_realized_mps2 = realised_condition(log.he_mps[:ahead], dt, setup.alpha2)[:n]


def realised_acceleration(br: StateBridge, qpos: np.ndarray, qvel: np.ndarray, v: np.ndarray,
                          dt: float) -> np.ndarray:  # fmt: skip
    """(n, 18) the plant's acceleration over each tick in Pinocchio's convention, from n + 1 MuJoCo states:
    MuJoCo integrates qvel_{k+1} = qvel_k + dt qacc_k, so qacc = (qvel_{k+1} - qvel_k) / dt exactly (trunk
    linear part in world axes, angular in trunk axes, joints); Pinocchio's free-flyer vdot is the spatial
    acceleration in trunk axes: linear R' a_world - omega x v_trunk, angular as MuJoCo's. ``v``: (n, 18)
    Pinocchio velocities at the start of each tick."""
    a, d = br.free_qadr, br.free_dadr
    qacc = (qvel[1:] - qvel[:-1]) / dt
    quat = qpos[:-1, a + 3 : a + 7]
    w, x, y, z = (quat / np.linalg.norm(quat, axis=1, keepdims=True)).T
    rot_t = np.stack([  # R' (trunk from world), row by row
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], axis=1),
        np.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], axis=1),
        np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)  # fmt: skip
    vdot = np.empty((qacc.shape[0], quad.NV))
    vdot[:, :3] = np.einsum("nij,nj->ni", rot_t, qacc[:, d : d + 3]) - np.cross(v[:, 3:6], v[:, :3])
    vdot[:, 3:6] = qacc[:, d + 3 : d + 6]
    vdot[:, 6:] = qacc[:, br.joint_dadr]
    return vdot


def realised_condition(h_e: np.ndarray, dt: float, alpha2: float) -> np.ndarray:
    """psi_k = (h_e,{k+1} - h_e,k) / dt + a2 h_e,k where both ticks have a value (the same swing)."""
    out = np.full_like(h_e, np.nan)
    if h_e.shape[0] > 1:
        out[:-1] = (h_e[1:] - h_e[:-1]) / dt + alpha2 * h_e[:-1]
    return out


PSI_TOLERANCE_MPS2 = 2.0  # [m/s²] a realised ECBF condition below -this counts as negative (one-tick finite
# differences of a matched model stay above -0.9 m/s² in 99 % of swing ticks on the virtual bump)


def _rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def residual_metrics(trace: EpisodeTrace, k0: int, limits) -> dict[str, float]:
    """Summary of the residuals over the walking ticks ``k0:n`` (RMS per group of the per-tick norms), and
    the alarm shares :mod:`taslel_bench.metrics.health` judges: ``residual_alarm_rate`` (ticks whose trunk-force
    residual norm exceeds ``limits.residual_trunk_force_n_max`` or whose largest joint residual exceeds
    ``limits.residual_joint_nm_max``) and ``barrier_psi_realized_negative_rate`` (swing ticks the QP solved
    whose realised ECBF condition is below -PSI_TOLERANCE_MPS2). Empty before the residuals are computed."""
    if trace.model_residual.shape[0] < trace.n or trace.n <= k0:
        return {}
    stream = ResidualStream(limits)
    stream.feed(trace, slice(k0, trace.n))
    return stream.result()


class ResidualStream:
    """:func:`residual_metrics` and :func:`alarm_events` fed chunk by chunk (rows of the current chunk
    whose residuals are computed); the alarm state carried across chunks."""

    def __init__(self, limits, max_events: int = 20) -> None:
        self.limits, self.max_events, self.acc = limits, max_events, Reducer()
        self.prev_alarm, self.events = False, []
        self.psi_negative, self.psi_judged, self.fed = 0, 0, False

    def result(self) -> dict[str, float]:
        if not self.fed:
            return {}
        out = self.acc.result()
        if "barrier_psi_error_mps2_rms" in out:
            out["barrier_psi_realized_negative_rate"] = (self.psi_negative / self.psi_judged if self.psi_judged
                                                         else math.nan)  # fmt: skip
        return out

    def feed(self, trace: EpisodeTrace, w: slice) -> None:
        r = trace.model_residual[w]
        if r.shape[0] == 0:
            return
        self.fed = True
        acc, limits = self.acc, self.limits
        force, torque, joint = (np.linalg.norm(r[:, s], axis=1) for s in (slice(0, 3), slice(3, 6), slice(6, None)))
        joint_max = np.abs(r[:, 6:]).max(axis=1)
        alarm = (force > limits.residual_trunk_force_n_max) | (joint_max > limits.residual_joint_nm_max)
        acc.rms("residual_trunk_force_n_rms", force)
        acc.rms("residual_trunk_torque_nm_rms", torque)
        acc.rms("residual_joint_nm_rms", joint)
        acc.pct("residual_joint_nm_p95", joint_max, 95)
        acc.mean("residual_alarm_rate", alarm)
        self._alarms(trace.t_s[w], alarm, force, joint_max)
        if not trace.filter_on:
            return
        stance = trace.in_stance[w]
        acc_err = np.linalg.norm(trace.foot_acc_error_w[w], axis=2)  # [m/s²] predicted - realised, per foot
        acc.rms("foot_acc_error_stance_mps2_rms", acc_err[stance])
        acc.rms("foot_acc_error_swing_mps2_rms", acc_err[~stance])
        solved = (trace.qp_status[w] == 0)[:, None]
        for log in trace.barriers.values():
            real, plan = log.psi_realized_mps2[w], log.psi_planned_mps2[w]
            both = np.isfinite(real) & np.isfinite(plan) & solved
            acc.rms("barrier_psi_error_mps2_rms", (real - plan)[both])
            self.psi_negative += int((real[both] < -PSI_TOLERANCE_MPS2).sum())
            self.psi_judged += int(both.sum())
        acc.first("barrier_psi_error_mps2_rms", math.nan)  # registered without barrier families too

    def _alarms(self, t_s: np.ndarray, alarm: np.ndarray, force: np.ndarray, joint: np.ndarray) -> None:
        onsets = np.flatnonzero(alarm & ~np.concatenate([[self.prev_alarm], alarm[:-1]]))
        self.prev_alarm = bool(alarm[-1])
        for j in onsets[: max(0, self.max_events - len(self.events))]:
            self.events.append({"t_s": float(t_s[j]), "kind": "alarm",
                                "message": f"model residual: trunk force {force[j]:.3g} N, largest joint "
                                           f"{joint[j]:.3g} N·m"})  # fmt: skip


def alarm_events(trace: EpisodeTrace, k0: int, limits, max_events: int = 20) -> list[dict[str, object]]:
    """The first ``max_events`` onsets of a residual alarm (see :func:`residual_metrics`), as events."""
    if trace.model_residual.shape[0] < trace.n or trace.n <= k0:
        return []
    stream = ResidualStream(limits, max_events)
    stream.feed(trace, slice(k0, trace.n))
    return stream.events
