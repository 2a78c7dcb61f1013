"""One episode: initial stand, then walk for ``duration_s`` under the nominal controller, the safety filter
(optional) and an estimator, in the MuJoCo plant. Returns per-tick arrays and a status; never raises for
faults inside the episode (NaN state, solver exceptions): they end or mark the run instead.

Time: ``t`` [s] is episode time from the start of the stand; walking starts at ``stand_duration_s``.
The control tick reads the plant state, computes u_nom, filters it, holds u for ``physics_per_tick``
physics steps (zero-order hold), then reads plant contact forces of the last physics step.

Initial state: built once per episode object from the seeded rng (stand pose + joint and trunk-velocity
noise), placed so that the lowest foot sphere touches the floor (z = 0) by :data:`INITIAL_PENETRATION_M`;
every :meth:`Episode.run` starts from that same state (the friction check of the run sees it too).

Falls are checked after *every* physics step on the state that step produced (trunk height and tilt read
from ``qpos``, not from ``xpos``/``xmat``, which ``mj_step`` leaves at the step's starting state), and on the
contacts MuJoCo found for the step's starting state (a non-foot robot geom touching the floor at distance
<= 0). ``time_to_fall_s`` is the episode time of the first state past a threshold.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from taslel_bench.control.nominal import NominalController
from taslel_bench.filter.layout import TickInputs
from taslel_bench.filter.safety_filter import SafetyFilter
from taslel_bench.interfaces import Estimator, Proprioception, Scenario
from taslel_bench.metrics import residuals
from taslel_bench.metrics.residuals import ResidualSetup
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.contacts import FootContactReader
from taslel_bench.record.trace import EpisodeTrace
from taslel_bench.robot import a1
from taslel_bench.robot.model import A1Model

INITIAL_PENETRATION_M = 1e-4  # [m] the lowest foot sphere starts this far into the floor: touching


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
        model: A1Model | None = None,  # the controller's model (None: the URDF as is)
    ) -> None:
        self.s = settings
        self.scenario = scenario
        self.terrain = scenario.terrain
        self.m = mj_model
        self.d = mujoco.MjData(mj_model)
        self.bridge = StateBridge(mj_model)
        self.model = model if model is not None else A1Model()
        self.controller = controller
        self.filter = safety_filter
        self.estimator = estimator
        self.rng = rng
        self.stance_from_contact = stance_from_contact
        self.contacts = FootContactReader(mj_model)
        self.physics_per_tick = round(settings.control_dt_s / settings.physics_dt_s)
        self.n_ticks = round((controller.stand_duration_s + settings.duration_s) / settings.control_dt_s)
        # --- QP recording hook (record.qps, taslel_bench.record.qpset.QPRecorder): on_tick(k, t, problem, result)
        self.qp_recorder = None
        # --- streaming hook (record.mcap): chunk_sink(trace, k0, k1) after every chunk_ticks ticks, outside
        # the ticks' timers (its time is reported as recording_s, not in wall_time_s)
        self.chunk_sink: Callable[[EpisodeTrace, int, int], None] | None = None
        self.chunk_ticks = 1000
        self.initial_qpos, self.initial_qvel = self._draw_initial_state()
        self.initial_state()

    def _draw_initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo (qpos, qvel) of the stand pose perturbed by the seeded rng (drawn once per episode): joint
        angles + N(0, init_joint_noise_rad), trunk linear velocity + N(0, init_base_vel_noise_mps) [world
        axes], trunk height set so the lowest foot-sphere bottom is INITIAL_PENETRATION_M below z = 0."""
        s, m, d = self.s, self.m, self.d
        q = np.zeros(a1.NQ)
        q[6] = 1.0
        q[2] = self.controller.gait.p.stand_height_m + a1.FOOT_RADIUS_M
        q[7:] = self.controller.stand_configuration() + self.rng.normal(0.0, s.init_joint_noise_rad, 12)
        v = np.zeros(a1.NV)
        v[:3] = self.rng.normal(0.0, s.init_base_vel_noise_mps, 3)
        mujoco.mj_resetData(m, d)
        self.bridge.qpos_mj(q, d.qpos)
        mujoco.mj_kinematics(m, d)
        feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f) for f in a1.FOOT_FRAMES]
        lowest_bottom = float(np.min(d.geom_xpos[feet, 2] - m.geom_size[feet, 0]))
        q[2] -= lowest_bottom + INITIAL_PENETRATION_M
        self.bridge.qpos_mj(q, d.qpos)
        self.bridge.qvel_mj(q, v, d.qvel)
        return d.qpos.copy(), d.qvel.copy()

    def initial_state(self) -> None:
        """Reset the plant to the episode's initial state (the same one every time)."""
        mujoco.mj_resetData(self.m, self.d)
        self.d.qpos[:] = self.initial_qpos
        self.d.qvel[:] = self.initial_qvel
        mujoco.mj_forward(self.m, self.d)

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

    def _residuals(self, trace: EpisodeTrace, res: EpisodeResult) -> None:
        """The controller model's residuals against the recorded plant motion (after the episode)."""
        t0 = time.perf_counter()
        alpha2 = self.filter.settings.ecbf_alpha2 if self.filter is not None else 20.0
        setup = ResidualSetup(self.bridge, self.model, self.initial_qpos, self.initial_qvel, self.s.control_dt_s, alpha2)
        try:
            residuals.compute(trace, setup)
        except Exception:  # noqa: BLE001 - a metric must not lose the run: note it
            res.extras["residuals_error"] = traceback.format_exc().strip().splitlines()[-1]
        res.extras["residuals_s"] = time.perf_counter() - t0

    def run(self, progress: Callable[[float], None] | None = None) -> EpisodeResult:
        s, m, d, br = self.s, self.m, self.d, self.bridge
        barriers = self.filter.barriers if self.filter is not None else []
        trace = EpisodeTrace(self.n_ticks, filter_on=self.filter is not None, nq=self.m.nq, nv=self.m.nv,
                             nsensordata=self.m.nsensordata, barrier_names=[b.name for b in barriers])
        res = EpisodeResult(trace=trace)
        self.initial_state()
        self.estimator.reset()
        profile = self.scenario.clearance_profile()
        trace.bind(br, self.contacts, profile, self.terrain)
        sink, chunk = self.chunk_sink, max(1, int(self.chunk_ticks))
        recording_s = 0.0  # [s] spent handing chunks to the sink, outside the ticks' timers
        q = np.zeros(a1.NQ)  # Pinocchio configuration, read from the plant every tick
        v = np.zeros(a1.NV)  # Pinocchio velocity (trunk linear velocity in trunk axes)
        qj, qdj = q[7:], v[6:]  # views: joint angles [rad] and velocities [rad/s], core order
        tau_prev = np.zeros(a1.N_JOINTS)
        mu_filter_prev = math.nan  # [-] friction the filter assumed on the previous tick (NaN: no filter)
        need_model = self.filter is not None
        res.extras["warmup_s"] = self._warm_up(q, v)
        cos_tilt_min = math.cos(s.fall_tilt_rad)
        vmax_sq = s.max_speed**2
        t0_plant = d.time
        qpos, qvel, ctrl, sensordata = d.qpos, d.qvel, d.ctrl, d.sensordata  # views, valid for the episode
        a = br.free_qadr  # trunk origin z [m] at qpos[a + 2], orientation (w, x, y, z) at qpos[a + 3 : a + 7]
        contacts = self.contacts
        wall0 = time.perf_counter()
        k = 0
        try:
            for k in range(self.n_ticks):
                tick0 = time.perf_counter()
                t = k * s.control_dt_s
                br.state_pin(qpos, qvel, q, v)  # also fills qj, qdj
                trunk_xy = qpos[a : a + 2]
                true_mu = self.terrain.friction_at(trunk_xy)
                est = self.estimator.step(Proprioception(t, qj, qdj, tau_prev, true_mu, mu_filter_prev))
                u_nom = self.controller.compute(t, qj, qdj)
                gs = self.controller.gait_state(t)
                in_stance = contacts.in_contact.copy() if self.stance_from_contact else gs.in_stance
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
                reason, t_fall, obstacle_touch, shin_touch, unstable = "", math.nan, False, False, False
                for _ in range(self.physics_per_tick):
                    br.ctrl_mj(u, ctrl)  # the scenario may alter ctrl (e.g. actuator delay) each step
                    self.scenario.on_tick(m, d, t)
                    t_before = d.time
                    mujoco.mj_step(m, d)
                    if d.time <= t_before:  # MuJoCo reset the data (NaN/huge qpos, qvel or qacc): no fall check
                        unstable = True
                        break
                    # --- fall checks on this step's result: trunk pose from qpos (the new state) ...
                    z = qpos[a + 2]
                    cos_tilt = 1.0 - 2.0 * (qpos[a + 4] * qpos[a + 4] + qpos[a + 5] * qpos[a + 5])  # trunk z . world z
                    if z < s.fall_height_m:
                        reason, t_fall = f"trunk height {z:.3f} m < {s.fall_height_m} m", d.time - t0_plant
                    elif cos_tilt < cos_tilt_min:
                        tilt = math.degrees(math.acos(max(-1.0, min(1.0, cos_tilt))))
                        reason, t_fall = f"trunk tilt {tilt:.0f} deg", d.time - t0_plant
                    # ... and contacts, which MuJoCo found for the step's starting state (one step earlier)
                    elif contacts.check_non_foot_contact(d):
                        reason = f"{contacts.non_foot_contact_name} (above the knee) touched the terrain"
                        t_fall = d.time - s.physics_dt_s - t0_plant
                    obstacle_touch |= contacts.non_foot_obstacle_contact
                    shin_touch |= contacts.shin_contact
                    if reason:
                        break
                if self.stance_from_contact:  # next tick's stance set
                    contacts.read(d)
                tau_prev[:] = u
                tick4 = time.perf_counter()
                trace.tick_parts_s[k] = (tick1 - tick0, tick2 - tick1, tick3 - tick2, tick4 - tick3)
                trace.record(k, t, qpos, qvel, sensordata, gs, in_stance, u_nom, u, fres, est.mu, true_mu,
                             tick4 - tick0, barriers, obstacle_touch, shin_touch)  # fmt: skip
                trace.mu_hat_ready[k] = est.ready
                # --- termination: a non-finite / exploding state (one dot product catches NaN/inf anywhere in
                # the state and bounds the joint speeds; a MuJoCo reset is caught by its clock above), then a fall
                vel_sq, pos_sq = float(qvel @ qvel), float(qpos @ qpos)
                if not (vel_sq < vmax_sq and math.isfinite(pos_sq)) or unstable:
                    res.status, res.message = "error", f"non-finite or exploding plant state at t={t:.3f}s"
                    break
                if reason:  # the time of the first physics state past a threshold, on the physics-step grid
                    t_fall = round(t_fall / s.physics_dt_s) * s.physics_dt_s
                    res.fell, res.time_to_fall_s, res.fall_reason = True, t_fall, reason
                    break
                if progress is not None and k % 500 == 0:
                    progress(t)
                if sink is not None and (k + 1) % chunk == 0:  # streaming recording, between two ticks
                    rec0 = time.perf_counter()
                    sink(trace, k + 1 - chunk, k + 1)
                    recording_s += time.perf_counter() - rec0
        except Exception as exc:  # noqa: BLE001 - a fault in one run is recorded, never crashes the sweep
            res.status = "error"
            res.message = f"{type(exc).__name__}: {exc}"
            res.extras["traceback"] = traceback.format_exc()
        res.wall_time_s = time.perf_counter() - wall0 - recording_s
        trace.finalize()
        self._residuals(trace, res)
        res.n_ticks = trace.n
        res.extras["recording_s"] = recording_s
        return res
