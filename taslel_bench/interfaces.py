"""The contract of the three sweep axes (docs/concepts.md, dependency rule): what ``scenarios``, ``solvers`` and
``estimators`` implement and the types they exchange with the core.

The axis packages import from the core only this module (types, protocols, the terrain vocabulary, the
the core's quadruped vocabulary, the field checks that name a bad config value) and :mod:`taslel_bench.api` (core
services); the core builds them from Hydra ``_target_`` entries and talks to them only through these protocols.

Joint vectors are in the core order (:data:`taslel_bench.robot.quadruped.JOINT_NAMES`, legs FL, FR, RL, RR).
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

from taslel_bench.plant.perturbation import ActuatorDelay, PlantPerturbation
from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.parts import GROUND, OBSTACLE, Box, FrictionStrips, Log, Plane, TerrainPart
from taslel_bench.terrain.profile import ClearanceProfile
from taslel_bench.terrain.relief import HeightField, Ramp, rough_heights
from taslel_bench.terrain.terrain import Terrain
from taslel_bench.util.fields import (
    ConfigError,
    choice,
    fail,
    flag,
    integer,
    is_number,
    number,
    number_or_list,
    numbers,
)
from taslel_bench.util.jit import all_finite

# ----------------------------------------------------------------------------------------------- QP


@dataclass
class QPProblem:
    """min 0.5 x'Px + q'x  s.t.  A x = b,  G x <= h,  lb <= x <= ub  (dense numpy arrays).

    The safety filter reuses one instance per episode (preallocated, updated in place each tick). The
    sparsity *pattern* masks are constant for a filter layout: every entry that can ever be non-zero is
    True, so persistent solvers can set up once and only update values.
    """

    P: np.ndarray  # (n, n)
    q: np.ndarray  # (n,)
    A: np.ndarray  # (m_eq, n)
    b: np.ndarray  # (m_eq,)
    G: np.ndarray  # (m_in, n)
    h: np.ndarray  # (m_in,)
    lb: np.ndarray  # (n,)  -inf where unbounded
    ub: np.ndarray  # (n,)  +inf where unbounded
    P_pattern: np.ndarray  # bool (n, n)
    A_pattern: np.ndarray  # bool (m_eq, n)
    G_pattern: np.ndarray  # bool (m_in, n)
    layout: dict[str, slice] = field(default_factory=dict)  # variable blocks, e.g. {"vdot": slice(0, 18)}
    row_labels: list[str] = field(default_factory=list)  # one label per G row (constraint family)

    @property
    def n(self) -> int:
        return self.P.shape[0]

    def copy(self) -> QPProblem:
        """Deep copy (for recording / replay): the filter overwrites its own instance each tick."""
        P, q, A, b, G, h, lb, ub = (np.array(a, copy=True)
                                    for a in (self.P, self.q, self.A, self.b, self.G, self.h, self.lb, self.ub))
        return QPProblem(
            P, q, A, b, G, h, lb, ub,
            self.P_pattern,
            self.A_pattern,
            self.G_pattern,
            dict(self.layout),
            list(self.row_labels),
        )


SOLVED = "solved"


@dataclass
class QPSolution:
    """What a backend returns. ``status`` is ``"solved"`` or a short reason (``"infeasible"``,
    ``"max_iter"``, ``"error: ..."``); ``x`` is None when no usable solution exists."""

    x: np.ndarray | None
    status: str
    solve_time_s: float  # [s] wall time inside the backend call, matrix building excluded
    iterations: int | None = None
    setup_time_s: float = 0.0  # [s] part of solve_time_s spent (re)building solver data, if known

    @property
    def ok(self) -> bool:
        return self.status == SOLVED and self.x is not None and all_finite(self.x)


@runtime_checkable
class QPBackend(Protocol):
    """One QP solver. ``solve`` must not raise for solver failures: it returns a non-solved status."""

    name: str

    def solve(self, problem: QPProblem) -> QPSolution: ...

    def reset(self) -> None:
        """Forget warm-start data / persistent solver state."""
        ...

    def describe(self) -> dict[str, object]:
        """Name, package version and the settings in force (for reports)."""
        ...


# ----------------------------------------------------------------------------------------- scenario


@runtime_checkable
class Scenario(Protocol):
    """A world: its terrain (the one source of geometry and friction for the plant, the filter's barriers
    and the metrics), what else it changes in the plant, and what happens during the run."""

    name: str
    terrain: Terrain

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        """Plant edits other than the terrain (perturbations); the core builds the terrain into ``spec``
        first. Most scenarios do nothing."""
        ...

    def clearance_profile(self) -> ClearanceProfile | None:
        """The paper's virtual obstacle z(s) under every swing foot, or None (no geometry in the plant)."""
        ...

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        """Per physics step hook (pushes, actuator delay ...); most scenarios do nothing."""
        ...


