"""From a validated run config to the typed settings and objects the core builds a run from: the filter's,
the episode's, the plant's and the controller's model's options, the nominal controller, the barrier list.
(Validation: :mod:`taslel_bench.config.validate`; the sweep axes: :mod:`taslel_bench.config.axes`.)"""

from __future__ import annotations

import math
from typing import Any

from hydra.utils import get_class, instantiate
from omegaconf import DictConfig, ListConfig, OmegaConf

from taslel_bench.config.model_file import model_values
from taslel_bench.control.contact_estimate import ContactEstimate, ContactEstimateSettings
from taslel_bench.control.plan import NominalControl
from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.robust import RobustSettings
from taslel_bench.filter.safety_filter import FilterSettings
from taslel_bench.metrics.health import HealthLimits
from taslel_bench.metrics.verdict import SafetyLimits
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
        regularization_target=str(f.regularization_target),
        lambda_min_n=float(f.lambda_min_n),
        contact_velocity_gain=float(f.contact_velocity_gain),
        torque_limit_nm=robot.torque_limit_nm,
        ecbf_enabled=bool(f.ecbf.enabled),
        ecbf_alpha1=float(f.ecbf.alpha1),
        ecbf_alpha2=float(f.ecbf.alpha2),
        fallback=str(f.fallback),
        stance_source=str(f.stance_source),
        formulation=str(f.formulation),
        robust=robust_settings(f.robust),
        control_dt_s=1.0 / float(cfg.control_rate_hz),
        friction_cone=str(f.friction_cone),
        cone_edge_downhill=bool(f.cone_edge_downhill),
        cone_edge_along_nominal=bool(f.cone_edge_along_nominal),
        release_lifted_feet=bool(f.release_lifted_feet),
        relaxation=str(f.relaxation),
        correction_limit_stance_nm=_limit(f.correction_limit_stance_nm),
        correction_limit_swing_nm=_limit(f.correction_limit_swing_nm),
        correction_limit_stance_unless_sliding=bool(f.correction_limit_stance_unless_sliding),
        sliding_ratio_max=_limit(f.sliding_ratio_max),
        support_min_normal_z=None if f.support_min_normal_z is None else float(f.support_min_normal_z),
    )


def _limit(value: float | None) -> float:
    """A config limit: null (no limit) -> inf."""
    return math.inf if value is None else float(value)


def contact_estimate(cfg: DictConfig) -> ContactEstimate:
    """The contact estimate of ``filter.stance_source: estimate`` from ``filter.contact_estimate``."""
    node = cfg.filter.contact_estimate
    return ContactEstimate(ContactEstimateSettings(**{str(k): float(v) for k, v in node.items()},
                                                   control_dt_s=1.0 / float(cfg.control_rate_hz)))


def robust_settings(node: DictConfig) -> RobustSettings:
    """``filter.robust`` as :class:`RobustSettings`."""
    return RobustSettings(enabled=bool(node.enabled), **{str(k): float(v) for k, v in node.items() if k != "enabled"})


def episode_settings(cfg: DictConfig, robot: RobotDescription) -> EpisodeSettings:
    return EpisodeSettings(
        duration_s=float(cfg.duration),
        physics_dt_s=1.0 / float(cfg.physics_rate_hz),
        control_dt_s=1.0 / float(cfg.control_rate_hz),
        fall=FallRule(height_m=robot.fall_height_m, tilt_deg=robot.fall_tilt_deg),
        init_joint_noise_rad=robot.init_joint_noise_rad,
        init_base_vel_noise_mps=robot.init_base_vel_noise_mps,
        filter_start_s=float(cfg.filter.start_time),
    )


def health_limits(cfg: DictConfig) -> HealthLimits:
    return HealthLimits(model_error_degrades=bool(cfg.health.model_error_degrades),
                        **{str(k): float(v) for k, v in cfg.health.items() if k != "model_error_degrades"})


def safety_limits(cfg: DictConfig) -> SafetyLimits:
    """The ``safety`` block (the verdict's limits) as :class:`SafetyLimits`."""
    block = cfg.safety
    return SafetyLimits(trips_max=int(block.trips_max), **{str(k): float(v) for k, v in block.items()
                                                           if k != "trips_max"})


def _plain(value: Any) -> Any:
    """OmegaConf containers as plain Python (lists as tuples), other values as they are."""
    if isinstance(value, (DictConfig, ListConfig)):
        value = OmegaConf.to_container(value, resolve=True)
    return tuple(value) if isinstance(value, list) else value


def model_options(cfg: DictConfig) -> ModelOptions:
    """The ``model`` group (validated by :func:`validate`), with ``model.from``'s file applied, as
    :class:`ModelOptions`."""
    return ModelOptions(**{key: _plain(value) for key, value in model_values(cfg).items()})


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
    return PlantOptions(
        timestep_s=1.0 / float(cfg.physics_rate_hz),
        torque_limit_nm=robot.torque_limit_nm,
        names=PlantNames(**{str(k): _plain(v) for k, v in cfg.robot.plant_names.items()}),
        overrides=PlantOverrides(**{str(k): _plain(v) for k, v in cfg.robot.plant_overrides.items()}),
    )



def build_barriers(cfg: DictConfig, robot: RobotDescription, terrain: Terrain, profile: ClearanceProfile | None
                   ) -> list[Barrier]:
    """The barrier families of ``filter.barriers`` (name -> ``{_target_: <Barrier subclass>, ...options}``,
    null to drop one) that apply to this world, in config order; none when ``filter.ecbf.enabled`` is off."""
    if not bool(cfg.filter.ecbf.enabled):
        return []
    world = BarrierWorld(terrain, profile, float(cfg.filter.ecbf.alpha1), float(cfg.filter.ecbf.alpha2), robot)
    barriers = []
    for name, node in cfg.filter.barriers.items():
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
