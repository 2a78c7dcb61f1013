"""Each default lives once: the run config's schema (taslel_bench/config/schema.py) holds the core groups' defaults,
which the settings the core builds from the default config reproduce; no option YAML restates one; each axis class's
defaults agree with its config file (a default written twice that differs is a bug)."""

from __future__ import annotations

import inspect
from dataclasses import fields
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from taslel_bench.config import settings
from taslel_bench.config.compose import CONF_DIR, compose
from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import PDGains
from taslel_bench.filter.robust import RobustSettings
from taslel_bench.filter.safety_filter import FilterSettings
from taslel_bench.metrics.health import HealthLimits
from taslel_bench.metrics.verdict import SafetyLimits
from taslel_bench.plant.build import PlantOptions
from taslel_bench.robot.model_options import ModelOptions
from taslel_bench.sim.episode import EpisodeSettings


def _differences(built, default) -> list[str]:
    return [f"{f.name}: config {getattr(built, f.name)!r}, dataclass {getattr(default, f.name)!r}"
            for f in fields(default) if getattr(built, f.name) != getattr(default, f.name)]


def test_core_settings_defaults_are_the_configs():
    cfg = compose()
    robot = settings.robot_description(cfg)
    controller = settings.build_controller(cfg, robot)
    pairs = {
        "filter": (settings.filter_settings(cfg, robot), FilterSettings()),
        "filter.robust": (settings.robust_settings(cfg.filter.robust), RobustSettings()),
        "episode": (settings.episode_settings(cfg, robot), EpisodeSettings()),
        "health": (settings.health_limits(cfg), HealthLimits()),
        "safety": (settings.safety_limits(cfg), SafetyLimits()),
        "model": (settings.model_options(cfg), ModelOptions()),
        "plant": (settings.plant_options(cfg, robot), PlantOptions()),
        "controller gait": (controller.gait.p, GaitParams()),
        "controller gains": (controller.gains, PDGains()),
    }
    wrong = {name: diff for name, (built, default) in pairs.items() if (diff := _differences(built, default))}
    assert not wrong


SCHEMA_GROUPS = ("filter", "model", "robot", "controller")  # the groups whose options build on the schema


def _leaves(node, prefix=""):
    """(dotted key, value) of every leaf of a plain YAML mapping (``defaults`` and ``_target_`` left out)."""
    for key, value in node.items():
        if key in ("defaults", "_target_"):
            continue
        if isinstance(value, dict) and value:
            yield from _leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def _schema_default(root, path: str):
    """The schema's default at ``path`` (``"?"`` where the schema has no fixed default: a required key, an entry
    of a free-form node such as ``filter.barriers``)."""
    parent, _, leaf = path.rpartition(".")
    node = OmegaConf.select(root, parent) if parent else root
    if node is None or OmegaConf.get_type(node) is dict or leaf not in node or OmegaConf.is_missing(node, leaf):
        return "?"
    return OmegaConf.to_container(node, resolve=False)[leaf]


@pytest.mark.parametrize("group", SCHEMA_GROUPS)
def test_no_option_restates_a_schema_default(group):
    from taslel_bench.config import schema

    node_type = {"filter": schema.FilterConfig, "model": schema.ModelConfig, "robot": schema.RobotConfig,
                 "controller": schema.TrotConfig}[group]
    base = OmegaConf.structured(node_type)
    restated = [f"{path.name}: {key}={value!r}" for path in sorted((CONF_DIR / group).glob("*.yaml"))
                for key, value in _leaves(OmegaConf.to_container(OmegaConf.load(path)) or {})
                if (default := _schema_default(base, key)) != "?" and _same(value, default)]
    assert not restated


def _same(yaml_value, default) -> bool:
    if isinstance(default, tuple):
        default = list(default)
    if isinstance(yaml_value, list) and isinstance(default, list) and len(yaml_value) == len(default):
        return all(_same(a, b) for a, b in zip(yaml_value, default, strict=True))
    if isinstance(yaml_value, dict) and isinstance(default, dict) and yaml_value.keys() == default.keys():
        return all(_same(yaml_value[k], default[k]) for k in yaml_value)
    return yaml_value == default


def _class_files() -> list[Path]:
    """The axis config files named like their class's default ``name`` (the others are presets:
    ``low_friction`` is FlatGround with friction 0.2); they must hold the class's defaults."""
    out = []
    for path in sorted(p for group in ("scenario", "estimator", "solver") for p in (CONF_DIR / group).glob("*.yaml")):
        node = OmegaConf.load(path)
        if "_target_" not in node:  # a preset over another file of its group (its defaults list): checked there
            assert "defaults" in node, f"{path}: neither _target_ nor a defaults list"
            continue
        target = get_class_or_function(node["_target_"])
        params = inspect.signature(target).parameters
        if "name" in params and params["name"].default == path.stem:
            out.append(path)
    return out


def get_class_or_function(target: str):
    module, _, name = target.rpartition(".")
    return getattr(__import__(module, fromlist=[name]), name)


@pytest.mark.parametrize("path", _class_files(), ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_an_axis_class_defaults_are_its_config_files(path: Path):
    node = OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    params = inspect.signature(get_class_or_function(node["_target_"])).parameters
    wrong = [f"{key}: yaml {value!r}, class {params[key].default!r}" for key, value in node.items()
             if key in params and params[key].default is not inspect.Parameter.empty
             and not _same(value, params[key].default)]
    assert not wrong