# ---------------------------------------------------------------------------------------- estimator

# [-] largest friction coefficient a config may give (scenario frictions, estimator constants): far above any
# real foot-ground pair (rubber on concrete ~1), low enough to catch typos like 1e6
MAX_FRICTION = 5.0
# [-] an estimate above the true friction by more than this is an over-estimate (the dangerous side: the filter's
# cone is then wider than the ground's); the one predicate is :func:`overestimates`
OVERESTIMATE_MARGIN = 0.05


def overestimates(mu_hat, mu_true):
    """mu_hat > mu_true + OVERESTIMATE_MARGIN (numbers or arrays): the estimate is on the dangerous side."""
    return mu_hat > mu_true + OVERESTIMATE_MARGIN


@dataclass
class ImuSample:
    """What the trunk's IMU measures on one control tick (ideal: no noise, bias or delay; the IMU at the trunk
    origin). A real robot's IMU reports its attitude (from its own filter), the gyro and the accelerometer."""

    quat_wxyz: np.ndarray  # [-] (4,) trunk orientation in the world (world <- trunk)
    gyro_in_base: np.ndarray  # [rad/s] (3,) trunk angular velocity, trunk axes
    # [m/s²] (3,) specific force (trunk acceleration minus gravity), trunk axes: the mean over the last control
    # tick (velocity change / tick), as an accelerometer averaged over the tick reads it
    accel_in_base: np.ndarray


@dataclass
class Proprioception:
    """One control tick of what a real robot measures (and what its controller knows it asked for). What
    only the simulator knows is :class:`GroundTruth`, a separate input."""

    t_s: float  # [s] episode time
    q_joints: np.ndarray  # [rad] (12,)
    qd_joints: np.ndarray  # [rad/s] (12,)
    tau_joints: np.ndarray  # [N·m] (12,) torques applied on the previous tick
    _: KW_ONLY
    # [-] friction the safety filter assumed on the previous tick, the one that produced tau_joints (the
    # controller knows what it asked for); NaN when no filter was in the loop on that tick
    filter_mu: float = math.nan
    imu: ImuSample | None = None  # the trunk IMU (None: the caller has none)


@dataclass
class GroundTruth:
    """What only the simulator knows at one control tick: the oracle estimator (``reads_ground_truth``), the
    data collection's labels and the metrics read it; a real robot has none of it."""

    friction_under_trunk: float  # [-] ground friction under the trunk
    # [-] (4,) ground friction under each foot, LEGS order (None unless the filter uses per-foot cones on a
    # terrain of more than one friction)
    friction_per_foot: np.ndarray | None = None


@dataclass
class FrictionEstimate:
    mu: float  # [-] estimate the filter uses
    sigma: float = 0.0  # [-] 1-sigma uncertainty, 0 when the estimator gives none
    ready: bool = True  # False while the estimator still uses its prior
    # [-] (4,) per foot, LEGS order, for per-foot friction cones; None: ``mu`` is broadcast to the four feet
    mu_per_foot: np.ndarray | None = None


@runtime_checkable
class Estimator(Protocol):
    """Terrain (friction) estimator in the loop. Optional: ``diagnostics() -> dict[str, float]`` (counters of
    the episode, e.g. drops detected, inference deadlines missed), added to ``summary.json`` as
    ``estimator_<key>``; ``reads_imu = True`` (class attribute): the loop fills ``Proprioception.imu`` every
    tick (else it is None: the sample costs time in every tick); ``reads_ground_truth = True`` (class
    attribute, an oracle): ``step`` gets the tick's :class:`GroundTruth` as a second argument (no other
    estimator sees it)."""

    name: str

    def reset(self) -> None: ...

    def step(self, obs: Proprioception) -> FrictionEstimate:
        """Called every control tick; the estimator decides when to recompute (its own rate)."""
        ...


__all__ = [  # grouped by topic
    # QP
    "SOLVED", "QPBackend", "QPProblem", "QPSolution", "all_finite",
    # scenario and terrain
    "GROUND", "OBSTACLE", "Box", "ClearanceProfile", "FrictionStrips", "HeightField", "Log", "Plane", "Ramp",
    "Scenario", "Terrain", "TerrainPart", "rough_heights",
    # estimator
    "MAX_FRICTION", "OVERESTIMATE_MARGIN", "Estimator", "FrictionEstimate", "GroundTruth", "ImuSample",
    "Proprioception",
    "overestimates",
    # the plant's perturbations
    "ActuatorDelay", "PlantPerturbation",
    # the robot and config values
    "ConfigError", "quad", "choice", "fail", "flag", "integer", "is_number", "number", "number_or_list", "numbers",
]  # fmt: skip
