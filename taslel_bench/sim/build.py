"""Everything one run needs, built from a validated config before anything is simulated: the axes, the
MuJoCo plant (URDF or another MJCF, the terrain, the scenario's edits), the controller and its model, the
safety filter with its barrier list, and the episode; the plant's foot friction is checked against the
terrain's before the first step."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import mujoco
import numpy as np
from omegaconf import DictConfig

from taslel_bench.config.axes import build_axis, build_backend
from taslel_bench.config.settings import (
    build_barriers,
    build_controller,
    build_model,
    contact_estimate,
    episode_settings,
    filter_settings,
    plant_options,
    robot_description,
)
from taslel_bench.config.validate import validate
from taslel_bench.filter.safety_filter import SafetyFilter
from taslel_bench.interfaces import Estimator, QPBackend, Scenario
from taslel_bench.plant.build import PlantOptions, compile_plant, mjcf_spec, robot_spec
from taslel_bench.plant.contacts import measure_contact_friction
from taslel_bench.qp.reference_check import reference_check
from taslel_bench.robot.description import RobotDescription
from taslel_bench.sim.episode import Episode
from taslel_bench.sim.observers import ReferenceChecks
from taslel_bench.sim.stance import EstimatedStance, MeasuredStance, PlannedStance, StanceSource

FRICTION_CHECK_TOL = 1e-9


class FrictionMismatch(RuntimeError):
    """The plant's foot contacts do not get the friction the scenario configured."""


def build_plant_model(cfg: DictConfig, robot: RobotDescription, scenario: Scenario, rng: np.random.Generator
                      ) -> mujoco.MjModel:
    """The MuJoCo plant of a run: the robot's URDF (or ``robot.plant_mjcf``), the scenario's terrain, then its
    other edits (:func:`build_plant`)."""
    mjcf = cfg.robot.plant_mjcf
    return build_plant(scenario, plant_options(cfg, robot), int(cfg.seed), rng, Path(mjcf) if mjcf else None, robot)


def build_plant(scenario: Scenario, options: PlantOptions | None = None, seed: int = 0,
                rng: np.random.Generator | None = None, mjcf: Path | None = None,
                robot: RobotDescription | None = None) -> mujoco.MjModel:
    """The robot's URDF plant (default: the A1), or the MJCF ``mjcf`` of it, with the scenario's terrain (drawn
    from its own stream of ``seed``: a random terrain does not shift the draws of ``rng``) and the scenario's
    other edits."""
    return compile_plant(build_plant_spec(scenario, options, seed, rng, mjcf, robot), mjcf)


def build_plant_spec(scenario: Scenario, options: PlantOptions | None = None, seed: int = 0,
                     rng: np.random.Generator | None = None, mjcf: Path | None = None,
                     robot: RobotDescription | None = None) -> mujoco.MjSpec:
    """The spec :func:`build_plant` compiles (the same arguments)."""
    options = options if options is not None else PlantOptions()
    spec = mjcf_spec(mjcf, options) if mjcf is not None else robot_spec(robot, options)
    scenario.terrain.build(spec, terrain_rng(seed))
    scenario.build(spec, rng if rng is not None else np.random.default_rng(seed))
    return spec


def terrain_rng(seed: int) -> np.random.Generator:
    """The generator a random terrain draws from: a stream of ``seed`` apart from the run's main one."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(TERRAIN_STREAM,)))


TERRAIN_STREAM = 1


def check_friction(episode: Episode) -> list[tuple[str, float, float]]:
    """Compare, on the initial stand, the friction of every foot contact (MuJoCo contact data) with the
    scenario's friction under that foot. Raises :class:`FrictionMismatch`; returns the triples checked."""
    m, d = episode.m, episode.d
    checked = []
    for foot, mu_plant in measure_contact_friction(m, d):
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, foot)
        mu_cfg = episode.terrain.friction_at(d.site_xpos[site, :2])
        checked.append((foot, mu_plant, mu_cfg))
        if abs(mu_plant - mu_cfg) > FRICTION_CHECK_TOL:
            raise FrictionMismatch(
                f"scenario {episode.scenario.name!r} configures friction {mu_cfg} under {foot} but the plant "
                f"contact has {mu_plant} (check terrain geom priority and friction)"
            )
    if not checked:
        raise FrictionMismatch("no foot touches the ground in the initial stand; cannot check friction")
    return checked


class Built:
    """Everything one run needs, built (and validated) before simulation starts: the parts, then the episode
    assembled from them. ``observers(built)``: the run's observers (:mod:`taslel_bench.sim.observers`), made
    from the built parts and kept as ``recorders`` (None: none but the reference check of
    ``record.reference_every``);
    ``chunk_ticks``: the episode's trace in chunks of that many ticks (None: the whole episode)."""

    def __init__(self, cfg: DictConfig, observers: Callable[[Built], Iterable[object]] | None = None,
                 chunk_ticks: int | None = None) -> None:
        validate(cfg)
        self.cfg = cfg
        self.rng = np.random.default_rng(int(cfg.seed))
        self.scenario: Scenario = build_axis(cfg, "scenario")  # each axis checks its arguments (ConfigError)
        self.estimator: Estimator = build_axis(cfg, "estimator")
        self.robot = robot_description(cfg)
        fs = filter_settings(cfg, self.robot)
        self.backend: QPBackend | None = build_backend(cfg) if fs.enabled else None
        self.mj_model = build_plant_model(cfg, self.robot, self.scenario, self.rng)
        self.controller = build_controller(cfg, self.robot, self.scenario.terrain)
        barriers = build_barriers(cfg, self.robot, self.scenario.terrain, self.scenario.clearance_profile())
        self.filter = None if self.backend is None else SafetyFilter(fs, self.backend, barriers, self.scenario.terrain)
        self.stance = stance_source(cfg, fs.stance_source if self.filter is not None else "schedule")
        # record.reference_every: the backend's answers checked against the tight reference (None: off)
        self.reference_check = reference_check(cfg) if self.filter is not None else None
        checks = [ReferenceChecks(self.reference_check)] if self.reference_check is not None else []
        self.recorders: Iterable[object] = observers(self) if observers is not None else ()
        self.episode = Episode(
            episode_settings(cfg, self.robot), self.scenario, self.mj_model, self.controller, self.filter,
            self.estimator, self.rng, model=build_model(cfg, self.robot), stance=self.stance,
            observers=[*checks, *self.recorders], chunk_ticks=chunk_ticks,
        )
        self.friction_checked = check_friction(self.episode)  # on the state every run of the episode starts from


def stance_source(cfg: DictConfig, name: str) -> StanceSource:
    """The filter's stance source ``name`` (``filter.stance_source``: schedule, contact, estimate)."""
    if name == "estimate":
        return EstimatedStance(contact_estimate(cfg))
    return MeasuredStance() if name == "contact" else PlannedStance()
