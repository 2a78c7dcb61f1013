"""From a validated run config to the typed settings and objects the core builds a run from: the filter's,
the episode's, the plant's and the controller's model's options, the nominal controller, the barrier list.
(Validation: :mod:`taslel_bench.config.validate`; the sweep axes: :mod:`taslel_bench.config.axes`.)"""

from __future__ import annotations

from typing import Any

from hydra.utils import get_class, instantiate
from omegaconf import DictConfig, ListConfig, OmegaConf

from taslel_bench.control.contact_estimate import ContactEstimate, ContactEstimateSettings
from taslel_bench.control.plan import NominalControl
from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.robust import RobustSettings
from taslel_bench.filter.safety_filter import FilterSettings
from taslel_bench.metrics.health import HealthLimits
from taslel_bench.plant.adapter import PlantNames, PlantOverrides
from taslel_bench.plant.build import PlantOptions
from taslel_bench.robot.description import RobotDescription, complete_robot_node, describe_robot
from taslel_bench.robot.model import RobotModel
from taslel_bench.robot.model_options import ModelOptions
from taslel_bench.sim.episode import EpisodeSettings
from taslel_bench.sim.terminations import FallRule
from taslel_bench.terrain.profile import ClearanceProfile
from taslel_bench.terrain.terrain import Terrain
from taslel_bench.util.fields import fail, plain_dict


def _get(cfg: DictConfig, path: str, default: Any = None) -> Any:
    return OmegaConf.select(cfg, path, default=default, throw_on_missing=True)


def robot_description(cfg: DictConfig) -> RobotDescription:
    """The run's robot (``cfg.robot``, one of ``conf/robot/``) as a :class:`RobotDescription`. A run folder's
    config written before robots were described (no ``robot.name``) was an A1 run: ``conf/robot/a1.yaml`` under its
    own robot values."""
    return describe_robot(complete_robot_node(plain_dict(cfg.robot, "robot")))


def build_controller(cfg: DictConfig, robot: RobotDescription, terrain: Terrain | None = None) -> NominalControl:
    """The nominal controller of the ``controller`` group (its ``_target_``, e.g.
    :func:`taslel_bench.control.trot.trot_controller`) for ``robot`` at the control rate; ``terrain``: the world's
    (a controller that follows the terrain reads it)."""
    make = instantiate(cfg.controller, _partial_=True, _convert_="all")  # options from the config, objects below
    return make(robot=robot, terrain=terrain, control_dt_s=1.0 / float(cfg.control_rate_hz))


def filter_settings(cfg: DictConfig, robot: RobotDescription) -> FilterSettings:
    f = cfg.filter
    return FilterSettings(
        enabled=bool(f.enabled),
        regularization=float(f.regularization),
        regularization_target=str(f.get("regularization_target", "nominal")),
        lambda_min_n=float(f.lambda_min_n),
        contact_velocity_gain=float(f.get("contact_velocity_gain", 0.0)),
        torque_limit_nm=robot.torque_limit_nm,
        ecbf_enabled=bool(f.ecbf.enabled),
        ecbf_alpha1=float(f.ecbf.alpha1),
        ecbf_alpha2=float(f.ecbf.alpha2),
        fallback=str(f.fallback),
        stance_source=str(f.stance_source),
        formulation=str(f.get("formulation", "condensed")),
        robust=robust_settings(f.get("robust")),
        control_dt_s=1.0 / float(cfg.control_rate_hz),
        friction_cone=str(f.get("friction_cone", "pyramid")),
        cone_edge_downhill=bool(f.get("cone_edge_downhill", False)),
        relaxation=str(f.get("relaxation", "none")),
    )


def contact_estimate(cfg: DictConfig) -> ContactEstimate:
    """The contact estimate of ``filter.stance_source: estimate`` from ``filter.contact_estimate`` (absent:
    the defaults of :class:`ContactEstimateSettings`)."""
    node = _get(cfg, "filter.contact_estimate") or {}
    return ContactEstimate(ContactEstimateSettings(**{k: float(v) for k, v in node.items()},
                                                   control_dt_s=1.0 / float(cfg.control_rate_hz)))


