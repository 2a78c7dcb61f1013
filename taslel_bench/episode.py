"""One episode: initial stand, then walk for ``duration_s`` under the nominal controller, the safety filter
(optional) and an estimator, in the MuJoCo plant. Returns per-tick arrays and a status; never raises for
faults inside the episode (NaN state, solver exceptions): they end or mark the run instead.

Time: ``t`` [s] is episode time from the start of the stand; walking starts at ``stand_duration_s``.
The control tick reads the plant state, computes u_nom, filters it, holds u for ``physics_per_tick``
physics steps (zero-order hold), then reads plant contact forces of the last physics step.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from taslel_bench import plant, robot
from taslel_bench.bridge import StateBridge
from taslel_bench.constraints import TickInputs
from taslel_bench.controller import NominalController
from taslel_bench.interfaces import Estimator, Proprioception, Scenario
from taslel_bench.model import A1Model
from taslel_bench.safety_filter import SafetyFilter
from taslel_bench.trace import EpisodeTrace


@dataclass(frozen=True)
class EpisodeSettings:
    duration_s: float = 10.0  # [s] walking time after the stand
    physics_dt_s: float = 0.001  # [s]
    control_dt_s: float = 0.001  # [s] an integer multiple of physics_dt_s
    fall_height_m: float = 0.12  # [m] trunk origin below this -> fall
    fall_tilt_rad: float = 1.0  # [rad] angle between trunk z and world z above this -> fall
    max_speed: float = 200.0  # [rad/s, m/s] ||qvel||_2 beyond this (or non-finite) -> "exploding state" error
    init_joint_noise_rad: float = 0.02  # [rad] std of the initial joint-angle perturbation (seeded)
    init_base_vel_noise_mps: float = 0.05  # [m/s] std of the initial trunk velocity perturbation
    clearance_tolerance_m: float = 0.001  # [m] swing-foot bottom below z(s) - tol counts as a violation
    filter_start_s: float = 0.0  # [s] episode time before which u_nom passes unfiltered (paper's figure)


@dataclass
class EpisodeResult:
    trace: EpisodeTrace
    status: str = "ok"  # "ok" or "error"
    message: str = ""
    fell: bool = False
    time_to_fall_s: float = math.nan
    fall_reason: str = ""
    n_ticks: int = 0
    wall_time_s: float = 0.0
    extras: dict[str, object] = field(default_factory=dict)


class Episode:
    """Wires plant, model, controller, filter and estimator for one run."""

    def __init__(
        self,
        settings: EpisodeSettings,
        scenario: Scenario,
        mj_model: mujoco.MjModel,
        controller: NominalController,
        safety_filter: SafetyFilter | None,
        estimator: Estimator,
        rng: np.random.Generator,
        stance_from_contact: bool = False,
    ) -> None:
        self.s = settings
        self.scenario = scenario
        self.m = mj_model
        self.d = mujoco.MjData(mj_model)
        self.bridge = StateBridge(mj_model)
        self.model = A1Model()
        self.controller = controller
        self.filter = safety_filter
        self.estimator = estimator
        self.rng = rng
        self.stance_from_contact = stance_from_contact
        self.contacts = plant.FootContactReader(mj_model)
        self.physics_per_tick = round(settings.control_dt_s / settings.physics_dt_s)
        self.n_ticks = round((controller.stand_duration_s + settings.duration_s) / settings.control_dt_s)
        self.trunk_body = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_BODY, robot.TRUNK_BODY)
        # --- QP recording hook (record.qps, taslel_bench.qpset.QPRecorder): on_tick(k, t, problem, result)
        self.qp_recorder = None

    def initial_state(self) -> None:
        """Stand pose with feet on the ground, perturbed by the seeded rng."""
        s, d = self.s, self.d
        q = np.zeros(robot.NQ)
        q[6] = 1.0
        q[2] = self.controller.gait.p.stand_height_m + robot.FOOT_RADIUS_M
        q[7:] = self.controller.stand_configuration() + self.rng.normal(0.0, s.init_joint_noise_rad, 12)
        v = np.zeros(robot.NV)
        v[:3] = self.rng.normal(0.0, s.init_base_vel_noise_mps, 3)
        mujoco.mj_resetData(self.m, d)
        self.bridge.qpos_mj(q, d.qpos)
        self.bridge.qvel_mj(q, v, d.qvel)
        mujoco.mj_forward(self.m, d)

    def _warm_up(self, q: np.ndarray, v: np.ndarray) -> float:
        """Run the tick's compiled kernels once on the initial state, before the episode clock starts (the
        first call of a kernel in a process loads or compiles it). Returns the time it took [s]."""
        t0 = time.perf_counter()
        self.bridge.state_pin(self.d.qpos, self.d.qvel, q, v)
        if self.filter is not None:
            self.model.update(q, v)
            # the gait's state arrays are read-only (a type of their own for the compiler), the plant's
            # contact flags (filter.stance_source=contact) writable: warm both
            for t, writable in ((0.0, True), (self.controller.stand_duration_s, False)):
                gs = self.controller.gait_state(t)
                u_nom = self.controller.compute(t, q[7:], v[6:])
                stance = gs.in_stance.copy() if writable else gs.in_stance
                inputs = TickInputs(self.model, v, stance, 1.0, gs.swing_phase, gs.swing_phase_rate)
                self.filter.filter(inputs, u_nom)
            self.filter.reset()  # the episode starts from a fresh solver (its setup is part of tick 0)
        return time.perf_counter() - t0

    def run(self, progress: Callable[[float], None] | None = None) -> EpisodeResult:
        s, m, d, br = self.s, self.m, self.d, self.bridge
        trace = EpisodeTrace(self.n_ticks, filter_on=self.filter is not None, nq=self.m.nq, nv=self.m.nv,
                             nsensordata=self.m.nsensordata)
        res = EpisodeResult(trace=trace)
        self.initial_state()
        self.estimator.reset()
        profile = self.scenario.clearance_profile()
        q = np.zeros(robot.NQ)  # Pinocchio configuration, read from the plant every tick
        v = np.zeros(robot.NV)  # Pinocchio velocity (trunk linear velocity in trunk axes)
        qj, qdj = q[7:], v[6:]  # views: joint angles [rad] and velocities [rad/s], core order
        tau_prev = np.zeros(robot.N_JOINTS)
        mu_filter_prev = math.nan  # [-] friction the filter assumed on the previous tick (NaN: no filter)
        need_model = self.filter is not None
        res.extras["warmup_s"] = self._warm_up(q, v)
        ecbf = self.filter.ecbf if self.filter is not None else None
        cos_tilt_min = math.cos(s.fall_tilt_rad)
        vmax_sq = s.max_speed**2
        t0_plant = d.time
        qpos, qvel, ctrl, sensordata = d.qpos, d.qvel, d.ctrl, d.sensordata  # views, valid for the episode
        xpos, xmat, trunk = d.xpos, d.xmat, self.trunk_body
        wall0 = time.perf_counter()
        k = 0
        try:
            for k in range(self.n_ticks):
                tick0 = time.perf_counter()
                t = k * s.control_dt_s
                br.state_pin(qpos, qvel, q, v)  # also fills qj, qdj
                trunk_xy = qpos[br.free_qadr : br.free_qadr + 2]
                true_mu = self.scenario.friction_at(trunk_xy)
                est = self.estimator.step(Proprioception(t, qj, qdj, tau_prev, true_mu, mu_filter_prev))
                u_nom = self.controller.compute(t, qj, qdj)
                gs = self.controller.gait_state(t)
                in_stance = self.contacts.in_contact.copy() if self.stance_from_contact else gs.in_stance
                tick1 = tick2 = tick3 = time.perf_counter()
                if need_model and t >= s.filter_start_s:
                    self.model.update(q, v)
                    tick2 = time.perf_counter()
                    inputs = TickInputs(self.model, v, in_stance, est.mu, gs.swing_phase, gs.swing_phase_rate)
                    fres = self.filter.filter(inputs, u_nom)
                    u = fres.u
                    mu_filter_prev = est.mu
                    if self.qp_recorder is not None:  # record.qps: copy this tick's QP + solution used
                        self.qp_recorder.on_tick(k, t, self.filter.backend_problem, fres)
                    tick3 = time.perf_counter()
                else:
                    fres = None
                    u = u_nom
                    mu_filter_prev = math.nan
                for _ in range(self.physics_per_tick):
                    br.ctrl_mj(u, ctrl)  # the scenario may alter ctrl (e.g. actuator delay) each step
                    self.scenario.on_tick(m, d, t)
                    mujoco.mj_step(m, d)
                if self.stance_from_contact:  # next tick's stance set
                    self.contacts.read(d)
                else:
                    self.contacts.check_non_foot_contact(d)
                tau_prev[:] = u
                tick4 = time.perf_counter()
                trace.tick_parts_us[k] = (tick1 - tick0, tick2 - tick1, tick3 - tick2, tick4 - tick3)
                tick_s = tick4 - tick0
                t_end_of_tick = t0_plant + (k + 1) * s.control_dt_s - 0.5 * s.physics_dt_s
                trace.record(k, t, qpos, qvel, sensordata, gs, in_stance, u_nom, u, fres, est.mu, true_mu, tick_s,
                             ecbf)
                trace.mu_hat_ready[k] = est.ready
                # --- termination checks (plant state after the tick) ---
                # one dot product catches NaN/inf anywhere in the state and bounds the joint speeds
                vel_sq, pos_sq = float(qvel @ qvel), float(qpos @ qpos)
                # MuJoCo resets the data (time -> 0) on a NaN/huge qpos, qvel or qacc: catch that cheaply
                unstable = d.time < t_end_of_tick
                if not (vel_sq < vmax_sq and math.isfinite(pos_sq)) or unstable:
                    res.status, res.message = "error", f"non-finite or exploding plant state at t={t:.3f}s"
                    break
                z = xpos[trunk, 2]
                cos_tilt = xmat[trunk, 8]  # world-z component of the trunk z axis
                reason = ""
                if z < s.fall_height_m:
                    reason = f"trunk height {z:.3f} m < {s.fall_height_m} m"
                elif cos_tilt < cos_tilt_min:
                    reason = f"trunk tilt {math.degrees(math.acos(max(-1.0, cos_tilt))):.0f} deg"
                elif self.contacts.non_foot_contact:
                    reason = "non-foot body touched the ground"
                if reason:
                    res.fell, res.time_to_fall_s, res.fall_reason = True, t + s.control_dt_s, reason
                    break
                if progress is not None and k % 500 == 0:
                    progress(t)
        except Exception as exc:  # noqa: BLE001 - a fault in one run is recorded, never crashes the sweep
            res.status = "error"
            res.message = f"{type(exc).__name__}: {exc}"
            res.extras["traceback"] = traceback.format_exc()
        trace.finalize(br, self.contacts, profile)
        res.n_ticks = trace.n
        res.wall_time_s = time.perf_counter() - wall0
        return res
