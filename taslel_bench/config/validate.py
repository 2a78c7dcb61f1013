"""Validation of a composed run config: every bad value is refused with the field name (dotted config
path), the value and what is allowed, before anything is built or simulated.

Hydra refuses, while composing, an unknown group option, a key the schema (:mod:`taslel_bench.config.schema`) does
not have and a value of the wrong type. Then, all run by :class:`taslel_bench.sim.build.Built` before the episode:

1. :func:`validate` -- no NaN or infinity anywhere in the config; every field's range from the schema
   (:func:`taslel_bench.util.params.check_fields`: the top level, ``record``, ``health``, ``safety``, ``robot``,
   ``model``, ``filter`` and the controller's schema); then the rules between keys and those that depend on the
   robot (the trot's reach and gains, the fall height below the stand, the memory a run needs).
2. :func:`build_axis` -- the sweep axes (``scenario``, ``solver``, ``estimator``) check their own
   constructor arguments (with :mod:`taslel_bench.util.fields`, naming ``scenario.<key>`` ...); an error raised
   inside Hydra's ``instantiate`` is turned back into a :class:`ConfigError` with that message.
3. :func:`build_backend` -- the QP backend must solve a trivial QP of the configured formulation's shape,
   which catches native solver settings the solver itself rejects.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import InterpolationResolutionError, MissingMandatoryValue

from taslel_bench.config.compose import CONF_DIR
from taslel_bench.config.model_file import model_values
from taslel_bench.config.schema import CONTROLLER_SCHEMAS, POLICY_TARGET, TROT_TARGET, RunConfig
from taslel_bench.control.gait import TrotScaling
from taslel_bench.control.policy import OnnxPolicy
from taslel_bench.control.policy_contract import contract_from_mapping
from taslel_bench.interfaces import MAX_FRICTION
from taslel_bench.plant.perturbation import check_trunk_and_joints
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription, describe_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.util.fields import ConfigError, choice, fail, number, numbers, plain_dict
from taslel_bench.util.params import check_fields

AXES = ("scenario", "solver", "estimator")
LEG_REACH_FRACTION = 0.95  # [-] of the robot's thigh + calf: the farthest a foot target may be from the hip
MIN_PHASE_TICKS = 2  # stance and swing each last at least this many control periods
MAX_SWING_HEIGHT_M = 0.2  # [m] the trot's swing apex (given or from controller.scaling)
MAX_KP_PER_NM = 30.0  # [1/rad] joint PD stiffness at most this x the robot's largest torque limit (A1: 1005 N·m/rad)
MAX_KD_PER_NM = 3.0  # [s/rad] joint PD damping at most this x the largest torque limit (A1: 100.5 N·m·s/rad)
MAX_TORQUE_LIMIT_NM = 500.0  # [N·m] per joint (the A1's motors give 33.5, ANYmal C's 80)
MAX_SOLREF_TIMECONST_S = 1.0  # [s] plant override
MAX_SOLREF_DAMPRATIO = 10.0  # [-] plant override
# peak resident memory of one run [GB] = base + per tick x control ticks held in memory. record.chunk_ticks=null
# holds the whole trace until the end: fitted to runs of 10 / 60 / 300 s at 1 kHz, record.mcap on (peak 0.41 /
# 0.65 / 1.60 GB; studies/notes/reliability.md). In chunks (the default) the trace holds one chunk, and what
# grows with the run is the 1-D series of the exact percentiles (taslel_bench.metrics.stream) and the
# parquet footer: MEMORY_SERIES_PER_TICK_GB per tick (docs/guides/reliability.md gives the measured peaks)
MEMORY_BASE_GB = 0.40
MEMORY_PER_TICK_GB = 4.0e-6
MEMORY_SERIES_PER_TICK_GB = 2.5e-7


def _get(cfg: DictConfig, path: str, default: Any = None) -> Any:
    """The value at a dotted path (None, or ``default``, when absent; interpolation errors propagate)."""
    return OmegaConf.select(cfg, path, default=default, throw_on_missing=True)


def _leaves(node: Any, path: str) -> Iterator[tuple[str, Any]]:
    """(dotted path, value) of every leaf under ``node`` at ``path`` (list entries as ``path[i]``)."""
    if isinstance(node, DictConfig):
        for key in node:
            yield from _leaves(node[key], f"{path}.{key}")
    elif isinstance(node, ListConfig):
        for i, item in enumerate(node):
            yield from _leaves(item, f"{path}[{i}]")
    else:
        yield path, node


def check_finite(cfg: DictConfig) -> None:
    """The generic pass: no field anywhere in the run config (axis settings included) may be NaN or
    infinite -- no field of this harness has a meaning for them; null is the "not set" value."""
    for group in (key for key in cfg if key != "hydra"):
        for path, value in _leaves(cfg[group], str(group)):
            if isinstance(value, float) and not math.isfinite(value):
                raise fail(path, value, "must be finite (NaN and infinity are refused in every field)")


def validate(cfg: DictConfig) -> None:
    """Raise :class:`ConfigError` on the first invalid field of the core groups (see module doc); a value
    that cannot be resolved (``seed=${oops}``, a missing ``???``) is one too."""
    try:
        _validate(cfg)
    except (InterpolationResolutionError, MissingMandatoryValue) as exc:
        path = str(getattr(exc, "full_key", "") or "")
        raise fail(path, _raw(cfg, path), f"cannot be resolved: {str(exc).splitlines()[0]}") from exc


def _raw(cfg: DictConfig, path: str) -> Any:
    """The unresolved value at ``path`` (``a.b[0].c``), e.g. the text of a broken interpolation."""
    node: Any = cfg
    try:
        for part in re.findall(r"[^.\[\]]+", path):
            node = node._get_node(int(part) if isinstance(node, ListConfig) else part)
        return node._value()
    except Exception:  # only for the message
        return "?"


def _validate(cfg: DictConfig) -> None:
    """The generic pass, the schema's ranges, the rules between keys, the axes' ``_target_``."""
    check_finite(cfg)
    _schema(cfg)
    control_rate_hz = _rates(cfg)
    robot = _robot(cfg)
    stand_height_m = _controller(cfg, control_rate_hz, robot)
    number("robot.fall_height_m", robot.fall_height_m, 0.0, stand_height_m, hi_open=True, unit="m",
           why="below the stand height (controller.stand_height, else robot.stand_height_m), else the stand is a fall")
    _meaningful(cfg)
    _memory(cfg, control_rate_hz)
    _model(cfg)
    for group in AXES:
        if not isinstance(_get(cfg, group), DictConfig) or "_target_" not in cfg[group]:
            raise fail(group, _get(cfg, group), "has no _target_ to build it from")
    if _get(cfg, "scenario.friction") is not None:  # every scenario has one (the scenario checks it too)
        number("scenario.friction", cfg.scenario.friction, 0.0, MAX_FRICTION, lo_open=True)


def _schema(cfg: DictConfig) -> None:
    """Every field's type and range from the schema, the controller's by its ``_target_``."""
    def bound(key: str) -> Any:
        return _get(cfg, key)

    check_fields("", cfg, RunConfig, bound)
    controller_schema = CONTROLLER_SCHEMAS.get(str(_get(cfg, "controller._target_")))
    if controller_schema is not None:  # another controller checks its own arguments when built
        check_fields("controller", cfg.controller, controller_schema, bound)


def _rates(cfg: DictConfig) -> int:
    """The control rate must divide the physics rate; returns the control rate [Hz]."""
    physics, control = int(cfg.physics_rate_hz), int(cfg.control_rate_hz)
    if physics % control:
        raise fail(
            "control_rate_hz", control, f"must divide physics_rate_hz={physics} (valid: {_divisors(physics)})"
        )
    return control


def memory_estimate_gb(cfg: DictConfig) -> float:
    """[GB] the peak resident memory a run of ``cfg`` is expected to need (see :data:`MEMORY_PER_TICK_GB`)."""
    ticks = (float(cfg.controller.stand_duration) + float(cfg.duration)) * float(cfg.control_rate_hz)
    chunk = cfg.record.chunk_ticks
    if chunk is None:
        return MEMORY_BASE_GB + MEMORY_PER_TICK_GB * ticks
    return MEMORY_BASE_GB + MEMORY_PER_TICK_GB * min(int(chunk) + 1, ticks) + MEMORY_SERIES_PER_TICK_GB * ticks


def _memory(cfg: DictConfig, control_rate_hz: int) -> None:
    """Refuse a run that would need more memory than ``max_memory_gb`` (before it runs for hours and is
    killed by the OOM killer at the end)."""
    limit = float(cfg.max_memory_gb)
    need = memory_estimate_gb(cfg)
    if need > limit:
        whole = cfg.record.chunk_ticks is None
        per_tick = MEMORY_PER_TICK_GB if whole else MEMORY_SERIES_PER_TICK_GB
        longest = (limit - MEMORY_BASE_GB) / (per_tick * control_rate_hz) - float(cfg.controller.stand_duration)
        held = ("record.chunk_ticks=null: the whole trace is held in memory until the end; the default chunks "
                "need far less" if whole else "record.chunk_ticks: the series of the exact percentiles grow")
        raise fail("duration", cfg.duration,
                   f"this run needs ~{need:.1f} GB by estimate ({per_tick * 1e6:.2f} kB per control tick at "
                   f"control_rate_hz={control_rate_hz}; {held}), more than max_memory_gb={limit:g}; the longest "
                   f"run within it is ~{max(longest, 0):.0f} s (shorten the run, lower control_rate_hz, or raise "
                   f"max_memory_gb if the machine has the memory)")


def _meaningful(cfg: DictConfig) -> None:
    """Combinations whose result would not mean what it says: a filter that never runs in the episode,
    recording QPs of a filter that is off."""
    walk_end_s = float(cfg.controller.stand_duration) + float(cfg.duration)
    filter_on = bool(cfg.filter.enabled)
    start = float(cfg.filter.start_time)
    if filter_on and start >= walk_end_s:
        raise fail("filter.start_time", cfg.filter.start_time,
                   f"the filter would never run: the episode ends at {walk_end_s:g} s (controller.stand_duration + "
                   f"duration); the run would report filter_enabled with no filtered tick. Use a start before "
                   f"{walk_end_s:g} s, or filter.enabled=false")
    if cfg.record.qps and not filter_on:
        raise fail("record.qps", True, "there is no QP to record with filter.enabled=false (set one of them)")
    if cfg.filter.cone_edge_along_nominal and cfg.filter.friction_cone != "terrain":
        raise fail("filter.cone_edge_along_nominal", True,
                   f"turns the terrain cone's pyramids; filter.friction_cone={cfg.filter.friction_cone} keeps the "
                   f"paper's (world x). Use filter.friction_cone=terrain, or filter=terrain_release")


def shipped_policies() -> list[str]:
    """The policies of ``conf/policy/`` (their names)."""
    return sorted(p.stem for p in (CONF_DIR / "policy").glob("*.yaml"))


def _policy(cfg: DictConfig, control_rate_hz: int, robot: RobotDescription) -> float:
    """``controller=policy``: the contract of the ``policy`` group (its keys, the robot, the rate, the ONNX file
    and its sizes), the command and the plan's hysteresis; returns the stand height [m] of its default pose."""
    if not isinstance(_get(cfg, "policy"), DictConfig):
        raise fail("policy", _get(cfg, "policy"), "controller=policy needs a policy: policy=<name> of conf/policy/ "
                   f"(shipped: {', '.join(shipped_policies()) or 'none'}); a policy of your own: "
                   "docs/guides/learned-policy.md")
    where = f"policy={cfg.policy.get('name', '?')}"
    contract = contract_from_mapping(plain_dict(cfg.policy, "policy"), where)
    if contract.robot != robot.name:
        raise fail("robot.name", robot.name, f"the policy {contract.name!r} was trained for robot "
                   f"{contract.robot!r}: set robot={contract.robot}")
    ticks = control_rate_hz / contract.rate_hz
    if abs(ticks - round(ticks)) > 1e-9:
        raise fail("control_rate_hz", control_rate_hz, f"must be a whole multiple of the policy's rate_hz="
                   f"{contract.rate_hz:g} ({where})")
    OnnxPolicy(contract, where)  # the file, its hash and its input and output sizes
    numbers("controller.command", cfg.controller.command, -5.0, 5.0, length=3, unit="m/s, m/s, rad/s")
    plan = cfg.controller.plan
    if not float(plan.liftoff_force_n) < float(plan.touchdown_force_n):
        raise fail("controller.plan.liftoff_force_n", plan.liftoff_force_n,
                   f"must be below controller.plan.touchdown_force_n={plan.touchdown_force_n} [N] (the hysteresis)")
    kin = LegKinematics(robot)
    pose = np.asarray(contract.default_pose)[contract.core_from_policy]
    return float(-np.mean([kin.leg_fk(i, pose[3 * i: 3 * i + 3])[2] for i in range(quad.N_LEGS)]))


