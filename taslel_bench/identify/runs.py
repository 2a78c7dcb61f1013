"""A recorded run as identification data: the model to fit (the run's plant with the identified fields at the
URDF's values) and the run's states and commanded torques in MuJoCo's order.

Frames and units of the recorded state (``steps.parquet``, one row per control tick, the plant's state *after* that
tick's physics steps): base position [m] and quaternion (w, x, y, z) of the trunk frame in the world; base linear
velocity [m/s] in world axes; base angular velocity [rad/s] in the trunk frame; joint angles [rad] and velocities
[rad/s]; ``u_*`` the commanded joint torques [N·m] of the tick. These are MuJoCo's free-joint ``qpos``/``qvel``
conventions, so a row is a MuJoCo state as it is (joints permuted by name into MuJoCo's order).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from taslel_bench.config.axes import build_axis
from taslel_bench.config.schema import load_run_config
from taslel_bench.config.settings import plant_options, robot_description
from taslel_bench.record import run_files
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.build import build_plant_spec
from taslel_bench.util.fields import ConfigError

# the identified fields at the URDF's values: the plant perturbation's "unchanged"
URDF_VALUES: dict[str, Any] = {"joint_damping": 0.0, "armature": 0.0, "joint_frictionloss": 0.0,
                               "trunk_mass_scale": 1.0, "trunk_com_shift_m": [0.0, 0.0, 0.0]}
FIELDS = tuple(URDF_VALUES)
RUN_CONFIG = "config.yaml"
TRUNK_SITE = "identify_trunk"  # a site at the trunk frame's origin, axes along the trunk frame's
BASE_POS = [f"base_{a}_w_m" for a in "xyz"] + [f"base_quat_{c}" for c in "wxyz"]  # [m], [-] world
BASE_VEL = [f"base_v{a}_w_mps" for a in "xyz"] + [f"base_w{a}_b_radps" for a in "xyz"]  # [m/s] world, [rad/s] trunk


@dataclass(frozen=True)
class RunData:
    """One run folder's identification data. Arrays have one row per control tick."""

    path: Path
    spec: mujoco.MjSpec  # the run's plant, identified fields at the URDF's values, state sensors (state_sensors)
    physics_dt_s: float  # [s]
    steps_per_tick: int  # physics steps per control tick
    delay_steps: int  # [physics steps] the plant's actuator delay (run config, known)
    t_s: np.ndarray  # (N,) [s]
    qpos: np.ndarray  # (N, nq) MuJoCo order
    qvel: np.ndarray  # (N, nv) MuJoCo order
    ctrl: np.ndarray  # (N, nu) [N·m] commanded, MuJoCo actuator order
    walk_from: int  # first row after the stand
    plant: dict[str, Any]  # the run config's values of the identified fields (the URDF's where it sets none)

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def walking_s(self) -> float:
        """[s] recorded time after the stand."""
        return float(len(self.t_s) - self.walk_from) * self.physics_dt_s * self.steps_per_tick


def load_run(path: Path) -> RunData:
    """The identification data of the run folder ``path`` (config.yaml, steps.parquet); a folder that is not a
    complete run, or a run on another plant file (``robot.plant_mjcf``), raises :class:`ConfigError` naming it."""
    path = Path(path)
    for name in (RUN_CONFIG, run_files.STEPS):
        if not (path / name).is_file():
            raise ConfigError(f"{path}: not a run folder (no {name})")
    cfg = load_run_config(path / RUN_CONFIG)
    if cfg.robot.plant_mjcf is not None:
        raise ConfigError(f"{path}: robot.plant_mjcf={cfg.robot.plant_mjcf!r}: identification fits values added to "
                          "the robot's URDF (as the model group's fields are); runs on the URDF plant only")
    spec = nominal_spec(cfg)
    model = spec.compile()
    steps = pd.read_parquet(path / run_files.STEPS)
    qpos, qvel, ctrl = recorded_state(model, steps, path)
    ticks = round(float(cfg.physics_rate_hz) / float(cfg.control_rate_hz))
    t_s = steps["t_s"].to_numpy(float)
    stand_s = float(OmegaConf.select(cfg, "controller.stand_duration", default=0.0) or 0.0)
    return RunData(path=path, spec=spec, physics_dt_s=float(model.opt.timestep), steps_per_tick=ticks,
                   delay_steps=int(OmegaConf.select(cfg, "scenario.actuator_delay_steps", default=0) or 0),
                   t_s=t_s, qpos=qpos, qvel=qvel, ctrl=ctrl, walk_from=int(np.searchsorted(t_s, stand_s - 1e-9)),
                   plant=plant_values(cfg))  # fmt: skip


