"""Many nominal episodes stepped together: every environment's physics through ``mujoco.batch`` on a thread pool,
the open-loop trot's joint PD of all of them in one compiled call per control tick.

Each environment runs as an :class:`taslel_bench.sim.episode.Episode` of the same parts without a safety filter
would, bit for bit (``tests/test_batch_rollout.py`` compares qpos, qvel and torques with ``np.array_equal``):

* its initial state is the episode's draw (:func:`taslel_bench.sim.episode.draw_initial_state`) from its own rng;
* its references are its controller's (:meth:`NominalController.reference_timeline`: the calls the loop makes),
  its torques the same compiled PD law (:func:`taslel_bench.control.nominal.pd_rows`);
* the fall terms and the state guard are the episode's kernels (:func:`taslel_bench.sim.terminations.step_terms`),
  checked after every physics step; a possible body contact is classified on the contacts of the step's starting
  state, recomputed for that environment only;
* ``mujoco.batch.Batch`` steps each simulation as ``mj_step`` on its own MjData would, at any thread count.

Not run: a safety filter (its model update and QP are per environment and per tick), an estimator (without a filter
nothing reads its estimate), observers and the per-tick trace (a :class:`BatchSamples` holds what the data
collection's sampler reads), scenarios that act on every step (``on_tick``), and controllers other than the
open-loop trot (the terrain-following trot reads the trunk pose). Time: tick k is at episode time k x
``control_dt_s`` [s]; states are MuJoCo's (qpos, qvel; world frame), joint vectors in the core order
[rad, rad/s, N·m].
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np
from mujoco import batch as mj_batch

from taslel_bench.control.nominal import NominalController, pd_rows
from taslel_bench.control.plan import NominalControl
from taslel_bench.interfaces import Scenario
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.contacts import FootContactReader
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.episode import EpisodeSettings, does_nothing, draw_initial_state
from taslel_bench.sim.terminations import READS_CONTACTS, Fall, Terminations
from taslel_bench.util.jit import kernel

RECORD = ("none", "torques", "states")  # what BatchRollout(record=...) keeps of every tick


@dataclass(frozen=True)
class BatchEnv:
    """One environment of a batched rollout: what its :class:`Episode` would be built from."""

    scenario: Scenario  # its world: the terrain sets the initial height and the friction under the trunk
    mj_model: mujoco.MjModel  # its plant; every environment of a batch has one layout (one builder)
    controller: NominalControl  # its open-loop trot (a NominalController); one object may serve several envs
    rng: np.random.Generator  # draws its initial state, as the episode's rng does


@dataclass
class EnvOutcome:
    """How one environment's episode ended (the fields of the episode's result of the same names)."""

    status: str = "ok"  # "ok", or "error": a non-finite or exploding state
    message: str = ""
    fell: bool = False
    time_to_fall_s: float = math.nan  # [s] episode time on the physics grid (nan: no fall)
    fall_reason: str = ""
    fall_term: str = ""  # one of taslel_bench.sim.terminations.TERMS ("" without a fall)
    n_ticks: int = 0  # control ticks run, the last one (of a fall or an error) included


@dataclass
class BatchSamples:
    """What an episode's observer sees on every ``every_ticks``-th control tick (k % every_ticks == 0), for each
    environment; a row of environment i is valid while ``ticks[s] < outcomes[i].n_ticks``."""

    every_ticks: int
    ticks: np.ndarray  # (S,) the sampled ticks
    q_joints: np.ndarray  # (S, N, 12) [rad] at the tick's start, core order
    qd_joints: np.ndarray  # (S, N, 12) [rad/s] at the tick's start
    tau_prev: np.ndarray  # (S, N, 12) [N·m] torque applied on the previous tick (the tick's Proprioception)
    friction_under_trunk: np.ndarray  # (S, N) [-] the terrain's under the trunk at the tick's start (GroundTruth)
    sensordata: np.ndarray  # (S, N, nsensordata) MuJoCo sensors after the tick's physics


@dataclass
class BatchTrace:
    """Every tick of every environment (``record``): the torque held over the tick and, with ``record="states"``, the
    plant state after the tick's physics (else empty arrays); rows after an environment's last tick repeat its final
    values (zero after the batch's last)."""

    u: np.ndarray  # (T, N, 12) [N·m] core order
    qpos: np.ndarray  # (T, N, nq) MuJoCo qpos
    qvel: np.ndarray  # (T, N, nv) MuJoCo qvel (free joint: linear velocity in world axes)


@dataclass
class BatchResult:
    outcomes: list[EnvOutcome]
    wall_time_s: float  # [s] the ticks' loop (controller, physics, fall terms, sampling)
    setup_time_s: float  # [s] initial states, reference timelines and the batch (before the loop)
    physics_steps: int  # mj_step calls over all environments
    nthread: int  # the batch's threads, the caller's included
    samples: BatchSamples | None = None
    trace: BatchTrace | None = None
    extras: dict[str, float] = field(default_factory=dict)

    @property
    def env_steps_per_s(self) -> float:
        """Physics steps per wall second of the ticks' loop, all environments together."""
        return self.physics_steps / self.wall_time_s if self.wall_time_s > 0 else math.nan


class BatchRollout:
    """The episodes of ``envs`` (see the module doc) with the episode ``settings`` (duration, rates, fall rule,
    initial noise) on ``nthread`` threads (0: every CPU). ``sample_every_ticks`` > 0 keeps a :class:`BatchSamples`;
    ``record`` keeps a :class:`BatchTrace`: one of :data:`RECORD` ("torques": ticks x envs x 12 floats, "states":
    x 49 for the A1)."""

    def __init__(self, settings: EpisodeSettings, envs: Sequence[BatchEnv], *, nthread: int = 0,
                 sample_every_ticks: int = 0, record: str = "none") -> None:
        t0 = time.perf_counter()
        self.s, self.envs = settings, tuple(envs)
        self.controllers = _checked_controllers(self.envs)
        if sample_every_ticks < 0:
            raise ValueError(f"sample_every_ticks must be >= 0 (0: no samples), got {sample_every_ticks!r}")
        if record not in RECORD:
            raise ValueError(f"record must be one of {', '.join(RECORD)}, got {record!r}")
        self.sample_every, self.record = int(sample_every_ticks), record
        m0 = self.envs[0].mj_model
        self.bridge = StateBridge(m0)
        self.contacts = FootContactReader(m0)  # one layout: the same sensor rows and geom classes in every env
        self.terminations = Terminations(settings.fall, self.bridge.free_qadr, self.contacts, settings.physics_dt_s)
        self.physics_per_tick = round(settings.control_dt_s / settings.physics_dt_s)
        self.end_tick = np.array([round((c.stand_duration_s + settings.duration_s) / settings.control_dt_s)
                                  for c in self.controllers])
        self.initial_qpos, self.initial_qvel = self._initial_states()
        self._timelines()
        self.batch = mj_batch.Batch(m0, len(self.envs), nthread)
        self.batch.set_models([e.mj_model for e in self.envs])
        self.setup_time_s = time.perf_counter() - t0

    def _initial_states(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, nq), (N, nv): each environment's initial MuJoCo state, drawn as its episode draws it."""
        scratch = mujoco.MjData(self.envs[0].mj_model)
        states = [draw_initial_state(e.mj_model, scratch, self.bridge, c, c.robot.foot_radius_m, e.scenario.terrain,
                                     self.s, e.rng) for e, c in zip(self.envs, self.controllers, strict=True)]
        return np.array([q for q, _ in states]), np.array([v for _, v in states])

    def _timelines(self) -> None:
        """Each controller's reference timeline (once per controller object), stacked: ``_rows`` (R, 2, 12),
        ``_index`` (T, N) the row of tick k of env i; the PD gains and limits per environment."""
        n_ticks = int(self.end_tick.max())
        rows, offsets, index = [], {}, np.zeros((n_ticks, len(self.envs)), np.int32)
        for i, controller in enumerate(self.controllers):
            key = id(controller)
            if key not in offsets:
                r, idx = controller.reference_timeline(n_ticks, self.s.control_dt_s)
                offsets[key] = (sum(len(x) for x in rows), idx)
                rows.append(r)
            offset, idx = offsets[key]
            index[:, i] = offset + idx
        self._rows, self._index = np.concatenate(rows), index
        self._kp = np.array([float(c.gains.kp) for c in self.controllers])  # [N·m/rad], as the controller's
        self._kd = np.array([float(c.gains.kd) for c in self.controllers])  # [N·m·s/rad]
        self._limit = np.array([c.torque_limit_nm for c in self.controllers], float)  # [N·m] (N, 12)

    # -------------------------------------------------------------------------------------------------- run
    def reset(self) -> None:
        """Every simulation of the batch at its environment's initial state, as the episode's ``initial_state()``:
        MuJoCo's reset, the initial qpos and qvel, ``mj_forward``."""
        b = self.batch
        b.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        b.bind("qpos")[:] = self.initial_qpos
        b.bind("qvel")[:] = self.initial_qvel
        b.forward()

    def run(self) -> BatchResult:
        """Every environment from its initial state until its end, a fall or an error (the same ones each run)."""
        loop = _Loop(self)
        wall0 = time.perf_counter()
        for k in range(int(self.end_tick.max())):
            if not loop.tick(k):
                break
        wall = time.perf_counter() - wall0
        return BatchResult(loop.outcomes, wall, self.setup_time_s, loop.physics_steps, self.batch.nthread,
                           loop.samples, loop.trace, {"contact_checks": float(loop.contact_checks)})


class _Loop:
    """One run of a :class:`BatchRollout`: its buffers and its ticks."""

    def __init__(self, r: BatchRollout) -> None:
        self.r, b, n = r, r.batch, len(r.envs)
        r.reset()
        self.qpos, self.qvel, self.ctrl, self.time = b.bind("qpos"), b.bind("qvel"), b.bind("ctrl"), b.bind("time")
        self.sensordata, self.ncon = b.bind("sensordata"), b.bind("ncon")
        self.alive = np.ones(n, bool)
        self.ids = np.arange(n)
        self.outcomes = [EnvOutcome() for _ in range(n)]
        self.q, self.qd = np.zeros((n, quad.N_JOINTS)), np.zeros((n, quad.N_JOINTS))  # [rad], [rad/s] tick start
        self.u, self.tau_prev = np.zeros((n, quad.N_JOINTS)), np.zeros((n, quad.N_JOINTS))  # [N·m]
        self.qpos_before = np.empty_like(self.qpos)  # each step's starting qpos (a body contact's contacts)
        self.codes, self.ok = np.zeros(n, np.int64), np.zeros(n, np.bool_)
        self.physics_steps = self.contact_checks = 0
        self._scratch: mujoco.MjData | None = None
        self.mujoco_errors: dict[int, str] = {}  # env -> the error MuJoCo raised in its step
        self.samples = _new_samples(r, n) if r.sample_every else None
        self.trace = _new_trace(r, n) if r.record != "none" else None
        mus = [e.scenario.terrain.uniform_friction for e in r.envs]  # [-] None: several frictions
        self._uniform_mu = np.array([math.nan if mu is None else mu for mu in mus])

    def tick(self, k: int) -> bool:
        """Control tick ``k`` of every running environment; False once none runs."""
        r, ids = self.r, self.ids
        _read_joints(self.qpos, self.qvel, ids, r.bridge.joint_qadr, r.bridge.joint_dadr, self.q, self.qd)
        pd_rows(r._rows, r._index[k], self.q, self.qd, r._kp, r._kd, r._limit, ids, self.u)
        _write_ctrl(self.u, ids, r.bridge.actuator_ids, self.ctrl)
        sample = self.samples is not None and k % r.sample_every == 0
        if sample:
            self._sample_before(k // r.sample_every, ids)
        falls, unstable = self._physics(ids)
        if sample and self.samples is not None:
            self.samples.sensordata[k // r.sample_every, ids] = self.sensordata[ids]
        self.tau_prev[ids] = self.u[ids]
        if self.trace is not None:
            self._record(k)
        self._end_tick(k, ids, falls, unstable)
        return bool(self.ids.size)

    def _physics(self, ids: np.ndarray) -> tuple[dict[int, Fall], set[int]]:
        """The tick's physics steps of the environments ``ids``, each checked after every step as the episode does:
        ({env: its fall}, {envs MuJoCo reset}); an environment stops stepping at its fall or reset."""
        r, b = self.r, self.r.batch
        falls: dict[int, Fall] = {}
        unstable: set[int] = set()
        step_ids = ids
        for _ in range(r.physics_per_tick):
            np.copyto(self.qpos_before, self.qpos)
            t_before = self.time[step_ids]
            try:
                b.step(None if step_ids.size == len(r.envs) else step_ids)
            except mj_batch.SimulationError as exc:  # those kept their state (no time step: ended below), the rest ran
                self.mujoco_errors.update({int(i): b.error(int(i)) for i in exc.ids})
            self.physics_steps += step_ids.size
            t_after = self.time[step_ids]
            r.terminations.after_steps(self.qpos, step_ids, self.sensordata, self.ncon, self.codes)
            flagged = np.flatnonzero((self.codes[: step_ids.size] != 0) | (t_after <= t_before))
            if flagged.size == 0:
                continue
            for j in flagged:
                self._resolve(int(step_ids[j]), bool(t_after[j] <= t_before[j]), int(self.codes[j]), falls, unstable)
            step_ids = np.array([i for i in step_ids if i not in falls and i not in unstable], np.int64)
            if step_ids.size == 0:
                break
        return falls, unstable

    def _resolve(self, i: int, reset: bool, code: int, falls: dict[int, Fall], unstable: set[int]) -> None:
        """Environment ``i`` after a step that MuJoCo ``reset`` (its divergence guard) or whose fall-term ``code``
        is not zero: note the reset or the fall (a body contact read on the step's starting contacts)."""
        if reset:  # MuJoCo reset the data: no fall check, as in the episode
            unstable.add(i)
            return
        data = self._contacts_at_step_start(i) if code == READS_CONTACTS else None
        fall = self.r.terminations.fall_of(code, self.qpos[i], data, float(self.time[i]))
        if fall is not None:
            falls[i] = fall

    def _contacts_at_step_start(self, i: int) -> mujoco.MjData:
        """An MjData of environment ``i`` holding the contacts of the last step's starting state (MuJoCo's contact
        list after ``mj_step``): collision recomputed at that qpos."""
        self.contact_checks += 1
        m = self.r.envs[i].mj_model
        d = self._scratch = self._scratch if self._scratch is not None else mujoco.MjData(m)  # one layout: one scratch
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self.qpos_before[i]
        mujoco.mj_fwdPosition(m, d)
        return d

    def _end_tick(self, k: int, ids: np.ndarray, falls: dict[int, Fall], unstable: set[int]) -> None:
        """The episode's end test after tick ``k`` for the environments ``ids``: a reset or a bad state is an error,
        else a fall ends it; then those that reached their last tick end; the ended leave the running set."""
        r = self.r
        r.terminations.states_ok(self.qpos, self.qvel, ids, self.ok)
        bad = set(ids[~self.ok[: ids.size]].tolist()) | unstable
        for i in bad:  # the episode's message, or MuJoCo's error (the episode's would name its exception)
            out = self.outcomes[i]
            out.status, out.message = "error", f"non-finite or exploding plant state at t={k * r.s.control_dt_s:.3f}s"
            if i in self.mujoco_errors:
                out.message = f"MuJoCo error at t={k * r.s.control_dt_s:.3f}s: {self.mujoco_errors[i]}"
        for i in falls.keys() - bad:
            out, fall = self.outcomes[i], falls[i]
            out.fell, out.time_to_fall_s = True, r.terminations.on_grid(fall.t_s)
            out.fall_reason, out.fall_term = fall.reason, fall.term
        ended = bad | falls.keys() | set(ids[r.end_tick[ids] == k + 1].tolist())
        if not ended:
            return
        for i in ended:
            self.outcomes[i].n_ticks = k + 1
            self.alive[i] = False
        self.ids = np.flatnonzero(self.alive)

    def _sample_before(self, s: int, ids: np.ndarray) -> None:
        """Sample row ``s``: the joint state at the tick's start, the previous tick's torque, the friction under
        the trunk (sensors are added after the tick's physics)."""
        smp = self.samples
        assert smp is not None  # sampling is on
        smp.q_joints[s, ids], smp.qd_joints[s, ids] = self.q[ids], self.qd[ids]
        smp.tau_prev[s, ids] = self.tau_prev[ids]
        mu = self._uniform_mu[ids]
        a = self.r.bridge.free_qadr
        for j in np.flatnonzero(np.isnan(mu)):  # a terrain of several frictions: read it under the trunk
            i = int(ids[j])
            mu[j] = self.r.envs[i].scenario.terrain.friction_at(self.qpos[i, a : a + 2])
        smp.friction_under_trunk[s, ids] = mu

    def _record(self, k: int) -> None:
        tr = self.trace
        assert tr is not None  # recording is on
        tr.u[k] = self.u
        if self.r.record == "states":
            tr.qpos[k], tr.qvel[k] = self.qpos, self.qvel


def _new_samples(r: BatchRollout, n: int) -> BatchSamples:
    ticks = np.arange(0, int(r.end_tick.max()), r.sample_every)
    s, nj = len(ticks), quad.N_JOINTS
    return BatchSamples(r.sample_every, ticks, np.zeros((s, n, nj)), np.zeros((s, n, nj)), np.zeros((s, n, nj)),
                        np.full((s, n), math.nan), np.zeros((s, n, r.envs[0].mj_model.nsensordata)))


def _new_trace(r: BatchRollout, n: int) -> BatchTrace:
    t, m = int(r.end_tick.max()), r.envs[0].mj_model
    rows = t if r.record == "states" else 0
    return BatchTrace(np.zeros((t, n, quad.N_JOINTS)), np.zeros((rows, n, m.nq)), np.zeros((rows, n, m.nv)))


def _checked_controllers(envs: tuple[BatchEnv, ...]) -> list[NominalController]:
    """The environments' controllers, after a ValueError naming the field of the first environment a batched
    rollout cannot run as its episode would."""
    if not envs:
        raise ValueError("BatchRollout: envs is empty; give at least one BatchEnv")
    m0, out = envs[0].mj_model, []
    for i, e in enumerate(envs):
        c = e.controller
        if not (isinstance(c, NominalController) and _open_loop(type(c))):
            raise ValueError(f"envs[{i}].controller: a batched rollout runs the open-loop trot (NominalController); "
                             f"got {type(c).__name__}")
        if not does_nothing(e.scenario.on_tick):
            raise ValueError(f"envs[{i}].scenario: {type(e.scenario).__name__}.on_tick acts on every physics step; "
                             "a batched rollout runs scenarios whose on_tick does nothing")
        if _layout(e.mj_model) != _layout(m0):
            raise ValueError(f"envs[{i}].mj_model: its layout {_layout(e.mj_model)} differs from envs[0]'s "
                             f"{_layout(m0)}; batch environments of one plant builder and terrain kind together")
        out.append(c)
    return out


def _open_loop(kind: type[NominalController]) -> bool:
    """The trot's references of ``kind`` are NominalController's (open loop: not overridden by a subclass)."""
    return kind.compute is NominalController.compute and kind.update_references is NominalController.update_references


def _layout(m: mujoco.MjModel) -> tuple[int, ...]:
    """The sizes and addresses a batch's models must share: (nq, nv, nu, nbody, ngeom, nsensordata) and a hash of
    the joint, sensor and actuator addresses."""
    addresses = np.concatenate([m.jnt_qposadr, m.jnt_dofadr, m.sensor_adr, m.actuator_trnid[:, 0]])
    return m.nq, m.nv, m.nu, m.nbody, m.ngeom, m.nsensordata, hash(addresses.tobytes())


@kernel
def _read_joints(qpos, qvel, ids, qadr, dadr, q, qd):  # pragma: no cover - compiled
    """q[i] = qpos[i, qadr], qd[i] = qvel[i, dadr] (core joint order) for each environment i of ``ids``."""
    for i in ids:
        for j in range(qadr.shape[0]):
            q[i, j] = qpos[i, qadr[j]]
            qd[i, j] = qvel[i, dadr[j]]


@kernel
def _write_ctrl(u, ids, act, ctrl):  # pragma: no cover - compiled
    """ctrl[i, act] = u[i] (core joint order -> MuJoCo actuators) for each environment i of ``ids``."""
    for i in ids:
        for j in range(act.shape[0]):
            ctrl[i, act[j]] = u[i, j]
