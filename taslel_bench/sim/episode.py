"""One episode: initial stand, then walk for ``duration_s`` under the nominal controller, the safety filter
(optional) and an estimator, in the MuJoCo plant. The one closed loop of the project: the benchmark, the
estimators' data collection and the in-loop studies all run it. Returns per-tick arrays and a status; never
raises for faults inside the episode (NaN state, solver exceptions): they end or mark the run instead.

Time: ``t`` [s] is episode time from the start of the stand; walking starts at ``stand_duration_s``.
A control tick (:meth:`Episode._tick`) reads the plant state, lets the estimator see it, computes u_nom,
filters it, holds u for ``physics_per_tick`` physics steps (zero-order hold) with the fall terms checked
after each (:mod:`taslel_bench.sim.terminations`), and records the tick.

Initial state: built once per episode object from the seeded rng (stand pose + joint and trunk-velocity
noise), placed so that the lowest foot sphere touches the terrain under it by :data:`INITIAL_PENETRATION_M`;
every :meth:`Episode.run` starts from that same state (the friction check of the run sees it too).
"""

from __future__ import annotations

import dis
import gc
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from types import SimpleNamespace

import mujoco
import numpy as np

from taslel_bench.control.plan import NominalControl, compute_of
from taslel_bench.filter.layout import TickInputs
from taslel_bench.filter.safety_filter import FilterResult, SafetyFilter
from taslel_bench.interfaces import (
    Estimator,
    FrictionEstimate,
    GroundTruth,
    ImuSample,
    Proprioception,
    Scenario,
    Terrain,
)
from taslel_bench.metrics import residuals
from taslel_bench.metrics.residuals import ResidualSetup
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.contact_frames import ContactFrameReader
from taslel_bench.plant.contacts import FootContactReader
from taslel_bench.record.result import EpisodeResult
from taslel_bench.record.trace import EpisodeTrace
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.model import RobotModel
from taslel_bench.sim.imu import TrunkImu
from taslel_bench.sim.observers import HOOKS, hooks_of
from taslel_bench.sim.stance import PlannedStance, StanceSource
from taslel_bench.sim.terminations import Fall, FallRule, Terminations

INITIAL_PENETRATION_M = 1e-4  # [m] the lowest foot sphere starts this far into the terrain: touching
PROGRESS_EVERY_TICKS = 500
DEFAULT_FALL_RULE = FallRule(height_m=0.12, tilt_deg=57.0)  # conf/robot/a1.yaml's


@dataclass(frozen=True)
class EpisodeSettings:
    """Built from the run config by :func:`taslel_bench.config.settings.episode_settings`; the defaults are the
    config's (the schema's and ``conf/robot/a1.yaml``; a test checks they agree)."""

    duration_s: float = 10.0  # [s] walking time after the stand
    physics_dt_s: float = 0.001  # [s]
    control_dt_s: float = 0.001  # [s] an integer multiple of physics_dt_s
    fall: FallRule = DEFAULT_FALL_RULE
    init_joint_noise_rad: float = 0.02  # [rad] std of the initial joint-angle perturbation (seeded)
    init_base_vel_noise_mps: float = 0.05  # [m/s] std of the initial trunk velocity perturbation
    filter_start_s: float = 0.0  # [s] episode time before which u_nom passes unfiltered (paper's figure)
    analyse: bool = True  # derive the trace's named quantities and the model residuals after the episode