def plant_values(cfg: DictConfig) -> dict[str, Any]:
    """The run's plant values of the identified fields: the scenario's where it sets them, else the URDF's."""
    scenario = OmegaConf.to_container(cfg.scenario, resolve=True)
    assert isinstance(scenario, dict)
    return {key: copy.deepcopy(scenario.get(key, default)) for key, default in URDF_VALUES.items()}


def nominal_spec(cfg: DictConfig) -> mujoco.MjSpec:
    """The run's plant spec (its robot, options, terrain and scenario edits) with the identified fields at the
    URDF's values (the plant's other edits, e.g. motor strength, stay: known), its sensors replaced by
    :func:`state_sensors`."""
    nominal = copy.deepcopy(cfg)
    for key, value in URDF_VALUES.items():
        if key in nominal.scenario:
            nominal.scenario[key] = value
    robot = robot_description(nominal)
    scenario = build_axis(nominal, "scenario")
    spec = build_plant_spec(scenario, plant_options(nominal, robot), int(nominal.seed),
                            np.random.default_rng(int(nominal.seed)), None, robot)
    state_sensors(spec)
    return spec


def state_sensors(spec: mujoco.MjSpec) -> None:
    """Replace the spec's sensors by ones whose ``sensordata`` is the state ``[qpos, qvel]`` of the free-floating
    robot (so recorded states are sysid's measured signals): trunk frame position and quaternion (world), each
    hinge's angle, the trunk frame origin's linear velocity (world axes), the trunk's angular velocity (trunk
    frame, a gyro at a site on the trunk frame), each hinge's velocity."""
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    order = [spec.compile().joint(i).name for i in range(len(spec.joints))]
    hinges = [name for name in order if spec.joint(name).type == mujoco.mjtJoint.mjJNT_HINGE]
    if len(hinges) != len(order) - 1:
        raise ConfigError(f"identification needs a free joint and hinges; the plant has joints {order}")
    trunk = spec.body(quad.TRUNK_BODY)
    trunk.add_site(name=TRUNK_SITE, pos=[0.0, 0.0, 0.0])
    xbody = mujoco.mjtObj.mjOBJ_XBODY
    spec.add_sensor(name="trunk_pos", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=xbody, objname=quad.TRUNK_BODY)
    spec.add_sensor(name="trunk_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=xbody, objname=quad.TRUNK_BODY)
    for name in hinges:
        spec.add_sensor(name=f"{name}_pos", type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT,
                        objname=name)
    spec.add_sensor(name="trunk_linvel", type=mujoco.mjtSensor.mjSENS_FRAMELINVEL, objtype=xbody,
                    objname=quad.TRUNK_BODY)
    spec.add_sensor(name="trunk_gyro", type=mujoco.mjtSensor.mjSENS_GYRO, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=TRUNK_SITE)
    for name in hinges:
        spec.add_sensor(name=f"{name}_vel", type=mujoco.mjtSensor.mjSENS_JOINTVEL, objtype=mujoco.mjtObj.mjOBJ_JOINT,
                        objname=name)


def recorded_state(model: mujoco.MjModel, steps: pd.DataFrame, path: Path) -> tuple[np.ndarray, ...]:
    """(qpos, qvel, commanded ctrl) of every row of ``steps``, MuJoCo's order (joints and actuators by name)."""
    short = {name: name.removesuffix("_joint") for name in quad.JOINT_NAMES}
    columns = BASE_POS + BASE_VEL + [f"{p}_{short[n]}_{u}" for n in quad.JOINT_NAMES
                                     for p, u in (("q", "rad"), ("qd", "radps"), ("u", "nm"))]
    if missing := [c for c in columns if c not in steps.columns]:
        raise ConfigError(f"{path / run_files.STEPS}: no column {missing[0]} (a run of another version?)")
    qpos, qvel = np.zeros((len(steps), model.nq)), np.zeros((len(steps), model.nv))
    qpos[:, :7], qvel[:, :6] = steps[BASE_POS].to_numpy(float), steps[BASE_VEL].to_numpy(float)
    for name in quad.JOINT_NAMES:
        joint = model.joint(name)
        qpos[:, joint.qposadr[0]] = steps[f"q_{short[name]}_rad"].to_numpy(float)
        qvel[:, joint.dofadr[0]] = steps[f"qd_{short[name]}_radps"].to_numpy(float)
    ctrl = np.zeros((len(steps), model.nu))
    for a in range(model.nu):
        joint = model.joint(int(model.actuator_trnid[a, 0])).name
        ctrl[:, a] = steps[f"u_{short[joint]}_nm"].to_numpy(float)
    return qpos, qvel, ctrl
