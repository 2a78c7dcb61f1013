"""Nominal-controller episodes for data collection without the benchmark's per-tick recording.

:class:`taslel_bench.api.Episode` records a trace (every state, contact and timing) each tick; a
collection episode needs only the estimator samples. For an episode *without* the safety filter and with
one physics step per control tick (``control_dt_s == physics_dt_s``, the collection setting), this module
runs the core episode's own parts -- its plant and initial state, its :class:`NominalController` (the
references of every tick computed by the controller itself, in tick order, before the loop), the PD law's
kernel, the scenario's ``on_tick``, the core :class:`Terminations` (the benchmark's fall rule, checked after
every physics step) -- in the same order as :meth:`Episode._tick`, minus the trace. The physics is the
same operation for operation, so the samples are bit-identical to the core loop's (tested in
``tests/test_estimators_fastloop.py`` on seeds with and without a fall).

Frames and units: joint angles [rad], velocities [rad/s], torques [N·m], core joint order; samples are
the estimator slot's 36 features (:func:`estimators.features.sample_vector`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numba import njit

from estimators.features import N_FEATURES


@dataclass
class FastResult:
    """What :func:`run_nominal` returns: the samples and the fall, as the core loop's result reports them."""

    samples: np.ndarray  # (n_samples, 36) float32: q, qdot, tau of the previous tick
    trunk_friction: np.ndarray  # (n_samples,) [-] friction under the trunk (the loop's Proprioception.true_friction)
    sensordata: np.ndarray  # (n_samples, nsensordata) the sensors of each sample's state (the trace's rows)
    n_ticks: int  # control ticks run (the fall tick included)
    fell: bool
    time_to_fall_s: float  # [s] on the physics grid; nan without a fall
    status: str  # "ok" or "error" (non-finite / exploding state)
    message: str = ""


def _whole_ticks(x_s: float, dt_s: float) -> int:
    """``x_s / dt_s`` if it is a whole number of ticks, else 0."""
    n = x_s / dt_s
    return round(n) if abs(n - round(n)) < 1e-9 else 0


def references(controller, n_ticks: int, dt_s: float) -> np.ndarray:
    """(n_ticks, 2, 12) the controller's (q_des [rad], qd_des [rad/s]) of every tick, computed by
    ``controller.update_references`` in tick order (the order, and so the reference cache, of the loop).
    When the gait period P and the stand are whole numbers of ticks, the controller itself looks its
    references up in a per-period table one tick past the first period (:class:`NominalController`): the
    ticks after that are copies of the tick P earlier (the same values the table returns)."""
    out = np.empty((n_ticks, 2, 12))
    period = _whole_ticks(controller.gait.p.period_s, dt_s)
    stand = _whole_ticks(controller.stand_duration_s, dt_s)
    tables = controller.use_tables and period and stand and controller.fd_dt_s == dt_s
    direct = min(n_ticks, stand + period + 1) if tables else n_ticks
    for k in range(direct):
        controller.update_references(k * dt_s)
        out[k, 0], out[k, 1] = controller.q_des, controller.qd_des
    for k in range(direct, n_ticks):
        out[k] = out[k - period]
    return out


@njit(cache=True, nogil=True)
def _tick(qpos, qvel, q_adr, v_adr, act_ids, ref_q, ref_qd, kp, kd, limit, tau_prev, sample, do_sample, ctrl):
    """One tick before the physics step: the sample (q, qdot, previous tau) if ``do_sample``, then the PD law
    u = clip(kp (q_des - q) + kd (qd_des - qdot), +-limit[j]) written into ``ctrl`` and ``tau_prev`` (the core's
    :func:`taslel_bench.control.nominal._pd` arithmetic)."""
    for j in range(12):
        q = qpos[q_adr[j]]
        qd = qvel[v_adr[j]]
        if do_sample:
            sample[j] = q
            sample[12 + j] = qd
            sample[24 + j] = tau_prev[j]
        u = min(max(kp * (ref_q[j] - q) + kd * (ref_qd[j] - qd), -limit[j]), limit[j])
        tau_prev[j] = u
        ctrl[act_ids[j]] = u


def run_nominal(episode, every_ticks: int) -> FastResult:
    """Run the core ``episode`` (an :class:`taslel_bench.api.Episode` built without a safety filter, one
    physics step per tick) from its initial state, sampling every ``every_ticks`` ticks."""
    if episode.filter is not None or episode.physics_per_tick != 1:
        raise ValueError("run_nominal: only unfiltered episodes with control_dt_s == physics_dt_s "
                         f"(filter={episode.filter is not None}, physics_per_tick={episode.physics_per_tick})")
    m, d, br, ctl = episode.m, episode.d, episode.bridge, episode.controller
    dt, n = episode.s.control_dt_s, episode.n_ticks
    episode.initial_state()
    episode.estimator.reset()
    refs = references(ctl, n, dt)
    q_adr, v_adr = np.asarray(br.joint_qadr), np.asarray(br.joint_dadr)
    act = np.asarray(br.actuator_ids)
    kp, kd, lim = float(ctl.gains.kp), float(ctl.gains.kd), np.asarray(ctl.torque_limit_nm, float)
    qpos, qvel, ctrl = d.qpos, d.qvel, d.ctrl
    n_max = n // every_ticks + 1
    samples, mu_trunk = np.zeros((n_max, N_FEATURES), np.float32), np.zeros(n_max)
    sensors, sensordata = np.zeros((n_max, m.nsensordata)), d.sensordata
    tau_prev, row = np.zeros(12), np.zeros(N_FEATURES)
    term, scen, t0, terrain, a = episode.terminations, episode.scenario, d.time, episode.terrain, br.free_qadr
    ns = 0

    def done(ticks: int, fell: bool, t_fall: float, status: str, message: str = "") -> FastResult:
        return FastResult(samples[:ns], mu_trunk[:ns], sensors[:ns], ticks, fell, t_fall, status, message)

    for k in range(n):
        t = k * dt
        take = k % every_ticks == 0
        if take:
            mu_trunk[ns] = terrain.friction_at(qpos[a : a + 2])
        _tick(qpos, qvel, q_adr, v_adr, act, refs[k, 0], refs[k, 1], kp, kd, lim, tau_prev, row, take, ctrl)
        scen.on_tick(m, d, t)
        t_before = d.time
        mujoco.mj_step(m, d)
        if take:  # sensors of this tick's state (mj_step evaluates them before integrating)
            samples[ns], sensors[ns] = row, sensordata
            ns += 1
        if d.time <= t_before:
            return done(k + 1, False, float("nan"), "error", f"MuJoCo reset the data at t={t:.3f}s")
        fall = term.after_step(qpos, d, d.time - t0)
        if term.state_is_bad(qpos, qvel):
            return done(k + 1, False, float("nan"), "error", f"non-finite or exploding plant state at t={t:.3f}s")
        if fall is not None:
            return done(k + 1, True, term.on_grid(fall.t_s), "ok")
    return done(n, False, float("nan"), "ok")
