"""Optimality checks of a QP solution against the original :class:`QPProblem`.

Dual convention (the one ``qpsolvers`` uses): stationarity reads

    P x + q + A' y + G' z + z_box = 0,   z >= 0,   z_box < 0 on an active lower bound, > 0 on an upper one,

and the duality gap is | x'Px + q'x + b'y + h'z + lb' min(z_box, 0) + ub' max(z_box, 0) | (finite bounds
only). A G row that is identically zero (an inactive ECBF row ``0 <= 1e6``) is a constant, not a
constraint: its multiplier is ignored so that ``h = 1e6`` times an interior-point solver's tiny ``z`` does
not pollute the gap.

Why the gap matters here: the cost is 1-strongly convex in u (P_uu = I), so for a feasible x a gap of g
bounds the torque error by ||u - u*||_2 <= sqrt(2 g).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from taslel_bench.interfaces import SOLVED, QPProblem

LEVELS = ("kkt", "primal", "none")


@dataclass(frozen=True)
class Tolerances:
    """Acceptance thresholds (absolute, infinity norm) for a solution that a solver calls optimal.

    ``level``: ``"kkt"`` checks primal residual, dual residual and duality gap (needed for iterative
    methods: OSQP, ProxQP, interior points); ``"primal"`` only the primal residual (cheaper, enough to catch
    garbage from an exact active-set method); ``"none"`` trusts the solver."""

    primal: float = 1e-6  # max(|Ax - b|, [Gx - h]+, bound violation)
    dual: float = 1e-5  # |Px + q + A'y + G'z + z_box|
    gap: float = 1e-5  # duality gap [same unit as the cost: (N·m)²]
    level: str = "kkt"

    def __post_init__(self) -> None:
        if self.level not in LEVELS:
            raise ValueError(f"check level {self.level!r}; valid: {', '.join(LEVELS)}")

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class Residuals:
    primal: float
    dual: float  # nan when the backend returned no duals
    gap: float  # nan when the backend returned no duals


def primal_residual(problem: QPProblem, x: np.ndarray) -> float:
    """Largest violation of A x = b, G x <= h and lb <= x <= ub (nan if any is nan)."""
    worst = []
    if problem.A.shape[0]:
        e = problem.A @ x
        e -= problem.b
        worst += [e.max(), -e.min()]
    if problem.G.shape[0]:
        g = problem.G @ x
        g -= problem.h
        worst.append(g.max())
    worst += [(problem.lb - x).max(), (x - problem.ub).max()]
    r = max(0.0, *worst)
    return float("nan") if any(math.isnan(v) for v in worst) else float(r)


def residuals(
    problem: QPProblem,
    x: np.ndarray,
    y: np.ndarray | None = None,
    z: np.ndarray | None = None,
    z_box: np.ndarray | None = None,
) -> Residuals:
    """Primal residual, and dual residual + duality gap when all duals are given (see module doc)."""
    rp = primal_residual(problem, x)
    if y is None or z is None or z_box is None:
        return Residuals(rp, float("nan"), float("nan"))
    if z.size:
        z = z * problem.G.any(axis=1)  # inert all-zero rows: constant, not constraints
    Px = problem.P @ x
    stat = Px + problem.q
    stat += y @ problem.A
    stat += z @ problem.G
    stat += z_box
    rd = float(np.abs(stat).max())
    # bound terms: lb * min(z_box, 0) + ub * max(z_box, 0), with 0 * inf read as 0
    zb_bound = np.where(z_box < 0.0, problem.lb, problem.ub)
    active = z_box != 0.0
    gap = x @ Px + problem.q @ x + problem.b @ y + problem.h @ z + zb_bound[active] @ z_box[active]
    return Residuals(rp, rd, float(abs(gap)))


def residuals_at_level(problem: QPProblem, x: np.ndarray, y, z, z_box, level: str,
                       primal: float | None = None) -> Residuals | None:  # fmt: skip
    """:func:`residuals` with only what ``level`` asks for (None for level "none"). ``primal``: the primal
    residual already computed by the backend on an exact copy of the problem's rows (saves the work)."""
    if level == "none":
        return None
    if level == "primal":
        return Residuals(primal_residual(problem, x) if primal is None else primal, float("nan"), float("nan"))
    return residuals(problem, x, y, z, z_box)


def verdict(res: Residuals | None, tol: Tolerances) -> str:
    """``"solved"`` if every available residual is within tolerance, else a short reason."""
    if res is None:
        return SOLVED
    if not math.isfinite(res.primal) or res.primal > tol.primal:
        return f"inaccurate: primal residual {res.primal:.1e} > {tol.primal:.0e}"
    if not math.isnan(res.dual) and not res.dual <= tol.dual:
        return f"inaccurate: dual residual {res.dual:.1e} > {tol.dual:.0e}"
    if not math.isnan(res.gap) and not res.gap <= tol.gap:
        return f"inaccurate: duality gap {res.gap:.1e} > {tol.gap:.0e}"
    return SOLVED