def _controller(cfg: DictConfig, control_rate_hz: int, robot: RobotDescription) -> float:
    """Trot parameters (null: the robot's, :class:`taslel_bench.control.gait.TrotScaling`); returns the stand
    height [m]."""
    if _get(cfg, "controller._target_") == POLICY_TARGET:
        return _policy(cfg, control_rate_hz, robot)
    if _get(cfg, "controller._target_") != TROT_TARGET:  # another controller checks its own arguments when built
        return robot.stand_height_m
    value = _trot_values(cfg, robot)
    stand = _trot_gait(cfg, control_rate_hz, robot, value)
    _trot_gains(cfg, robot, value)
    _trot_terrain_following(cfg)
    return stand


def _trot_values(cfg: DictConfig, robot: RobotDescription) -> Callable[[str], Any]:
    """Key -> the trot's value (the config's, else the robot's from ``controller.scaling``)."""
    c = "controller"
    scaling = cfg.controller.scaling
    defaults = TrotScaling(**{str(k): float(v) for k, v in scaling.items()}).values(
        robot.mass_kg, robot.leg_length_m, robot.stand_height_m)

    def value(key: str) -> Any:
        got = _get(cfg, f"{c}.{key}")
        return defaults[key] if got is None else got

    return value


def _trot_gait(cfg: DictConfig, control_rate_hz: int, robot: RobotDescription, value: Callable[[str], Any]) -> float:
    """Stand and swing heights, period, duty and speed within the robot's leg reach; returns the stand height [m]."""
    c = "controller"
    reach = LEG_REACH_FRACTION * robot.leg_length_m  # [m]
    stand = number(f"{c}.stand_height", value("stand_height"), 0.25 * reach, reach, unit="m",
                   why=f"leg reach of robot={robot.name} ({reach:.3g} m)")
    swing = number(f"{c}.swing_height", value("swing_height"), 0.0, MAX_SWING_HEIGHT_M, unit="m")
    if stand + swing > reach + 0.1:
        raise fail(
            f"{c}.swing_height",
            swing,
            f"too high for the leg: stand_height + swing_height must be <= {reach + 0.1:g} m",
        )
    period, duty = float(cfg.controller.period), float(cfg.controller.duty)  # in range (the schema's)
    shortest_s = period * min(duty, 1.0 - duty)
    if shortest_s * control_rate_hz < MIN_PHASE_TICKS:
        blamed = ("duty", duty) if 0.5 * period * control_rate_hz >= MIN_PHASE_TICKS else ("period", period)
        raise fail(
            f"{c}.{blamed[0]}",
            blamed[1],
            f"at period={period:g} s and duty={duty:g} the shorter of stance "
            f"and swing lasts {shortest_s:g} s; it must last >= {MIN_PHASE_TICKS} control periods "
            f"({MIN_PHASE_TICKS / control_rate_hz:g} s)",
        )
    max_speed = 2.0 * math.sqrt(max(reach**2 - stand**2, 0.0)) / (period * duty)
    number(
        f"{c}.speed",
        value("speed"),
        0.0,
        max_speed,
        unit="m/s",
        why=f"the stance stroke speed x period x duty must stay within the leg's reach at "
        f"stand_height={stand:g} m, period={period:g} s, duty={duty:g}",
    )
    return stand


