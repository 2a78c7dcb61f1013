"""Validation of a composed run config: every bad value is refused with the field name, the value and
what is allowed, before anything is built or simulated. (Unknown group options and unknown keys are
refused by Hydra itself, with the list of valid options.)"""

from __future__ import annotations

import math
from typing import Any

from omegaconf import DictConfig

from taslel_bench.safety_filter import FALLBACKS, FORMULATIONS, REGULARIZATION_TARGETS

STANCE_SOURCES = ("schedule", "contact")
MAX_LEG_REACH_M = 0.38  # [m] thigh + calf minus a margin


class ConfigError(ValueError):
    """A config value is invalid; the message names the field."""


def _num(cfg: DictConfig, path: str) -> float:
    node: Any = cfg
    for part in path.split("."):
        node = node[part]
    try:
        value = float(node)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{path}={node!r}: must be a number") from exc
    if not math.isfinite(value):
        raise ConfigError(f"{path}={node!r}: must be finite")
    return value


def _check(cond: bool, path: str, value: object, rule: str) -> None:
    if not cond:
        raise ConfigError(f"{path}={value!r}: {rule}")


def validate(cfg: DictConfig) -> None:
    """Raise :class:`ConfigError` on the first invalid field."""
    d = _num(cfg, "duration")
    _check(d > 0, "duration", cfg.duration, "must be > 0 seconds")
    _check(float(cfg.seed).is_integer() and cfg.seed >= 0, "seed", cfg.seed, "must be an integer >= 0")
    pr, cr = _num(cfg, "physics_rate_hz"), _num(cfg, "control_rate_hz")
    _check(pr > 0 and pr.is_integer(), "physics_rate_hz", cfg.physics_rate_hz, "must be a positive integer")
    _check(cr > 0 and cr.is_integer(), "control_rate_hz", cfg.control_rate_hz, "must be a positive integer")
    _check(
        int(pr) % int(cr) == 0,
        "control_rate_hz",
        cfg.control_rate_hz,
        f"must divide physics_rate_hz={int(pr)} (valid: {_divisors(int(pr))})",
    )
    c = "controller"
    _check(_num(cfg, f"{c}.speed") >= 0, f"{c}.speed", cfg.controller.speed, "must be >= 0 m/s")
    _check(_num(cfg, f"{c}.period") > 0, f"{c}.period", cfg.controller.period, "must be > 0 s")
    duty = _num(cfg, f"{c}.duty")
    _check(0 < duty < 1, f"{c}.duty", cfg.controller.duty, "must be in (0, 1)")
    _check(_num(cfg, f"{c}.swing_height") >= 0, f"{c}.swing_height", cfg.controller.swing_height, "must be >= 0")
    sh = _num(cfg, f"{c}.stand_height")
    _check(0.1 <= sh <= MAX_LEG_REACH_M, f"{c}.stand_height", cfg.controller.stand_height,
           f"must be in [0.1, {MAX_LEG_REACH_M}] m (leg reach)")
    _check(sh + _num(cfg, f"{c}.swing_height") <= MAX_LEG_REACH_M + 0.1, f"{c}.swing_height",
           cfg.controller.swing_height, "too high for the leg")
    for key in ("kp", "kd", "stand_duration"):
        _check(_num(cfg, f"{c}.{key}") >= 0, f"{c}.{key}", cfg.controller[key], "must be >= 0")
    f = "filter"
    _check(_num(cfg, f"{f}.regularization") > 0, f"{f}.regularization", cfg.filter.regularization, "must be > 0")
    _check(_num(cfg, f"{f}.lambda_min_n") >= 0, f"{f}.lambda_min_n", cfg.filter.lambda_min_n, "must be >= 0 N")
    _check(_num(cfg, f"{f}.start_time") >= 0, f"{f}.start_time", cfg.filter.start_time, "must be >= 0 s")
    _check(_num(cfg, f"{f}.contact_velocity_gain") >= 0, f"{f}.contact_velocity_gain",
           cfg.filter.contact_velocity_gain, "must be >= 0 1/s")
    for key in ("alpha1", "alpha2"):
        _check(_num(cfg, f"{f}.ecbf.{key}") > 0, f"{f}.ecbf.{key}", cfg.filter.ecbf[key], "must be > 0 1/s")
    _check(cfg.filter.fallback in FALLBACKS, f"{f}.fallback", cfg.filter.fallback,
           f"valid: {', '.join(FALLBACKS)}")
    _check(cfg.filter.regularization_target in REGULARIZATION_TARGETS, f"{f}.regularization_target",
           cfg.filter.regularization_target, f"valid: {', '.join(REGULARIZATION_TARGETS)}")
    _check(cfg.filter.get("formulation", "full") in FORMULATIONS, f"{f}.formulation", cfg.filter.get("formulation"),
           f"valid: {', '.join(FORMULATIONS)}")
    _check(cfg.filter.stance_source in STANCE_SOURCES, f"{f}.stance_source", cfg.filter.stance_source,
           f"valid: {', '.join(STANCE_SOURCES)}")
    r = "robot"
    _check(_num(cfg, f"{r}.torque_limit_nm") > 0, f"{r}.torque_limit_nm", cfg.robot.torque_limit_nm, "must be > 0")
    _check(0 < _num(cfg, f"{r}.fall_tilt_deg") <= 180, f"{r}.fall_tilt_deg", cfg.robot.fall_tilt_deg,
           "must be in (0, 180]")
    _check(_num(cfg, f"{r}.fall_height_m") >= 0, f"{r}.fall_height_m", cfg.robot.fall_height_m, "must be >= 0")
    for key in ("init_joint_noise_rad", "init_base_vel_noise_mps"):
        _check(_num(cfg, f"{r}.{key}") >= 0, f"{r}.{key}", cfg.robot[key], "must be >= 0")
    if "friction" in cfg.scenario and cfg.scenario.friction is not None:
        _check(_num(cfg, "scenario.friction") > 0, "scenario.friction", cfg.scenario.friction, "must be > 0")
    for group in ("scenario", "solver", "estimator"):
        _check("_target_" in cfg[group], group, dict(cfg[group]), "has no _target_ to build it from")


def _divisors(n: int) -> str:
    divs = [k for k in range(1, n + 1) if n % k == 0]
    return ", ".join(map(str, divs[:12])) + (" ..." if len(divs) > 12 else "")
