"""The core's services for the axis packages (``scenarios/``, ``solvers/``, ``estimators/``) and studies.

Axis packages import :mod:`taslel_bench.interfaces` for types and this module for the core services they
need beyond them: the project config, the safety filter, the controller, the plant and the one episode loop
(data collection and in-loop studies run the benchmark's loop, fall rule included). Everything here is built
from the project's Hydra config, so a solver or filter setting means the same thing in a data-collection
run as in a benchmark run.

    cfg = api.compose(["solver=daqp"])
    safety_filter = api.build_safety_filter(cfg)          # SafetyFilter with cfg.solver's backend
    controller = api.build_controller(cfg)                # NominalController (trot, IK, joint PD)
    controller = api.NominalController(api.GaitParams(speed_mps=0.3), api.PDGains())  # or set by hand
    world = api.StaticWorld(Terrain((Plane(0.4),)), perturbation=PlantPerturbation(trunk_mass_scale=1.2))
    plant = api.build_plant(world)                        # compiled MuJoCo model
    episode = api.Episode(api.episode_settings(cfg), world, plant, controller, None, estimator, rng)
    result = episode.run()                                # result.trace, result.fell, result.time_to_fall_s
    batch = api.BatchRollout(settings, [api.BatchEnv(world, plant, controller, rng), ...], nthread=2)
    batch.run()                                           # the same nominal episodes (no filter), stepped together
"""

from __future__ import annotations

from hydra.utils import instantiate
from omegaconf import DictConfig

from taslel_bench.config import settings
from taslel_bench.config.compose import compose
from taslel_bench.config.settings import build_barriers, filter_settings, robot_description
from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.control.plan import NominalControl
from taslel_bench.filter.layout import TickInputs
from taslel_bench.filter.safety_filter import FilterResult, SafetyFilter
from taslel_bench.interfaces import ClearanceProfile, Terrain
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.build import PlantOptions
from taslel_bench.record.qpset import QPRecorder, QPSet, active_sets, binding_tags, from_problems
from taslel_bench.record.qpset import load as load_qpset
from taslel_bench.record.qpset import save as save_qpset
from taslel_bench.record.result import EpisodeResult
from taslel_bench.robot import leg_chain
from taslel_bench.robot.description import RobotDescription, load_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.robot.model import RobotModel
from taslel_bench.sim.batch import BatchEnv, BatchResult, BatchRollout
from taslel_bench.sim.build import build_plant
from taslel_bench.sim.episode import Episode, EpisodeSettings
from taslel_bench.sim.observers import FilterQPs
from taslel_bench.sim.stance import EstimatedStance, MeasuredStance, PlannedStance
from taslel_bench.sim.world import StaticWorld
from taslel_bench.util.machine import machine_info

__all__ = [
    "BatchEnv",
    "BatchResult",
    "BatchRollout",
    "Episode",
    "EpisodeResult",
    "EpisodeSettings",
    "EstimatedStance",
    "FilterQPs",
    "FilterResult",
    "GaitParams",
    "NominalController",
    "PDGains",
    "LegKinematics",
    "MeasuredStance",
    "PlannedStance",
    "PlantOptions",
    "QPRecorder",
    "QPSet",
    "RobotDescription",
    "RobotModel",
    "SafetyFilter",
    "StateBridge",
    "StaticWorld",
    "TickInputs",
    "active_sets",
    "binding_tags",
    "build_controller",
    "build_plant",
    "build_safety_filter",
    "compose",
    "episode_settings",
    "from_problems",
    "leg_chain",
    "load_qpset",
    "load_robot",
    "robot_description",
    "machine_info",
    "save_qpset",
]


def build_safety_filter(cfg: DictConfig, terrain: Terrain | None = None,
                        profile: ClearanceProfile | None = None) -> SafetyFilter:
    """The ID-CBF-QP filter configured by ``cfg.filter``/``cfg.robot`` with the backend ``cfg.solver`` and the
    barrier families of ``cfg.filter.barriers`` that apply to ``terrain`` (default: the flat floor) and the
    virtual ``profile`` (None: no phase-profile rows). Per tick:
    ``safety_filter.filter(TickInputs(model, v, in_stance, mu, swing_phase, swing_phase_rate), u_nom)``
    with ``model`` a :class:`RobotModel` updated at the plant state (see :mod:`taslel_bench.sim.episode`). The
    terrain also reaches the filter itself: ``filter=terrain``'s cone about the terrain normal reads it."""
    robot = robot_description(cfg)
    fs = filter_settings(cfg, robot)
    if not fs.enabled:
        raise ValueError("build_safety_filter: cfg.filter.enabled is false")
    terrain = terrain if terrain is not None else Terrain()
    barriers = build_barriers(cfg, robot, terrain, profile)
    return SafetyFilter(fs, instantiate(cfg.solver), barriers, terrain)


def build_controller(cfg: DictConfig, terrain: Terrain | None = None) -> NominalControl:
    """The nominal controller of ``cfg.controller`` for the robot ``cfg.robot``."""
    return settings.build_controller(cfg, robot_description(cfg), terrain)


def episode_settings(cfg: DictConfig) -> EpisodeSettings:
    """The episode's settings (duration, rates, the robot's fall rule and initial noise) of ``cfg``."""
    return settings.episode_settings(cfg, robot_description(cfg))
