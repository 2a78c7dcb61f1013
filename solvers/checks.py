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
from numba import njit

from taslel_bench.interfaces import SOLVED, QPProblem, choice, number

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
        """Checked as the ``solver.check`` config group: positive finite thresholds, a known level."""
        for name in ("primal", "dual", "gap"):
            number(f"solver.check.{name}", getattr(self, name), 0.0, lo_open=True)
        choice("solver.check.level", self.level, LEVELS)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class Residuals:
    primal: float
    dual: float  # nan when the backend returned no duals
    gap: float  # nan when the backend returned no duals


def primal_residual(problem: QPProblem, x: np.ndarray) -> float:
    """Largest violation of A x = b, G x <= h and lb <= x <= ub (nan if any is nan)."""
    p = problem
    return float(_primal(p.A, p.b, p.G, p.h, p.lb, p.ub, x))


def residuals(
    problem: QPProblem,
    x: np.ndarray,
    y: np.ndarray | None = None,
    z: np.ndarray | None = None,
    z_box: np.ndarray | None = None,
) -> Residuals:
    """Primal residual, and dual residual + duality gap when all duals are given (see module doc)."""
    p = problem
    if y is None or z is None or z_box is None:
        return Residuals(primal_residual(p, x), float("nan"), float("nan"))
    rp, rd, gap = _kkt(p.P, p.q, p.A, p.b, p.G, p.h, p.lb, p.ub, x, y, z, z_box)
    return Residuals(float(rp), float(rd), float(gap))


# Compiled: the check runs on every answer of every backend in the control loop (a dozen numpy calls on
# small arrays cost ~15 µs, more than some solves). Same definitions as the module doc.


@njit(cache=True, nogil=True)
def _primal(A, b, G, h, lb, ub, x):  # pragma: no cover - compiled
    worst = 0.0
    nan = False
    for r in range(A.shape[0]):
        e = -b[r]
        for j in range(x.shape[0]):
            e += A[r, j] * x[j]
        nan |= np.isnan(e)
        worst = max(worst, abs(e))
    for r in range(G.shape[0]):
        g = -h[r]
        for j in range(x.shape[0]):
            g += G[r, j] * x[j]
        nan |= np.isnan(g)
        worst = max(worst, g)
    for j in range(x.shape[0]):
        nan |= np.isnan(x[j]) or np.isnan(lb[j]) or np.isnan(ub[j])
        worst = max(worst, lb[j] - x[j], x[j] - ub[j])
    return np.nan if nan else worst


@njit(cache=True, nogil=True)
def _kkt(P, q, A, b, G, h, lb, ub, x, y, z, z_box):  # pragma: no cover - compiled
    """(primal, dual, gap); a G row that is identically zero is a constant: its multiplier is ignored."""
    n = x.shape[0]
    rp = _primal(A, b, G, h, lb, ub, x)
    stat = q + z_box  # P x + q + A'y + G'z + z_box, accumulated below
    gap = 0.0
    for i in range(n):
        px = 0.0
        for j in range(n):
            px += P[i, j] * x[j]
        stat[i] += px
        gap += x[i] * px + q[i] * x[i]
    for r in range(A.shape[0]):
        gap += b[r] * y[r]
        for j in range(n):
            stat[j] += A[r, j] * y[r]
    for r in range(G.shape[0]):
        zero_row = True
        for j in range(n):
            if G[r, j] != 0.0:
                zero_row = False
                break
        if zero_row:
            continue
        gap += h[r] * z[r]
        for j in range(n):
            stat[j] += G[r, j] * z[r]
    rd, nan = 0.0, False
    for j in range(n):
        nan |= np.isnan(stat[j])
        rd = max(rd, abs(stat[j]))
        if z_box[j] < 0.0:
            gap += lb[j] * z_box[j]
        elif z_box[j] > 0.0:
            gap += ub[j] * z_box[j]
    return rp, (np.nan if nan else rd), abs(gap)


def residuals_at_level(problem: QPProblem, x: np.ndarray, y, z, z_box, level: str) -> Residuals | None:
    """:func:`residuals` with only what ``level`` asks for (None for level "none")."""
    if level == "none":
        return None
    if level == "primal":
        return Residuals(primal_residual(problem, x), float("nan"), float("nan"))
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
