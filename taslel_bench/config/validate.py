"""Validation of a composed run config: every bad value is refused with the field name (dotted config
path), the value and what is allowed, before anything is built or simulated. (Unknown group options and
unknown keys are refused by Hydra itself, with the list of valid options.)

Three layers, all run by :class:`taslel_bench.sim.build.Built` before the episode:

1. :func:`validate` -- a generic pass (no NaN or infinity anywhere in the config) and one rule per field of
   the core groups (top level, ``record``, ``controller``, ``filter``, ``robot``, ``model``); the ranges are
   the constants below. :func:`model_options` and :func:`plant_options` turn the validated ``model`` and
   ``robot`` groups into the builders' options.
2. :func:`build_axis` -- the sweep axes (``scenario``, ``solver``, ``estimator``) check their own
   constructor arguments (with :mod:`taslel_bench.util.fields`, naming ``scenario.<key>`` ...); an error raised
   inside Hydra's ``instantiate`` is turned back into a :class:`ConfigError` with that message.
3. :func:`build_backend` -- the QP backend must solve a trivial QP of the configured formulation's shape,
   which catches native solver settings the solver itself rejects.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import InterpolationResolutionError, MissingMandatoryValue

from taslel_bench.config.safety import safety_limits
from taslel_bench.control.gait import TrotScaling
from taslel_bench.filter.robust import RobustSettings
from taslel_bench.filter.safety_filter import (
    FALLBACKS,
    FORMULATIONS,
    FRICTION_CONES,
    REGULARIZATION_TARGETS,
    RELAXATIONS,
    STANCE_SOURCES,
)
from taslel_bench.interfaces import MAX_FRICTION
from taslel_bench.plant.adapter import CONES, INTEGRATORS, PlantNames, PlantOverrides
from taslel_bench.plant.perturbation import check_trunk_and_joints
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription, describe_robot
from taslel_bench.robot.model_options import ModelOptions
from taslel_bench.util.fields import ConfigError, choice, fail, flag, integer, number, numbers, plain_dict

AXES = ("scenario", "solver", "estimator")
TROT_TARGET = "taslel_bench.control.trot.trot_controller"  # conf/controller/trot.yaml's builder
LEG_REACH_FRACTION = 0.95  # [-] of the robot's thigh + calf: the farthest a foot target may be from the hip
MAX_SEED = 2**63 - 1
MAX_DURATION_S = 3600.0  # [s] one episode (and the latest filter start)
PHYSICS_RATE_RANGE_HZ = (100, 100_000)  # MuJoCo is unstable on this robot beyond 10 ms steps
MIN_CONTROL_RATE_HZ = 10
MIN_PHASE_TICKS = 2  # stance and swing each last at least this many control periods
MAX_PERIOD_S = 5.0  # [s] gait period
MAX_SWING_HEIGHT_M = 0.2  # [m]
MAX_STAND_DURATION_S = 60.0  # [s]
MAX_KP_PER_NM = 30.0  # [1/rad] joint PD stiffness at most this x the robot's largest torque limit (A1: 1005 N·m/rad)
MAX_KD_PER_NM = 3.0  # [s/rad] joint PD damping at most this x the largest torque limit (A1: 100.5 N·m·s/rad)
MAX_FOOTHOLD_SEARCH_M = 0.08  # [m] half the 0.16 m between touchdowns of one foot at the default gait
# [m] a swing that ends this far above the expected ground still lands within the stance's first 30 ms at ~0.9 m/s
MAX_TOUCHDOWN_HEIGHT_M = 0.03
MAX_LAMBDA_MIN_N = 100.0  # [N] about the A1's weight (12.5 kg): a stance foot cannot be asked for more
MAX_TORQUE_LIMIT_NM = 500.0  # [N·m] per joint (the A1's motors give 33.5, ANYmal C's 80)
MAX_JOINT_NOISE_RAD = 0.5  # [rad] std of the initial joint perturbation
MAX_BASE_VEL_NOISE_MPS = 2.0  # [m/s]
# the controller's model: the fields it shares with the plant are checked by taslel_bench/plant/perturbation.py
MAX_FRICTION_SMOOTHING_RADPS = 10.0  # [rad/s]
# plant overrides
MAX_NOSLIP_ITERATIONS = 1000
MAX_IMPRATIO = 100.0  # [-]
MAX_SOLREF_TIMECONST_S = 1.0  # [s]
MAX_SOLREF_DAMPRATIO = 10.0  # [-]
MAX_FOOT_MARGIN_M = 0.05  # [m]
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
    """The generic pass, the core groups' rules, the axes' ``_target_``."""
    check_finite(cfg)
    control_rate_hz = _top_level(cfg)
    robot = _robot(cfg)
    stand_height_m = _controller(cfg, control_rate_hz, robot)
    number("robot.fall_height_m", robot.fall_height_m, 0.0, stand_height_m, hi_open=True, unit="m",
           why="below the stand height (controller.stand_height, else robot.stand_height_m), else the stand is a fall")
    _filter(cfg, control_rate_hz)
    _meaningful(cfg)
    _memory(cfg, control_rate_hz)
    _model(cfg)
    safety_limits(cfg)  # the verdict's limits (taslel_bench/config/safety.py)
    for group in AXES:
        if not isinstance(_get(cfg, group), DictConfig) or "_target_" not in cfg[group]:
            raise fail(group, _get(cfg, group), "has no _target_ to build it from")
    if _get(cfg, "scenario.friction") is not None:  # every scenario has one (the scenario checks it too)
        number("scenario.friction", cfg.scenario.friction, 0.0, MAX_FRICTION, lo_open=True)


def _top_level(cfg: DictConfig) -> int:
    """Seed, duration, rates, flags, ``record.*``; returns the control rate [Hz]."""
    integer("seed", _get(cfg, "seed"), 0, MAX_SEED)
    number("duration", _get(cfg, "duration"), 0.0, MAX_DURATION_S, lo_open=True, unit="s")
    physics = integer("physics_rate_hz", _get(cfg, "physics_rate_hz"), *PHYSICS_RATE_RANGE_HZ, unit="Hz")
    control = integer(
        "control_rate_hz", _get(cfg, "control_rate_hz"), MIN_CONTROL_RATE_HZ, physics, unit="Hz"
    )
    if physics % control:
        raise fail(
            "control_rate_hz", control, f"must divide physics_rate_hz={physics} (valid: {_divisors(physics)})"
        )
    for key in ("force", "progress", "record.mcap", "record.qps", "record.video"):
        flag(key, _get(cfg, key, False))
    integer("record.qps_every", _get(cfg, "record.qps_every", 1), 1)
    if _get(cfg, "record.chunk_ticks", None) is not None:
        integer("record.chunk_ticks", _get(cfg, "record.chunk_ticks"), 1)
    integer("record.reference_every", _get(cfg, "record.reference_every", 10), 0)
    number("record.reference_tol_nm", _get(cfg, "record.reference_tol_nm", 1e-3), 0.0, lo_open=True, unit="N·m")
    if _get(cfg, "record.mcap_rate_hz", None) is not None:
        number("record.mcap_rate_hz", _get(cfg, "record.mcap_rate_hz"), 0.0, control, lo_open=True, unit="Hz",
               why="at most control_rate_hz; null: every tick")
    _video(cfg)
    return control


def memory_estimate_gb(cfg: DictConfig) -> float:
    """[GB] the peak resident memory a run of ``cfg`` is expected to need (see :data:`MEMORY_PER_TICK_GB`)."""
    ticks = (float(cfg.controller.stand_duration) + float(cfg.duration)) * float(cfg.control_rate_hz)
    chunk = _get(cfg, "record.chunk_ticks", None)
    if chunk is None:
        return MEMORY_BASE_GB + MEMORY_PER_TICK_GB * ticks
    return MEMORY_BASE_GB + MEMORY_PER_TICK_GB * min(int(chunk) + 1, ticks) + MEMORY_SERIES_PER_TICK_GB * ticks


def _memory(cfg: DictConfig, control_rate_hz: int) -> None:
    """Refuse a run that would need more memory than ``max_memory_gb`` (before it runs for hours and is
    killed by the OOM killer at the end)."""
    limit = number("max_memory_gb", _get(cfg, "max_memory_gb", 8.0), 0.0, 1e4, lo_open=True, unit="GB")
    need = memory_estimate_gb(cfg)
    if need > limit:
        whole = _get(cfg, "record.chunk_ticks", None) is None
        per_tick = MEMORY_PER_TICK_GB if whole else MEMORY_SERIES_PER_TICK_GB
        longest = (limit - MEMORY_BASE_GB) / (per_tick * control_rate_hz) - float(cfg.controller.stand_duration)
        held = ("record.chunk_ticks=null: the whole trace is held in memory until the end; the default chunks "
                "need far less" if whole else "record.chunk_ticks: the series of the exact percentiles grow")
        raise fail("duration", _get(cfg, "duration"),
                   f"this run needs ~{need:.1f} GB by estimate ({per_tick * 1e6:.2f} kB per control tick at "
                   f"control_rate_hz={control_rate_hz}; {held}), more than max_memory_gb={limit:g}; the longest "
                   f"run within it is ~{max(longest, 0):.0f} s (shorten the run, lower control_rate_hz, or raise "
                   f"max_memory_gb if the machine has the memory)")


def _meaningful(cfg: DictConfig) -> None:
    """Combinations whose result would not mean what it says: a filter that never runs in the episode,
    recording QPs of a filter that is off, an MCAP rate on a run without MCAP."""
    walk_end_s = float(_get(cfg, "controller.stand_duration", 0.0)) + float(_get(cfg, "duration"))
    filter_on = bool(_get(cfg, "filter.enabled"))
    start = float(_get(cfg, "filter.start_time", 0.0))
    if filter_on and start >= walk_end_s:
        raise fail("filter.start_time", _get(cfg, "filter.start_time"),
                   f"the filter would never run: the episode ends at {walk_end_s:g} s (controller.stand_duration + "
                   f"duration); the run would report filter_enabled with no filtered tick. Use a start before "
                   f"{walk_end_s:g} s, or filter.enabled=false")
    if bool(_get(cfg, "record.qps", False)) and not filter_on:
        raise fail("record.qps", True, "there is no QP to record with filter.enabled=false (set one of them)")


def _video(cfg: DictConfig) -> None:
    """``record.video_*``: frame rate and size of the rendered video."""
    integer("record.video_fps", _get(cfg, "record.video_fps", 30), 1, 240, unit="frames/s")
    for key in ("record.video_width", "record.video_height"):
        integer(key, _get(cfg, key, 480), 16, 4096, unit="px")


def _controller(cfg: DictConfig, control_rate_hz: int, robot: RobotDescription) -> float:
    """Trot parameters (null: the robot's, :class:`taslel_bench.control.gait.TrotScaling`); returns the stand
    height [m]."""
    c = "controller"
    number(f"{c}.stand_duration", _get(cfg, f"{c}.stand_duration"), 0.0, MAX_STAND_DURATION_S, unit="s")
    if _get(cfg, f"{c}._target_") != TROT_TARGET:  # another controller checks its own arguments when built
        return robot.stand_height_m
    value = _trot_values(cfg, robot)
    stand = _trot_gait(cfg, control_rate_hz, robot, value)
    _trot_gains(cfg, robot, value)
    _trot_terrain_following(cfg)
    return stand


def _trot_values(cfg: DictConfig, robot: RobotDescription) -> Callable[[str], Any]:
    """``controller.scaling`` checked; returns key -> the trot's value (the config's, else the robot's)."""
    c = "controller"
    scaling = _get(cfg, f"{c}.scaling") or {}
    _known_keys(f"{c}.scaling", scaling, TrotScaling)
    for key in (f.name for f in dataclasses.fields(TrotScaling)):
        number(f"{c}.scaling.{key}", scaling.get(key), 0.0, lo_open=True)
    defaults = TrotScaling(**{k: float(v) for k, v in scaling.items()}).values(robot.mass_kg, robot.leg_length_m,
                                                                               robot.stand_height_m)

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
    period = number(f"{c}.period", _get(cfg, f"{c}.period"), 0.0, MAX_PERIOD_S, lo_open=True, unit="s")
    duty = number(f"{c}.duty", _get(cfg, f"{c}.duty"), 0.0, 1.0, lo_open=True, hi_open=True)
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
    c = "controller"
    following = flag(f"{c}.terrain_following", _get(cfg, f"{c}.terrain_following", False))
    search = number(f"{c}.foothold_search", _get(cfg, f"{c}.foothold_search", 0.0), 0.0, MAX_FOOTHOLD_SEARCH_M,
                    unit="m", why="touchdown offsets along the heading, within the stance stroke's reach")
    if search > 0.0 and not following:
        raise fail(f"{c}.foothold_search", search, "foothold choice is part of the terrain-following nominal: "
                    "set controller.terrain_following=true, or foothold_search=0")
    replan = number(f"{c}.foothold_replan_phase", _get(cfg, f"{c}.foothold_replan_phase", 0.0), 0.0, 1.0,
                    hi_open=True, why="0 plans each touchdown at lift-off only; a swing phase in (0, 1) plans it again "
                                      "there")
    if replan > 0.0 and search == 0.0:
        raise fail(f"{c}.foothold_replan_phase", replan, "re-planning needs foothold choice: set "
                    "controller.foothold_search > 0, or foothold_replan_phase=0")
    if flag(f"{c}.swing_from_measured_hips", _get(cfg, f"{c}.swing_from_measured_hips", False)) and not following:
        raise fail(f"{c}.swing_from_measured_hips", True, "swing heights from the measured hips are part of the "
                   "terrain-following nominal: set controller.terrain_following=true, or leave it false")
    aim = number(f"{c}.touchdown_height", _get(cfg, f"{c}.touchdown_height", 0.0), 0.0, MAX_TOUCHDOWN_HEIGHT_M,
                 unit="m", why="the swing's end above the expected ground, below the swing apex")
    if aim > 0.0 and not following:
        raise fail(f"{c}.touchdown_height", aim, "the touchdown aim is part of the terrain-following nominal: set "
                   "controller.terrain_following=true, or touchdown_height=0")


def _filter(cfg: DictConfig, control_rate_hz: int) -> None:
    """The safety filter's settings; gains are bounded by the control rate (gain x control period <= 1)."""
    f = "filter"
    flag(f"{f}.enabled", _get(cfg, f"{f}.enabled"))
    flag(f"{f}.ecbf.enabled", _get(cfg, f"{f}.ecbf.enabled"))
    number(f"{f}.start_time", _get(cfg, f"{f}.start_time", 0.0), 0.0, MAX_DURATION_S, unit="s")
    number(f"{f}.regularization", _get(cfg, f"{f}.regularization"), 0.0, 1.0, lo_open=True)
    number(f"{f}.lambda_min_n", _get(cfg, f"{f}.lambda_min_n"), 0.0, MAX_LAMBDA_MIN_N, unit="N")
    rate_bound = f"gain x control period <= 1 at control_rate_hz={control_rate_hz}"
    number(
        f"{f}.contact_velocity_gain",
        _get(cfg, f"{f}.contact_velocity_gain", 0.0),
        0.0,
        control_rate_hz,
        unit="1/s",
        why=rate_bound,
    )
    for key in ("alpha1", "alpha2"):
        number(
            f"{f}.ecbf.{key}",
            _get(cfg, f"{f}.ecbf.{key}"),
            0.0,
            control_rate_hz,
            lo_open=True,
            unit="1/s",
            why=rate_bound,
        )
    choice(f"{f}.fallback", _get(cfg, f"{f}.fallback"), FALLBACKS)
    choice(
        f"{f}.regularization_target",
        _get(cfg, f"{f}.regularization_target", "nominal"),
        REGULARIZATION_TARGETS,
    )
    choice(f"{f}.formulation", _get(cfg, f"{f}.formulation", "full"), FORMULATIONS)
    choice(f"{f}.stance_source", _get(cfg, f"{f}.stance_source"), STANCE_SOURCES)
    choice(f"{f}.friction_cone", _get(cfg, f"{f}.friction_cone", "pyramid"), FRICTION_CONES)
    flag(f"{f}.cone_edge_downhill", _get(cfg, f"{f}.cone_edge_downhill", False))
    choice(f"{f}.relaxation", _get(cfg, f"{f}.relaxation", "none"), RELAXATIONS)
    for key, hi, unit in (("force_threshold_n", 1000.0, "N"), ("min_swing_phase", 1.0, "-"),
                          ("min_force_vertical_share", 1.0, "-"), ("late_touchdown_max_s", 1.0, "s")):
        value = _get(cfg, f"{f}.contact_estimate.{key}")
        if value is not None:
            number(f"{f}.contact_estimate.{key}", value, 0.0, hi, unit=unit)
    _robust(cfg)


def _robust(cfg: DictConfig) -> None:
    """``filter.robust``: the margins of taslel_bench/filter/robust.py."""
    r = "filter.robust"
    if _get(cfg, r) is None:
        return
    _known_keys(r, _get(cfg, r), RobustSettings)
    flag(f"{r}.enabled", _get(cfg, f"{r}.enabled", False))
    number(f"{r}.ecbf_margin_mps2", _get(cfg, f"{r}.ecbf_margin_mps2", 0.0), 0.0, 100.0, unit="m/s²")
    number(f"{r}.adaptive_gain", _get(cfg, f"{r}.adaptive_gain", 0.0), 0.0, 100.0)
    number(f"{r}.adaptive_time_constant_s", _get(cfg, f"{r}.adaptive_time_constant_s", 0.5), 0.0, 60.0,
           lo_open=True, unit="s")
    number(f"{r}.max_margin_mps2", _get(cfg, f"{r}.max_margin_mps2", 50.0), 0.0, 1000.0, unit="m/s²")
    number(f"{r}.friction_margin", _get(cfg, f"{r}.friction_margin", 0.0), 0.0, 1.0, hi_open=True,
           why="the pyramid uses mu (1 - friction_margin)")
    number(f"{r}.observer_time_constant_s", _get(cfg, f"{r}.observer_time_constant_s", 0.0), 0.0, 10.0,
           unit="s", why="0: no disturbance observer")


def _robot(cfg: DictConfig) -> RobotDescription:
    """The robot's description (its YAML and URDF: names, limits, stand height, fall rule), the initial-state
    noise, the plant MJCF path (read at build time); returns the description."""
    r = "robot"
    if not isinstance(_get(cfg, r), DictConfig):
        raise fail(r, _get(cfg, r), "must be a robot config (conf/robot/<name>.yaml)")
    robot = describe_robot(plain_dict(cfg.robot, r))
    if max(robot.torque_limit_nm) > MAX_TORQUE_LIMIT_NM:
        raise fail(f"{r}.torque_limit_nm", _get(cfg, f"{r}.torque_limit_nm"),
                   f"every joint's limit must be in (0, {MAX_TORQUE_LIMIT_NM:g}] N·m")
    number(f"{r}.fall_tilt_deg", robot.fall_tilt_deg, 0.0, 180.0, lo_open=True, unit="deg")
    number(f"{r}.init_joint_noise_rad", robot.init_joint_noise_rad, 0.0, MAX_JOINT_NOISE_RAD, unit="rad")
    number(f"{r}.init_base_vel_noise_mps", robot.init_base_vel_noise_mps, 0.0, MAX_BASE_VEL_NOISE_MPS, unit="m/s")
    mjcf = _get(cfg, f"{r}.plant_mjcf")
    if mjcf is not None and not (isinstance(mjcf, str) and mjcf.strip()):
        raise fail(f"{r}.plant_mjcf", mjcf, "must be null or the path of an MJCF file")
    _known_keys(f"{r}.plant_names", _get(cfg, f"{r}.plant_names"), PlantNames)
    _known_keys(f"{r}.plant_overrides", _get(cfg, f"{r}.plant_overrides"), PlantOverrides)
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
    """``robot.plant_overrides``: null keeps the plant file's (or the URDF plant's) value."""
    p = "robot.plant_overrides"
    if (v := _get(cfg, f"{p}.integrator")) is not None:
        choice(f"{p}.integrator", v, INTEGRATORS)
    if (v := _get(cfg, f"{p}.cone")) is not None:
        choice(f"{p}.cone", v, CONES)
    if (v := _get(cfg, f"{p}.noslip_iterations")) is not None:
        integer(f"{p}.noslip_iterations", v, 0, MAX_NOSLIP_ITERATIONS)
    if (v := _get(cfg, f"{p}.impratio")) is not None:
        number(f"{p}.impratio", v, 0.0, MAX_IMPRATIO, lo_open=True)
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
    if (v := _get(cfg, f"{p}.foot_margin_m")) is not None:
        number(f"{p}.foot_margin_m", v, 0.0, MAX_FOOT_MARGIN_M, unit="m")


def _known_keys(path: str, group: Any, cls: type) -> None:
    """Refuse keys of ``group`` (a config node or None) that ``cls`` (a dataclass) has no field for."""
    if isinstance(group, DictConfig):
        valid = [f.name for f in dataclasses.fields(cls)]
        for key in group:
            if key not in valid:
                raise fail(f"{path}.{key}", _raw(group, str(key)),
                           f"unknown field; valid: {', '.join(valid)}")


def _model(cfg: DictConfig) -> None:
    """The controller's model (``model`` group; absent = the URDF as is)."""
    m = "model"
    _known_keys(m, _get(cfg, m), ModelOptions)
    urdf = _get(cfg, f"{m}.urdf")
    if urdf is not None and not (isinstance(urdf, str) and urdf.strip() and Path(urdf).is_file()):
        raise fail(f"{m}.urdf", urdf, "must be null (the robot's URDF) or the path of an existing "
                                      "URDF")
    shared = ("trunk_mass_scale", "trunk_com_shift_m", "payload_mass_kg", "payload_pos_m", "joint_damping",
              "armature", "joint_frictionloss")  # the plant perturbation's fields, checked by the same rules
    given = {key: _get(cfg, f"{m}.{key}") for key in shared}
    check_trunk_and_joints(m, {key: value for key, value in given.items() if value is not None})
    number(f"{m}.frictionloss_smoothing_radps", _get(cfg, f"{m}.frictionloss_smoothing_radps", 0.05), 0.0,
           MAX_FRICTION_SMOOTHING_RADPS, lo_open=True, unit="rad/s")
    number(f"{m}.implicit_damping_dt_s", _get(cfg, f"{m}.implicit_damping_dt_s", 0.0), 0.0, 0.1, unit="s",
           why="0: continuous model; the plant's time step when it integrates joint damping implicitly")

def _divisors(n: int) -> str:
    divs = [k for k in range(1, n + 1) if n % k == 0]
    return ", ".join(map(str, divs[:12])) + (" ..." if len(divs) > 12 else "")


# ------------------------------------------------------------------------------------------ the axes


__all__ = ["ConfigError", "check_finite", "memory_estimate_gb", "validate"]