class Episode:
    """One run's closed loop, assembled from its declared parts: the plant (``mj_model`` with the ``scenario``'s
    terrain and edits), the nominal ``controller``, the ``stance`` source and the ``safety_filter`` (None: the
    nominal torques reach the plant), the friction ``estimator``, the controller's ``model`` and the
    ``observers`` (:mod:`taslel_bench.sim.observers`: the recorders, each timed on its own clock).

    ``trace``: record every tick in an :class:`EpisodeTrace` (the metrics, steps.parquet and MCAP read it;
    False for a loop that only needs its observers, as data collection); ``chunk_ticks``: process and drop
    the trace every that many ticks (None: keep the whole episode; ``result.trace`` then holds every tick)."""

    def __init__(
        self,
        settings: EpisodeSettings,
        scenario: Scenario,
        mj_model: mujoco.MjModel,
        controller: NominalControl,
        safety_filter: SafetyFilter | None,
        estimator: Estimator,
        rng: np.random.Generator,
        *,
        model: RobotModel | None = None,  # the controller's model (None: the URDF as is)
        stance: StanceSource | None = None,  # the filter's stance set (None: the controller's plan)
        observers: Sequence[object] = (),
        chunk_ticks: int | None = None,
        trace: bool = True,
        initial_state: tuple[np.ndarray, np.ndarray] | None = None,  # MuJoCo (qpos, qvel); None: drawn from rng
    ) -> None:
        self.s = settings
        self.scenario = scenario
        self.terrain = scenario.terrain
        self.m = mj_model
        self.d = mujoco.MjData(mj_model)
        self.bridge = StateBridge(mj_model)
        self.model = model if model is not None else RobotModel()
        self.controller = controller
        self.filter = safety_filter
        self.estimator = estimator
        self.rng = rng
        self.stance: StanceSource = stance if stance is not None else PlannedStance()
        self.observers = tuple(observers)
        self.chunk_ticks = int(chunk_ticks) if chunk_ticks else None
        self.records_trace = bool(trace)
        # the terrain-aware filter reads the feet's contact forces (contact estimate) and the friction under
        # each foot (per-foot cones) every tick
        self.per_foot_terrain = safety_filter is not None and safety_filter.settings.friction_cone == "terrain"
        self._read_feet = self.stance.reads_feet_before_tick or self.per_foot_terrain
        self.contacts = FootContactReader(mj_model)
        self.contact_frames = ContactFrameReader(mj_model)  # every foot contact in its own frame (metrics)
        self.terminations = Terminations(settings.fall, self.bridge.free_qadr, self.contacts, settings.physics_dt_s)
        self.physics_per_tick = round(settings.control_dt_s / settings.physics_dt_s)
        self.imu = TrunkImu(mj_model.opt.gravity, settings.control_dt_s)  # the estimator's trunk IMU
        self._imu_on = False  # sampled every tick of a run whose estimator reads it (set at the run's start)
        self._scenario_step: Callable | None = None  # scenario.on_tick, None if it does nothing (per run)
        self.n_ticks = round((controller.stand_duration_s + settings.duration_s) / settings.control_dt_s)
        self.sensed: Proprioception | None = None  # the current tick's proprioception (observers read it)
        self.truth: GroundTruth | None = None  # the current tick's ground truth (observers read it)
        if initial_state is None:
            initial_state = self._draw_initial_state()
        self.initial_qpos, self.initial_qvel = (np.array(x, float) for x in initial_state)
        self.initial_state()

    def with_observers(self, observers: Sequence[object], *, analyse: bool | None = None,
                       chunk_ticks: int | None = None) -> Episode:
        """A new episode of the same parts and initial state with other ``observers`` (a tool's extra run,
        e.g. one that records the filter's QPs); ``analyse``: override ``settings.analyse``."""
        settings = self.s if analyse is None else replace(self.s, analyse=analyse)
        return Episode(settings, self.scenario, self.m, self.controller, self.filter, self.estimator, self.rng,
                       model=self.model, stance=self.stance, observers=observers, chunk_ticks=chunk_ticks,
                       trace=self.records_trace, initial_state=(self.initial_qpos, self.initial_qvel))

    # ------------------------------------------------------------------------------------ initial state
    def _draw_initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo (qpos, qvel) of the episode's initial state (:func:`draw_initial_state`, drawn once per episode)."""
        return draw_initial_state(self.m, self.d, self.bridge, self.controller, self.model.robot.foot_radius_m,
                                  self.terrain, self.s, self.rng)

    def initial_state(self) -> None:
        """Reset the plant to the episode's initial state (the same one every time)."""
        mujoco.mj_resetData(self.m, self.d)
        self.d.qpos[:] = self.initial_qpos
        self.d.qvel[:] = self.initial_qvel
        mujoco.mj_forward(self.m, self.d)

    def _warm_up(self) -> float:
        """Run the tick's compiled kernels once on the initial state, before the episode clock starts (the
        first call of a kernel in a process loads or compiles it), and resolve the scenario's per-step hook
        (per run: it may be replaced after construction). Returns the time it took [s]."""
        t0 = time.perf_counter()
        hook = self.scenario.on_tick
        self._scenario_step = None if does_nothing(hook) else hook  # most scenarios do nothing per step
        q, v = self._q, self._v
        self.bridge.state_pin(self.d.qpos, self.d.qvel, q, v)
        results: list[FilterResult | None] = [None]
        if self.filter is not None:
            self.model.update(q, v)
            # the gait's state arrays are read-only (a type of their own for the compiler), the plant's
            # contact flags (filter.stance_source=contact) writable: warm both
            for t, writable in ((0.0, True), (self.controller.stand_duration_s, False)):
                gs = self.controller.contact_plan(t)
                u_nom = self._compute(t, q[7:], v[6:], self._base_pose, self._base_velocity, self._tau_prev)
                stance = gs.in_stance.copy() if writable else gs.in_stance
                inputs = TickInputs(self.model, v, stance, 1.0, gs.swing_phase, gs.swing_phase_rate)
                results.append(self.filter.filter(inputs, u_nom))
            self.filter.reset()  # the episode starts from a fresh solver (its setup is part of tick 0)
        self.controller.reset()  # the controller starts with no memory of the warm-up or an earlier episode
        self._warm_up_after_filter(results)
        return time.perf_counter() - t0

    def _warm_up_after_filter(self, results: list[FilterResult | None]) -> None:
        """The kernels of the tick's second half (fall terms, state guard; with a trace: contact rows, the
        trace's row copy) on the initial state, the row copy into a scratch trace with and without a filter
        result, read-only (gait table) and writable (contact flags, an off-grid gait state) stance and phase
        arrays."""
        self.terminations.after_step(self._qpos, self.d, 0.0)  # a check only: nothing of the episode changes
        self.terminations.state_is_bad(self._qpos, self._qvel)
        if not self.records_trace:
            return
        self.contact_frames.warm_up(self.d)
        scratch = self._new_trace(1)
        gs = self.controller.contact_plan(self.controller.stand_duration_s)
        est = FrictionEstimate(mu=1.0, sigma=0.0, ready=True)
        writable = SimpleNamespace(phi=gs.phi, swing_phase=gs.swing_phase.copy(), in_stance=gs.in_stance.copy())
        for fres in results:
            for state, stance in ((gs, gs.in_stance), (writable, gs.in_stance.copy())):
                scratch.record(0, 0.0, self._plant_rows, state, stance, self._tau_prev, self._tau_prev, fres, est, 1.0,
                               (0.0, 0.0, 0.0, 0.0, 0.0), self._barriers, False, False)  # fmt: skip

    def _new_trace(self, capacity: int) -> EpisodeTrace:
        return EpisodeTrace(capacity, filter_on=self.filter is not None, nq=self.m.nq, nv=self.m.nv,
                            nsensordata=self.m.nsensordata, barrier_names=[b.name for b in self._barriers],
                            barrier_rows={b.name: tuple(b.rows) for b in self._barriers if not b.per_leg})

    # -------------------------------------------------------------------------------------------- run
    def run(self, progress: Callable[[float], None] | None = None) -> EpisodeResult:
        """Reset, run every tick until the end, a fall or an error, then analyse the trace. The observers'
        time is reported under their clocks (``result.extras``), not in ``result.wall_time_s``."""
        trace, res = self._start()
        gc_was_enabled = gc.isenabled()
        gc.disable()  # the loop makes no reference cycles: no collector pauses inside ticks (restored below)
        wall0 = time.perf_counter()
        try:
            for k in range(self.n_ticks):
                ended = self._tick(k, trace, res)
                self._ticks_done = k + 1
                if ended:
                    break
                self._between_ticks(k, trace, progress)
        except Exception as exc:  # a fault in one run is recorded, never crashes the sweep
            res.status, res.message = "error", f"{type(exc).__name__}: {exc}"
            res.extras["traceback"] = traceback.format_exc()
        finally:
            if gc_was_enabled:
                gc.enable()
        res.wall_time_s = time.perf_counter() - wall0 - sum(self._clock.values())
        if trace is not None:
            res.n_ticks = trace.n
            self._process_chunk(trace, res, trace.n - trace.offset)  # the last (or only) chunk
        else:
            res.n_ticks = self._ticks_done
        self._observe(self._hooks["finish"], res)
        res.extras.update(self._clock)  # recording_s, reference_s, residuals_s: [s] off the loop's clock
        return res

    def _start(self) -> tuple[EpisodeTrace | None, EpisodeResult]:
        """A fresh trace (if recorded) and result, the plant at its initial state, the per-run buffers,
        the observers started, warmed kernels."""
        self._barriers = self.filter.barriers if self.filter is not None else []
        trace = None
        if self.records_trace:
            trace = self._new_trace(self.n_ticks if not self.chunk_ticks else min(self.n_ticks, self.chunk_ticks + 1))
        res = EpisodeResult(trace=trace)
        self.initial_state()
        self.estimator.reset()
        self.stance.reset()
        if trace is not None:
            trace.bind(self.bridge, self.contacts, self.scenario.clearance_profile(), self.terrain,
                       self.contact_frames)  # fmt: skip
        self._views()
        self.imu.reset(self._v_trunk_w)
        self._t0_plant = self.d.time
        self._ticks_done = 0
        # [s] off the loop's clock, per observer clock
        self._clock: dict[str, float] = dict.fromkeys(("recording_s", "reference_s", "residuals_s"), 0.0)
        self._hooks = {hook: hooks_of(self.observers, hook) for hook in HOOKS}
        # the hooks called every tick, looked up once
        self._after_tick, self._between_ticks_hooks = self._hooks["after_tick"], self._hooks["between_ticks"]
        for _, clock in (pair for pairs in self._hooks.values() for pair in pairs):
            self._clock.setdefault(clock, 0.0)
        if trace is None and self._hooks["on_chunk"]:
            raise ValueError("Episode(trace=False): an observer reads the trace's chunks (on_chunk): "
                             f"{[m.__qualname__ for m, _ in self._hooks['on_chunk']]}")
        self._residuals_error = ""  # the first residual computation's error ("" none)
        self._state_before = (self.initial_qpos.copy(), self.initial_qvel.copy())  # before the chunk's first row
        self._observe(self._hooks["start"], self)
        res.extras["warmup_s"] = self._warm_up()
        return trace, res

    def _views(self) -> None:
        """Views of the plant's arrays and the tick's buffers, made once per run (MjData makes a new numpy
        wrapper on every attribute read), and the controller's compute as the tick calls it."""
        self._compute = compute_of(self.controller)  # per run: a tool may wrap the controller's compute
        self._qpos, self._qvel, self._sensordata, self._ctrl = self.d.qpos, self.d.qvel, self.d.sensordata, self.d.ctrl
        self._q = np.zeros(quad.NQ)  # Pinocchio configuration, read from the plant every tick
        self._base_pose = self._q[:7]  # its trunk pose (a view, made once): the controller's base_pose
        self._v = np.zeros(quad.NV)  # Pinocchio velocity (trunk linear velocity in trunk axes)
        self._base_velocity = self._v[:6]  # its trunk velocity (a view): the controller's base_velocity
        self._q_joints, self._qd_joints = self._q[7:], self._v[6:]  # [rad], [rad/s] core order (views, made once)
        self._plant_rows = (self._qpos, self._qvel, self._sensordata)  # what the trace copies after each tick
        a = self.bridge.free_qadr
        self._trunk_xy = slice(a, a + 2)  # the trunk's (x, y) in qpos: where the terrain's friction is read
        self._true_mu = self.terrain.uniform_friction  # [-] one coefficient everywhere (None: read it each tick)
        self._tau_prev = np.zeros(quad.N_JOINTS)  # [N·m] the torque applied on the previous tick
        self._mu_filter_prev = math.nan  # [-] friction the filter assumed on the previous tick (NaN: no filter)
        self._v_trunk_w = self._qvel[self.bridge.free_dadr : self.bridge.free_dadr + 3]  # [m/s] view, world axes
        self._imu_on = bool(getattr(self.estimator, "reads_imu", False))
        # an oracle's step also gets the tick's ground truth (resolved once: None for every other estimator); the
        # Estimator protocol declares the one-argument step only, hence the ignore
        reads_truth = bool(getattr(self.estimator, "reads_ground_truth", False))
        self._truth_step: Callable[[Proprioception, GroundTruth], FrictionEstimate] | None = (
            self.estimator.step if reads_truth else None)  # pyright: ignore[reportAttributeAccessIssue]
        self._read_feet_after_step = self.stance.reads_feet_after_step

    def _observe(self, hooks: list[tuple[Callable, str]], *args) -> None:
        """Call each observer's hook, its time added to the observer's clock."""
        for method, clock in hooks:
            t0 = time.perf_counter()
            method(*args)
            self._clock[clock] += time.perf_counter() - t0

    def _imu_sample(self) -> ImuSample | None:
        """This tick's trunk IMU sample (None when the estimator does not read one)."""
        return self.imu.read(self._q, self._v, self._v_trunk_w) if self._imu_on else None

    def _tick(self, k: int, trace: EpisodeTrace | None, res: EpisodeResult) -> bool:
        """Control tick ``k``: sense and estimate, control, filter, step the plant, record. True when the
        episode ends here (a fall or a non-finite state)."""
        tick0 = time.perf_counter()
        t = k * self.s.control_dt_s
        qpos, q_joints, qd_joints = self._qpos, self._q_joints, self._qd_joints
        self.bridge.state_pin(qpos, self._qvel, self._q, self._v)
        true_mu = self._true_mu if self._true_mu is not None else self.terrain.friction_at(qpos[self._trunk_xy])
        mu_feet = None
        if self._read_feet:
            self.contacts.read(self.d)
            if self.per_foot_terrain and self.terrain.uniform_friction is None:  # one coefficient: mu broadcast
                mu_feet = self.terrain.friction_under(self.contacts.foot_pos_in_world[:, :2])
        self.truth = truth = GroundTruth(true_mu, mu_feet)  # what only the simulator knows
        self.sensed = sensed = Proprioception(t, q_joints, qd_joints, self._tau_prev, filter_mu=self._mu_filter_prev,
                                              imu=self._imu_sample())  # what the robot measures
        est = self.estimator.step(sensed) if self._truth_step is None else self._truth_step(sensed, truth)
        u_nom = self._compute(t, q_joints, qd_joints, self._base_pose, self._base_velocity, self._tau_prev)
        gs = self.controller.contact_plan(t)
        in_stance = self.stance.stance(gs, self.contacts)
        tick1 = time.perf_counter()
        u, fres, tick2, tick3 = self._filter(t, u_nom, gs, in_stance, est, tick1)
        fall, obstacle_touch, shin_touch, unstable = self._step_plant(u, t)
        tick4 = time.perf_counter()
        if trace is not None:
            trace.record(k, t, self._plant_rows, gs, in_stance, u_nom, u, fres, est, true_mu,
                         (tick0, tick1, tick2, tick3, tick4), self._barriers, obstacle_touch, shin_touch)  # fmt: skip
            frames0 = time.perf_counter()
            self.contact_frames.record(self.d, trace.contact_log, k - trace.offset)  # the tick's last physics step
            self._clock["recording_s"] += time.perf_counter() - frames0  # recording for the metrics
        if self._after_tick:
            self._observe(self._after_tick, k, t, fres)
        self._tau_prev[:] = u
        return self._ended(t, fall, unstable, res)

    def _filter(self, t: float, u_nom: np.ndarray, gs, in_stance: np.ndarray, est: FrictionEstimate,
                tick1: float) -> tuple[np.ndarray, FilterResult | None, float, float]:
        """(u, the filter's result or None, the times the model update and the filter ended) for this tick:
        u_nom while no filter is in the loop (none, or before ``filter_start_s``: both times are ``tick1``)."""
        if self.filter is None or t < self.s.filter_start_s:
            self._mu_filter_prev = math.nan
            return u_nom, None, tick1, tick1
        self.model.update(self._q, self._v)
        tick2 = time.perf_counter()
        inputs = TickInputs(self.model, self._v, in_stance, est.mu, self.stance.swing_phase(gs), gs.swing_phase_rate,
                            est.mu_per_foot if self.per_foot_terrain else None)  # fmt: skip
        fres = self.filter.filter(inputs, u_nom)
        self._mu_filter_prev = est.mu
        return fres.u, fres, tick2, time.perf_counter()

    def _step_plant(self, u: np.ndarray, t: float) -> tuple[Fall | None, bool, bool, bool]:
        """Hold ``u`` for the tick's physics steps, checking the fall terms after each. Returns (the fall or
        None, a lower leg touched an obstacle, a lower leg touched the floor, MuJoCo reset the data)."""
        m, d, contacts, qpos, ctrl = self.m, self.d, self.contacts, self._qpos, self._ctrl
        after_step, scenario_step, act, t0_plant = self.terminations.after_step, self._scenario_step, \
            self.bridge.actuator_ids, self._t0_plant
        obstacle_touch = shin_touch = False
        ctrl[act] = u  # joint torques [N·m], core order -> MuJoCo actuators (Episode.bridge.ctrl_mj)
        for _ in range(self.physics_per_tick):
            if scenario_step is not None:  # the scenario may alter ctrl (e.g. actuator delay) each step
                ctrl[act] = u
                scenario_step(m, d, t)
            t_before = d.time
            mujoco.mj_step(m, d)
            t_after = d.time
            if t_after <= t_before:  # MuJoCo reset the data (NaN/huge qpos, qvel or qacc): no fall check
                return None, obstacle_touch, shin_touch, True
            fall = after_step(qpos, d, t_after - t0_plant)
            obstacle_touch |= contacts.non_foot_obstacle_contact
            shin_touch |= contacts.shin_contact
            if fall is not None:
                return fall, obstacle_touch, shin_touch, False
        if self._read_feet_after_step:  # the stance source's next stance set
            contacts.read(d)
        return None, obstacle_touch, shin_touch, False

    def _ended(self, t: float, fall: Fall | None, unstable: bool, res: EpisodeResult) -> bool:
        """Mark ``res`` if the tick ended the episode: a non-finite or exploding state (an error), a fall."""
        if unstable or self.terminations.state_is_bad(self._qpos, self._qvel):
            res.status, res.message = "error", f"non-finite or exploding plant state at t={t:.3f}s"
            return True
        if fall is not None:
            res.fell, res.time_to_fall_s, res.fall_reason = True, self.terminations.on_grid(fall.t_s), fall.reason
            res.extras["fall_term"] = fall.term
            return True
        return False

    def _between_ticks(self, k: int, trace: EpisodeTrace | None, progress: Callable[[float], None] | None) -> None:
        """Progress, the observers' between-tick work and the chunk's processing (``chunk_ticks``), outside
        the tick's timers. A chunk is processed once the tick after it is recorded (the realised barrier
        condition of its last tick needs the next one), then dropped from the trace."""
        if progress is not None and k % PROGRESS_EVERY_TICKS == 0:
            progress(k * self.s.control_dt_s)
        if self._between_ticks_hooks:
            self._observe(self._between_ticks_hooks, k, trace)
        if self.chunk_ticks and trace is not None and trace.n - trace.offset == self.chunk_ticks + 1:
            self._process_chunk(trace, None, self.chunk_ticks)
            trace.roll(self.chunk_ticks)
            rec0 = time.perf_counter()
            gc.collect()  # the collector is off in the loop: free the chunk's cyclic garbage (tables, frames)
            self._clock["recording_s"] += time.perf_counter() - rec0

    def _process_chunk(self, trace: EpisodeTrace, res: EpisodeResult | None, rows: int) -> None:
        """The first ``rows`` rows of the trace: derived quantities and model residuals (``analyse``), then the
        observers' ``on_chunk`` in order."""
        if self.s.analyse:
            rec0 = time.perf_counter()
            trace.finalize(rows)
            self._clock["recording_s"] += time.perf_counter() - rec0
            self._residuals(trace, rows)
        k0 = trace.offset
        self._observe(self._hooks["on_chunk"], trace, k0, k0 + rows)
        if rows:
            self._state_before = (trace.qpos_mj[rows - 1].copy(), trace.qvel_mj[rows - 1].copy())
        if self._residuals_error and res is not None:
            res.extras["residuals_error"] = self._residuals_error

    def _residuals(self, trace: EpisodeTrace, rows: int) -> None:
        """The controller model's residuals against the recorded plant motion of the chunk's rows (after
        their ticks; the first error is noted and stops them for the rest of the episode)."""
        if self._residuals_error:
            return
        t0 = time.perf_counter()
        alpha2 = self.filter.settings.ecbf_alpha2 if self.filter is not None else 20.0
        setup = ResidualSetup(self.bridge, self.model, self.initial_qpos, self.initial_qvel, self.s.control_dt_s,
                              alpha2)
        try:
            residuals.compute_rows(trace, setup, rows, *self._state_before)
        except Exception:  # a metric must not lose the run: note it
            self._residuals_error = traceback.format_exc().strip().splitlines()[-1]
        self._clock["residuals_s"] += time.perf_counter() - t0