def _trot_gains(cfg: DictConfig, robot: RobotDescription, value: Callable[[str], Any]) -> None:
    """The joint PD gains within the robot's torque scale."""
    c = "controller"
    torque = max(robot.torque_limit_nm)  # [N·m]
    scaled = "" if _get(cfg, f"{c}.kp") is not None else " (from controller.scaling)"
    number(f"{c}.kp", value("kp"), 0.0, MAX_KP_PER_NM * torque, unit="N·m/rad",
           why=f"at most {MAX_KP_PER_NM:g} x robot={robot.name}'s largest torque limit{scaled}")
    scaled = "" if _get(cfg, f"{c}.kd") is not None else " (from controller.scaling)"
    number(f"{c}.kd", value("kd"), 0.0, MAX_KD_PER_NM * torque, unit="N·m·s/rad",
           why=f"at most {MAX_KD_PER_NM:g} x robot={robot.name}'s largest torque limit{scaled}")


def _trot_terrain_following(cfg: DictConfig) -> None:
    """The terrain-following options (beyond the paper) and what each needs."""
    c = cfg.controller
    following = bool(c.terrain_following)
    if c.foothold_search > 0.0 and not following:
        raise fail("controller.foothold_search", c.foothold_search, "foothold choice is part of the "
                   "terrain-following nominal: set controller.terrain_following=true, or foothold_search=0")
    if c.foothold_replan_phase > 0.0 and c.foothold_search == 0.0:
        raise fail("controller.foothold_replan_phase", c.foothold_replan_phase, "re-planning needs foothold "
                   "choice: set controller.foothold_search > 0, or foothold_replan_phase=0")
    if c.swing_from_measured_hips and not following:
        raise fail("controller.swing_from_measured_hips", True, "swing heights from the measured hips are part of "
                   "the terrain-following nominal: set controller.terrain_following=true, or leave it false")
    if c.touchdown_height > 0.0 and not following:
        raise fail("controller.touchdown_height", c.touchdown_height, "the touchdown aim is part of the "
                   "terrain-following nominal: set controller.terrain_following=true, or touchdown_height=0")


