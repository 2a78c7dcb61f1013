"""The fit: ``mujoco.sysid`` parameters for the five model fields, a windowed replay residual, the least-squares
solve and the confidence intervals.

Residual (multiple shooting): the walking part of each run is cut into windows of ``window_s``; each window starts
from its recorded state (one ``steps.parquet`` row), is rolled out by ``mujoco.sysid.sysid_rollout`` (MuJoCo's
``rollout``) under the recorded commanded torques (held for the tick's physics steps, delayed by the plant's known
actuator delay), and the predicted velocities at the following ticks are compared with the recorded ones: joint
velocities [rad/s], trunk angular velocity [rad/s] (trunk frame), trunk linear velocity [m/s] (world axes) divided
by :data:`LEVER_M` so that all three weigh as angular velocities. A free-floating trot cannot be replayed open-loop
for long (it falls over within a fraction of a second), short windows can: from the true model the replay matches
the record to rounding (~1e-6 rad/s).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TextIO

import mujoco
import numpy as np
from mujoco import sysid

from taslel_bench.identify.runs import FIELDS, URDF_VALUES, RunData
from taslel_bench.plant.perturbation import (
    MAX_ARMATURE_KGM2,
    MAX_COM_SHIFT_M,
    MAX_JOINT_DAMPING,
    MAX_JOINT_FRICTIONLOSS_NM,
    MAX_SCALE,
    PlantPerturbation,
    as_joint_values,
)
from taslel_bench.robot import quadruped as quad
from taslel_bench.util.fields import ConfigError

LEVER_M = 0.2  # [m] trunk linear velocity / this = an angular velocity's weight (the A1's thigh is 0.2 m long)
FD_STEP = 1e-6  # finite-difference step of the Jacobian, x max(1, |x|) in the fields' units
CONFIDENCE = 0.95  # of the intervals
SIGNALS = {"joint_velocity_radps": slice(6, None), "trunk_linear_velocity_mps": slice(0, 3),
           "trunk_angular_velocity_radps": slice(3, 6)}  # qvel of the free-floating robot


@dataclass(frozen=True)
class FieldSpec:
    """One identified field: unit, bounds of the fit (the plant perturbation's ranges), typical magnitude (the
    optimizer's scaling; the joint losses start at a fifth of it, inside their lower bound)."""

    unit: str
    lo: float
    hi: float
    scale: float


SPECS = {
    "joint_damping": FieldSpec("N·m·s/rad", 0.0, MAX_JOINT_DAMPING, 1.0),
    "armature": FieldSpec("kg·m²", 0.0, MAX_ARMATURE_KGM2, 0.01),
    "joint_frictionloss": FieldSpec("N·m", 0.0, MAX_JOINT_FRICTIONLOSS_NM, 0.1),
    "trunk_mass_scale": FieldSpec("-", 0.1, MAX_SCALE, 1.0),
    "trunk_com_shift_m": FieldSpec("m, trunk frame", -MAX_COM_SHIFT_M, MAX_COM_SHIFT_M, 0.01),
}
JOINT_FIELDS = ("joint_damping", "armature", "joint_frictionloss")


@dataclass(frozen=True)
class FitSettings:
    window_s: float = 0.02  # [s] replay window
    max_walk_s: float = 20.0  # [s] walking data used at most (runs in the order given, each from its stand's end)
    per_joint: bool = False  # 12 values per joint field (core order) instead of one for all joints
    max_iters: int = 50
    threads: int = 2  # rollout threads


@dataclass
class Windows:
    """One run's replay windows: sysid's measured rollouts and the arrays the residual compares."""

    run: RunData
    sequences: sysid.ModelSequences
    starts: np.ndarray  # (nw,) rows the windows start from
    measured_qvel: np.ndarray  # (nw, W, nv) recorded velocities at the window's ticks
    datas: list[mujoco.MjData] = field(default_factory=list)


@dataclass
class FitResult:
    """What the fit found. Values per field as lists (1, 3 or 12 numbers); intervals are half-widths at
    :data:`CONFIDENCE` from sysid's ``calculate_intervals``."""

    runs: list[str]
    window_s: float
    windows: int
    walking_s: float
    physics_dt_s: float
    urdf: dict[str, list[float]]
    start: dict[str, list[float]]
    value: dict[str, list[float]]
    interval: dict[str, list[float]]
    plant: dict[str, list[float]] | None  # the runs' plant values (run configs), None when they differ
    rms_before: dict[str, float]  # replay error RMS at the URDF's values
    rms_after: dict[str, float]
    iterations: int
    seconds: float
    sysid: dict[str, Any] = field(default_factory=dict, repr=False)  # initial/opt params, opt result, covariance


def identify(runs: Sequence[RunData], settings: FitSettings = FitSettings(), output: TextIO | None = None
             ) -> FitResult:
    """Fit the five model fields to ``runs`` (``output``: where the optimizer writes its iterations)."""
    if not runs:
        raise ConfigError("identify: no run folders given")
    groups = windows_of(runs, settings)
    params = parameters(settings.per_joint)
    initial = params.copy()

    def residual_fn(x: np.ndarray, p: sysid.ParameterDict, **_: Any) -> tuple[list[np.ndarray], list, list]:
        return [weighted(replay_errors(x, p, groups, settings.threads), x.ndim > 1)], [], []

    t0 = time.perf_counter()
    opt_params, result = sysid.optimize(initial_params=params, residual_fn=residual_fn, optimizer="mujoco",
                                        verbose=False, eps=FD_STEP, x_scale=scales(params),
                                        max_iters=settings.max_iters, output=output)  # fmt: skip
    seconds = time.perf_counter() - t0
    x_star = np.ravel(result.x)
    r_star = residual_fn(x_star, opt_params)[0]
    covariance, intervals = sysid.calculate_intervals(r_star, result.jac, alpha=1.0 - CONFIDENCE)
    nominal = initial.as_nominal_vector()
    return FitResult(
        runs=[str(r.path) for r in runs], window_s=settings.window_s, windows=sum(len(g.starts) for g in groups),
        walking_s=sum(g.measured_qvel.shape[0] * g.measured_qvel.shape[1] * g.run.physics_dt_s * g.run.steps_per_tick
                      for g in groups), physics_dt_s=runs[0].physics_dt_s,
        urdf=by_field(params, nominal), start=by_field(params, initial.as_vector()), value=by_field(params, x_star),
        interval=by_field(params, np.asarray(intervals)), plant=shared_plant(runs, settings.per_joint),
        rms_before=rms(replay_errors(nominal, initial, groups, settings.threads)),
        rms_after=rms(replay_errors(x_star, opt_params, groups, settings.threads)),
        iterations=max(len(result.extras.get("objective", [])) - 1, 0), seconds=seconds,
        sysid={"initial": initial, "opt": opt_params, "result": result, "covariance": covariance, "groups": groups},
    )  # fmt: skip


# ------------------------------------------------------------------------------------------------ parameters
def parameters(per_joint: bool) -> sysid.ParameterDict:
    """sysid parameters of the five fields: nominal = the URDF's values, value = the start (joint losses a fifth
    of their scale, inside the lower bound), bounds from :data:`SPECS`. Applied by :func:`build_model`, not by
    per-parameter modifiers (one implementation of the edits: :class:`PlantPerturbation`)."""
    params = sysid.ParameterDict()
    for name in FIELDS:
        spec, size = SPECS[name], field_size(name, per_joint)
        nominal = np.broadcast_to(np.asarray(URDF_VALUES[name], float), (size,)).copy()
        p = sysid.Parameter(name, nominal, np.full(size, spec.lo), np.full(size, spec.hi))
        if name in JOINT_FIELDS:
            p.value = np.full(size, 0.2 * spec.scale)
        params.add(p)
    return params


def field_size(name: str, per_joint: bool) -> int:
    if name in JOINT_FIELDS:
        return quad.N_JOINTS if per_joint else 1
    return 3 if name == "trunk_com_shift_m" else 1


def scales(params: sysid.ParameterDict) -> np.ndarray:
    """The optimizer's per-component scaling (``x_scale``): each field's typical magnitude."""
    return np.concatenate([np.full(p.size, SPECS[n].scale) for n, p in params.items()])


def perturbation(params: sysid.ParameterDict) -> PlantPerturbation:
    """The plant perturbation with the parameters' current values (joint fields: one value -> all 12)."""
    def joint(name: str) -> tuple[float, ...]:
        value = params[name].value
        return as_joint_values(value.tolist() if value.size > 1 else float(value[0]))

    shift = params["trunk_com_shift_m"].value
    return PlantPerturbation(trunk_mass_scale=float(params["trunk_mass_scale"].value[0]),
                             trunk_com_shift_m=(float(shift[0]), float(shift[1]), float(shift[2])),
                             joint_damping=joint("joint_damping"), armature=joint("armature"),
                             joint_frictionloss=joint("joint_frictionloss"))


def build_model(params: sysid.ParameterDict, spec: mujoco.MjSpec) -> mujoco.MjModel:
    """sysid's ``BuildModelFn``: a copy of the nominal ``spec`` with the parameters applied as the plant
    perturbation is, compiled."""
    edited = spec.copy()
    perturbation(params).apply(edited)
    return edited.compile()


def by_field(params: sysid.ParameterDict, vector: np.ndarray) -> dict[str, list[float]]:
    """A flat parameter vector as {field: its values}."""
    out, i = {}, 0
    for name, p in params.items():
        n = p.size
        out[name] = [float(v) for v in vector[i:i + n]]
        i += n
    return out


def shared_plant(runs: Sequence[RunData], per_joint: bool) -> dict[str, list[float]] | None:
    """The runs' plant values of the identified fields in the fit's sizes, None when the runs differ or a value
    has no form of that size (different values per joint under a shared fit)."""
    first = runs[0].plant
    if any(r.plant != first for r in runs):
        return None
    out = {}
    for name in FIELDS:
        values, size = np.atleast_1d(np.asarray(first[name], float)), field_size(name, per_joint)
        if values.size != size and np.ptp(values) > 0.0:
            return None
        out[name] = (values if values.size == size else np.full(size, values[0])).tolist()
    return out


# --------------------------------------------------------------------------------------------------- windows
def windows_of(runs: Sequence[RunData], settings: FitSettings) -> list[Windows]:
    """Each run's replay windows, at most ``settings.max_walk_s`` of walking in all."""
    left_s, groups = settings.max_walk_s, []
    for run in runs:
        ticks = max(1, round(settings.window_s / (run.physics_dt_s * run.steps_per_tick)))
        n = min(int((len(run.t_s) - 1 - run.walk_from) // ticks),
                int(round(left_s / (ticks * run.physics_dt_s * run.steps_per_tick))))
        if n <= 0:
            continue
        groups.append(run_windows(run, run.walk_from + ticks * np.arange(n), ticks))
        left_s -= n * ticks * run.physics_dt_s * run.steps_per_tick
    if not groups:
        raise ConfigError(f"identify: no walking data after the stand in {[str(r.path) for r in runs]}")
    return groups


def run_windows(run: RunData, starts: np.ndarray, ticks: int) -> Windows:
    """sysid's measured rollouts of ``run``: per window, the state of row k (initial state), the applied torques
    of the next ``ticks`` ticks per physics step, the recorded states of rows k+1..k+ticks as sensordata."""
    model = run.spec.compile()
    n, dt = run.steps_per_tick, run.physics_dt_s
    states, controls, sensors = [], [], []
    for k in starts:
        state = sysid.create_initial_state(model, run.qpos[k], run.qvel[k])
        state[0] = run.t_s[k]  # mjSTATE_FULLPHYSICS starts with the time
        steps = np.arange((k + 1) * n, (k + 1 + ticks) * n + 1)  # the last one: sysid drops it (no next state)
        applied = run.ctrl[np.clip((steps - run.delay_steps) // n, 0, len(run.ctrl) - 1)]
        controls.append(sysid.TimeSeries(run.t_s[k] + (steps - (k + 1) * n) * dt, applied))
        rows = slice(k + 1, k + 1 + ticks)
        sensors.append(sysid.TimeSeries.from_names(run.t_s[rows], np.hstack([run.qpos[rows], run.qvel[rows]]), model))
        states.append(state)
    names = [f"{run.name} t={run.t_s[k]:.3f}s" for k in starts]
    sequences = sysid.ModelSequences(run.name, run.spec, names, states, controls, sensors)
    measured = np.stack([run.qvel[k + 1:k + 1 + ticks] for k in starts])
    return Windows(run, sequences, starts, measured)


# -------------------------------------------------------------------------------------------------- residual
def replay_errors(x: np.ndarray, params: sysid.ParameterDict, groups: Sequence[Windows], threads: int
                  ) -> np.ndarray:
    """Predicted minus recorded velocities, (columns of x, windows, W, nv) for x of shape (p,) or (p, columns)."""
    xs = x.reshape(x.shape[0], -1)
    out = []
    for g in groups:
        models = []
        for c in range(xs.shape[1]):
            params.update_from_vector(xs[:, c])
            models.append(build_model(params, g.run.spec))
        out.append(rollout_qvel(g, models, threads) - g.measured_qvel[None])
    params.update_from_vector(xs[:, 0])
    return np.concatenate(out, axis=1)


def rollout_qvel(g: Windows, models: list[mujoco.MjModel], threads: int) -> np.ndarray:
    """Velocities after each tick of every window, replayed in each model: (models, windows, W, nv)."""
    seq, nw = g.sequences, len(g.starts)
    if not g.datas:
        g.datas = [mujoco.MjData(models[0]) for _ in range(threads)]
    qpos_map, qvel_map, act_map, ctrl_map = sysid.TimeSeries.compute_all_state_mappings(models[0])
    trajectories = sysid.sysid_rollout(
        models=[m for m in models for _ in range(nw)], datas=g.datas, control_signal=seq.control * len(models),
        initial_states=seq.initial_state * len(models), rollout_state_mapping=qpos_map | qvel_map | act_map,
        rollout_signal_mapping=sysid.TimeSeries.compute_all_sensor_mapping(models[0]), ctrl_mapping=ctrl_map)
    m, n = models[0], g.run.steps_per_tick
    qvel = np.stack([t.state.data[n - 1::n, 1 + m.nq:1 + m.nq + m.nv] for t in trajectories if t.state is not None])
    return qvel.reshape(len(models), nw, *qvel.shape[1:])


def weighted(errors: np.ndarray, columns: bool) -> np.ndarray:
    """The least-squares residual: errors with the trunk's linear velocity over :data:`LEVER_M`, flattened per
    column -> (n,), or (n, columns) when ``columns`` (x was 2-D: sysid's vectorised finite differences)."""
    w = np.ones(errors.shape[-1])
    w[SIGNALS["trunk_linear_velocity_mps"]] = 1.0 / LEVER_M
    r = (errors * w).reshape(errors.shape[0], -1)
    return r.T if columns else r[0]


def rms(errors: np.ndarray) -> dict[str, float]:
    """RMS replay error per signal group (first column only)."""
    return {name: float(np.sqrt(np.mean(errors[0][..., cols] ** 2))) for name, cols in SIGNALS.items()}