def draw_initial_state(m: mujoco.MjModel, d: mujoco.MjData, bridge: StateBridge, controller: NominalControl,
                       foot_radius_m: float, terrain: Terrain, settings: EpisodeSettings,
                       rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo (qpos, qvel) of the controller's stand pose perturbed by ``rng``: joint angles +
    N(0, ``settings.init_joint_noise_rad``) [rad], trunk linear velocity + N(0, ``init_base_vel_noise_mps``) [m/s,
    world axes], trunk height set so that the lowest foot-sphere bottom (spheres of ``foot_radius_m`` [m]) is
    :data:`INITIAL_PENETRATION_M` below the ``terrain`` under it. ``d`` (an MjData of ``m``'s layout) is scratch."""
    q = np.zeros(quad.NQ)
    q[6] = 1.0
    q[2] = controller.stand_height_m + foot_radius_m
    q[7:] = controller.stand_configuration() + rng.normal(0.0, settings.init_joint_noise_rad, 12)
    v = np.zeros(quad.NV)
    v[:3] = rng.normal(0.0, settings.init_base_vel_noise_mps, 3)
    mujoco.mj_resetData(m, d)
    bridge.qpos_mj(q, d.qpos)
    mujoco.mj_kinematics(m, d)
    feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f) for f in quad.FOOT_FRAMES]
    ground = np.array([terrain.height_at(x, y) for x, y in d.geom_xpos[feet, :2]])
    lowest_bottom = float(np.min(d.geom_xpos[feet, 2] - m.geom_size[feet, 0] - ground))
    q[2] -= lowest_bottom + INITIAL_PENETRATION_M
    bridge.qpos_mj(q, d.qpos)
    bridge.qvel_mj(q, v, d.qvel)
    return d.qpos.copy(), d.qvel.copy()


_NOOP_OPS = ("RESUME", "NOP", "LOAD_CONST", "RETURN_VALUE", "RETURN_CONST")


def does_nothing(method: Callable) -> bool:
    """True if ``method``'s body only returns None (``...``, ``return None``, a docstring): its calls can be
    skipped. Anything else (or no Python code to read) counts as doing something."""
    code = getattr(getattr(method, "__func__", method), "__code__", None)
    if code is None:
        return False
    ops = list(dis.get_instructions(code))
    return all(op.opname in _NOOP_OPS for op in ops) and all(
        op.argval is None for op in ops if op.opname in ("LOAD_CONST", "RETURN_CONST"))