def _robot(cfg: DictConfig) -> RobotDescription:
    """The robot's description (its YAML and URDF: names, limits, stand height, fall rule), the plant MJCF path
    (read at build time), the plant's names and overrides; returns the description."""
    r = "robot"
    robot = describe_robot(plain_dict(cfg.robot, r))
    if max(robot.torque_limit_nm) > MAX_TORQUE_LIMIT_NM:
        raise fail(f"{r}.torque_limit_nm", _get(cfg, f"{r}.torque_limit_nm"),
                   f"every joint's limit must be in (0, {MAX_TORQUE_LIMIT_NM:g}] N·m")
    mjcf = _get(cfg, f"{r}.plant_mjcf")
    if mjcf is not None and not mjcf.strip():
        raise fail(f"{r}.plant_mjcf", mjcf, "must be null or the path of an MJCF file")
    _plant_names(cfg, has_file=mjcf is not None)
    _plant_overrides(cfg)
    return robot


def _optional_name(path: str, value: Any) -> None:
    if value is not None and not (isinstance(value, str) and value.strip()):
        raise fail(path, value, "must be null or a name")


def _plant_names(cfg: DictConfig, has_file: bool) -> None:
    """``robot.plant_names``: per kind null, a pattern with {leg} (and {joint}) or {core name: file name}."""
    p = "robot.plant_names"
    kinds = (("joints", quad.JOINT_NAMES), ("actuators", quad.JOINT_NAMES), ("feet", quad.FOOT_FRAMES))
    for kind, cores in kinds:
        path, value = f"{p}.{kind}", _get(cfg, f"{p}.{kind}")
        if value is not None and not has_file:
            raise fail(path, value, "is only used with robot.plant_mjcf (set it, or leave this null)")
        if value is None:
            continue
        placeholders = "{leg}" + (" and {joint}" if kind != "feet" else "")
        if isinstance(value, str):
            try:
                names = {value.format(leg=c.split("_")[0], joint=c.split("_")[1]) for c in cores}
            except (KeyError, IndexError, ValueError) as exc:
                raise fail(path, value, f"a pattern may use only {placeholders} ({exc!r})") from None
            if len(names) != len(cores):
                raise fail(path, value, f"a pattern must give {len(cores)} different names: use "
                                        f"{placeholders}")
        elif isinstance(value, DictConfig):
            for core, name in value.items():
                choice(f"{path} key", core, cores)
                _optional_name(f"{path}.{core}", name)
        else:
            raise fail(path, value, f"must be null, a pattern with {placeholders}, or "
                                    f"{{core name: name in the file}}")
    for key in ("trunk", "floor"):
        value = _get(cfg, f"{p}.{key}")
        _optional_name(f"{p}.{key}", value)
        if value is not None and not has_file:
            raise fail(f"{p}.{key}", value, "is only used with robot.plant_mjcf (set it, or leave this null)")


