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

from dataclasses import asdict, dataclass

import numpy as np

from taslel_bench.interfaces import SOLVED, QPProblem


@dataclass(frozen=True)
class Tolerances:
    """Acceptance thresholds (absolute, infinity norm) for a solution that a solver calls optimal."""

    primal: float = 1e-6  # max(|Ax - b|, [Gx - h]+, bound violation)
    dual: float = 1e-5  # |Px + q + A'y + G'z + z_box|
    gap: float = 1e-5  # duality gap [same unit as the cost: (N·m)²]

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class Residuals:
    primal: float
    dual: float  # nan when the backend returned no duals
    gap: float  # nan when the backend returned no duals


def primal_residual(problem: QPProblem, x: np.ndarray) -> float:
    """Largest violation of A x = b, G x <= h and lb <= x <= ub."""
    r = 0.0
    if problem.A.shape[0]:
        r = float(np.max(np.abs(problem.A @ x - problem.b)))
    if problem.G.shape[0]:
        r = max(r, float(np.max(problem.G @ x - problem.h)))
    r = max(r, float(np.max(problem.lb - x)), float(np.max(x - problem.ub)))
    return max(r, 0.0)


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
    z = np.where(np.any(problem.G != 0.0, axis=1), z, 0.0)
    Px = problem.P @ x
    rd = float(np.max(np.abs(Px + problem.q + problem.A.T @ y + problem.G.T @ z + z_box)))
    fin_l, fin_u = np.isfinite(problem.lb), np.isfinite(problem.ub)
    gap = (
        x @ Px
        + problem.q @ x
        + problem.b @ y
        + problem.h @ z
        + problem.lb[fin_l] @ np.minimum(z_box[fin_l], 0.0)
        + problem.ub[fin_u] @ np.maximum(z_box[fin_u], 0.0)
    )
    return Residuals(rp, rd, float(abs(gap)))


def verdict(res: Residuals, tol: Tolerances) -> str:
    """``"solved"`` if every available residual is within tolerance, else a short reason."""
    if not np.isfinite(res.primal) or res.primal > tol.primal:
        return f"inaccurate: primal residual {res.primal:.1e} > {tol.primal:.0e}"
    if not np.isnan(res.dual) and not res.dual <= tol.dual:
        return f"inaccurate: dual residual {res.dual:.1e} > {tol.dual:.0e}"
    if not np.isnan(res.gap) and not res.gap <= tol.gap:
        return f"inaccurate: duality gap {res.gap:.1e} > {tol.gap:.0e}"
    return SOLVED