def robust_settings(node) -> RobustSettings:
    """``filter.robust`` (absent: off)."""
    if not node:
        return RobustSettings()
    return RobustSettings(enabled=bool(node.get("enabled", False)),
                          **{k: float(v) for k, v in node.items() if k != "enabled"})


def episode_settings(cfg: DictConfig, robot: RobotDescription) -> EpisodeSettings:
    return EpisodeSettings(
        duration_s=float(cfg.duration),
        physics_dt_s=1.0 / float(cfg.physics_rate_hz),
        control_dt_s=1.0 / float(cfg.control_rate_hz),
        fall=FallRule(height_m=robot.fall_height_m, tilt_deg=robot.fall_tilt_deg),
        init_joint_noise_rad=robot.init_joint_noise_rad,
        init_base_vel_noise_mps=robot.init_base_vel_noise_mps,
        filter_start_s=float(cfg.filter.get("start_time", 0.0)),
    )


def health_limits(cfg: DictConfig) -> HealthLimits:
    h = cfg.get("health") or {}
    return HealthLimits(**{k: float(v) for k, v in h.items()})


def _plain(value: Any) -> Any:
    """OmegaConf containers as plain Python (lists as tuples), other values as they are."""
    if isinstance(value, (DictConfig, ListConfig)):
        value = OmegaConf.to_container(value, resolve=True)
    return tuple(value) if isinstance(value, list) else value


def model_options(cfg: DictConfig) -> ModelOptions:
    """The ``model`` group (validated by :func:`validate`) as :class:`ModelOptions`; absent = defaults."""
    group = _get(cfg, "model")
    if group is None:
        return ModelOptions()
    return ModelOptions(**{k: _plain(v) for k, v in group.items()})


def build_model(cfg: DictConfig, robot: RobotDescription) -> RobotModel:
    """The controller's model of ``robot``; a URDF Pinocchio cannot read or that lacks the robot's joints raises
    a :class:`ConfigError` naming ``model.urdf``."""
    options = model_options(cfg)
    try:
        return RobotModel(robot, options)
    except (ValueError, RuntimeError) as exc:
        if options.urdf is None:
            raise
        reason = " ".join(str(exc).split())
        raise fail("model.urdf", options.urdf,
                   f"not a URDF of robot={robot.name} for the controller's model: {reason}") from exc


def plant_options(cfg: DictConfig, robot: RobotDescription) -> PlantOptions:
    """The plant builder's options from the validated config (time step, torque limit, names, overrides)."""
    names = _get(cfg, "robot.plant_names")
    overrides = _get(cfg, "robot.plant_overrides")
    return PlantOptions(
        timestep_s=1.0 / float(cfg.physics_rate_hz),
        torque_limit_nm=robot.torque_limit_nm,
        names=PlantNames(**{k: _plain(v) for k, v in names.items()}) if names is not None else PlantNames(),
        overrides=(PlantOverrides(**{k: _plain(v) for k, v in overrides.items()}) if overrides is not None
                   else PlantOverrides()),
    )



def build_barriers(cfg: DictConfig, robot: RobotDescription, terrain: Terrain, profile: ClearanceProfile | None
                   ) -> list[Barrier]:
    """The barrier families of ``filter.barriers`` (name -> ``{_target_: <Barrier subclass>, ...options}``,
    null to drop one) that apply to this world, in config order; none when ``filter.ecbf.enabled`` is off."""
    if not bool(_get(cfg, "filter.ecbf.enabled", True)):
        return []
    world = BarrierWorld(terrain, profile, float(cfg.filter.ecbf.alpha1), float(cfg.filter.ecbf.alpha2), robot)
    barriers = []
    for name, node in (_get(cfg, "filter.barriers") or {}).items():
        if node is None:
            continue
        path = f"filter.barriers.{name}"
        try:
            cls = get_class(node["_target_"])
        except Exception as exc:  # a bad target is a config error naming the field
            raise fail(f"{path}._target_", node.get("_target_"), f"cannot be imported: {exc}") from None
        if not (isinstance(cls, type) and issubclass(cls, Barrier)):
            raise fail(f"{path}._target_", node["_target_"], "must name a subclass of "
                                                             "taslel_bench.filter.barriers.base.Barrier")
        if cls.applies(world):
            make = instantiate(node, _partial_=True)  # options from the config; the world as an object
            barriers.append(make(world=world, name=str(name)))
    return barriers
