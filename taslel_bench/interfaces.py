"""The small interface the three sweep axes implement (DESIGN.md, dependency rule).

``scenarios``, ``solvers`` and ``estimators`` import only this module (and the constants/plant helpers it
names) from the core; the core builds them from Hydra ``_target_`` entries and talks to them only through
these protocols and dataclasses.

Joint vectors are in the core order (:data:`taslel_bench.robot.a1.JOINT_NAMES`, legs FL, FR, RL, RR).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

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
        return QPProblem(
            *(np.array(a, copy=True) for a in (self.P, self.q, self.A, self.b, self.G, self.h, self.lb, self.ub)),
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
        # a finite x'x <=> all entries finite (entries beyond ~1e154, which overflow it, also read as not ok)
        return self.status == SOLVED and self.x is not None and math.isfinite(self.x @ self.x)


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


@dataclass(frozen=True)
class ClearanceProfile:
    """Obstacle height under a swing foot as a polynomial of the swing phase s in [0, 1]:
    z(s) = sum_k coeffs[k] s^k  [m, world z of the foot-sphere *bottom*]."""

    coeffs: tuple[float, ...]

    def __call__(self, s: float) -> tuple[float, float, float]:
        """(z, dz/ds, d²z/ds²) at phase ``s``."""
        z = dz = ddz = 0.0
        for k, c in enumerate(self.coeffs):
            z += c * s**k
            if k >= 1:
                dz += k * c * s ** (k - 1)
            if k >= 2:
                ddz += k * (k - 1) * c * s ** (k - 2)
        return z, dz, ddz

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised (z, dz/ds, d²z/ds²) for an array of phases (one Vandermonde matrix, three dots)."""
        powers = np.asarray(s, float)[:, None] ** self._k  # (n, K): s^0 .. s^(K-1)
        return powers @ self._c, powers @ self._c1, powers @ self._c2

    def __post_init__(self) -> None:
        c = np.asarray(self.coeffs, float)
        k = np.arange(len(c))
        c1 = np.zeros_like(c)
        c1[: len(c) - 1] = c[1:] * k[1:]  # coefficients of dz/ds, padded to K
        c2 = np.zeros_like(c)
        c2[: len(c) - 2] = c[2:] * k[2:] * k[1:-1]  # coefficients of d²z/ds²
        for name, value in (("_k", k), ("_c", c), ("_c1", c1), ("_c2", c2)):
            object.__setattr__(self, name, value)  # frozen dataclass: cached derived arrays

    def coefficient_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The coefficients of z, dz/ds and d²z/ds² (ascending powers, all of length K)."""
        return self._c, self._c1, self._c2

    @property
    def peak_m(self) -> float:
        return float(max(self(s)[0] for s in np.linspace(0.0, 1.0, 201)))


@dataclass(frozen=True)
class RoundObstacle:
    """A log (cylinder) lying across the path on the floor: its axis is parallel to world y, through
    (x_m, z_m) [m, world], radius ``radius_m`` [m]; it spans y in [-half_width_m, half_width_m]. Its top is
    at ``z_m + radius_m`` above the floor. Real geometry in the plant (a capsule), and the swing-foot
    barrier's obstacle: the foot sphere of radius r is clear of it iff
    sqrt((x - x_m)² + (z - z_m)²) >= radius_m + r for the foot-sphere centre (x, z)."""

    x_m: float
    z_m: float
    radius_m: float
    half_width_m: float = 0.5

    @property
    def top_m(self) -> float:
        return self.z_m + self.radius_m


@runtime_checkable
class Scenario(Protocol):
    """A world: what the plant looks like and what is true about it."""

    name: str

    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        """Edit the plant spec in place (terrain geoms, frictions, obstacles, perturbations)."""
        ...

    def friction_at(self, xy_in_world: np.ndarray) -> float:
        """True Coulomb friction coefficient [-] of the ground at a world (x, y) [m]."""
        ...

    def clearance_profile(self) -> ClearanceProfile | None:
        """z(s) for the swing-foot ECBF, or None when the scenario has no obstacle profile (a *virtual*
        obstacle: no geometry in the plant)."""
        ...

    def obstacles(self) -> tuple[RoundObstacle, ...]:
        """Physical obstacles the scenario puts in the plant (empty for most scenarios); the filter's
        obstacle barrier and the clearance metrics use them."""
        ...

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        """Per control tick hook (pushes, friction patches ...); most scenarios do nothing."""
        ...


# ---------------------------------------------------------------------------------------- estimator

# [-] largest friction coefficient a config may give (scenario frictions, estimator constants): far above any
# real foot-ground pair (rubber on concrete ~1), low enough to catch typos like 1e6
MAX_FRICTION = 5.0


@dataclass
class Proprioception:
    """One control tick of what a real robot measures, plus the truth for the oracle and the metrics."""

    t_s: float  # [s] episode time
    q_joints: np.ndarray  # [rad] (12,)
    qd_joints: np.ndarray  # [rad/s] (12,)
    tau_joints: np.ndarray  # [N·m] (12,) torques applied this tick
    true_friction: float  # [-] ground friction under the robot (oracle / metrics only)
    # [-] friction the safety filter assumed on the previous tick, the one that produced tau_joints (the
    # controller knows what it asked for); NaN when no filter was in the loop on that tick
    filter_mu: float = math.nan


@dataclass
class FrictionEstimate:
    mu: float  # [-] estimate the filter uses
    sigma: float = 0.0  # [-] 1-sigma uncertainty, 0 when the estimator gives none
    ready: bool = True  # False while the estimator still uses its prior


@runtime_checkable
class Estimator(Protocol):
    """Terrain (friction) estimator in the loop. Optional: ``diagnostics() -> dict[str, float]`` (counters of
    the episode, e.g. drops detected, inference deadlines missed), added to ``summary.json`` as
    ``estimator_<key>``."""

    name: str

    def reset(self) -> None: ...

    def step(self, obs: Proprioception) -> FrictionEstimate:
        """Called every control tick; the estimator decides when to recompute (its own rate)."""
        ...