def _plant_overrides(cfg: DictConfig) -> None:
    """``robot.plant_overrides``' contact parameters, entry by entry (the other keys: the schema's ranges)."""
    p = "robot.plant_overrides"
    if (v := _get(cfg, f"{p}.contact_solref")) is not None:
        numbers(f"{p}.contact_solref", v, length=2, why="[timeconst s, dampratio]")
        number(f"{p}.contact_solref[0]", v[0], 0.0, MAX_SOLREF_TIMECONST_S, lo_open=True, unit="s",
               why="timeconst")
        number(f"{p}.contact_solref[1]", v[1], 0.0, MAX_SOLREF_DAMPRATIO, lo_open=True, why="dampratio")
    if (v := _get(cfg, f"{p}.contact_solimp")) is not None:
        numbers(f"{p}.contact_solimp", v, length=5, why="[dmin, dmax, width m, midpoint, power]")
        for i, (key, lo, hi, hi_open) in enumerate((("dmin", 0.0, 1.0, True), ("dmax", 0.0, 1.0, True),
                                                     ("width", 0.0, 1.0, False), ("midpoint", 0.0, 1.0, True),
                                                     ("power", 1.0, 10.0, False))):  # fmt: skip
            number(f"{p}.contact_solimp[{i}]", v[i], lo, hi, lo_open=True, hi_open=hi_open, why=key)
        if v[0] > v[1]:
            raise fail(f"{p}.contact_solimp", v, "dmin must be <= dmax")


def _model(cfg: DictConfig) -> None:
    """The controller's model: its URDF and the fields it shares with the plant perturbations."""
    m = "model"
    urdf = _get(cfg, f"{m}.urdf")
    if urdf is not None and not (isinstance(urdf, str) and urdf.strip() and Path(urdf).is_file()):
        raise fail(f"{m}.urdf", urdf, "must be null (the robot's URDF) or the path of an existing "
                                      "URDF")
    shared = ("trunk_mass_scale", "trunk_com_shift_m", "payload_mass_kg", "payload_pos_m", "joint_damping",
              "armature", "joint_frictionloss")  # the plant perturbation's fields, checked by the same rules
    given = model_values(cfg)  # with model.from's file applied (its values checked, naming the file)
    check_trunk_and_joints(m, {key: given[key] for key in shared if given[key] is not None})


def _divisors(n: int) -> str:
    divs = [k for k in range(1, n + 1) if n % k == 0]
    return ", ".join(map(str, divs[:12])) + (" ..." if len(divs) > 12 else "")


# ------------------------------------------------------------------------------------------ the axes


__all__ = ["ConfigError", "check_finite", "memory_estimate_gb", "validate"]
