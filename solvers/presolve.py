"""Exact reductions of a :class:`QPProblem` before handing it to a solver, and the way back for duals.

Two things the filter's QP contains that some solvers cannot digest:

* **Implied inequality rows.** A swing foot has ``lambda_i = 0`` as three unit equality rows *and* its five
  friction-pyramid rows (``-lambda_z <= 0``, ``|lambda_x| <= mu~ lambda_z`` ...), which then hold with
  equality and are linearly dependent on the equalities (LICQ fails). quadprog's dual active-set method
  picks such a row up as "violated" by round-off (``lambda = -1e-17``), finds it dependent on the active
  equalities and aborts with "constraints are inconsistent, no solution". Dropping rows whose every
  variable is pinned by a unit equality row -- after checking they hold at the pinned values -- is exact.
  Identically-zero rows (inactive ECBF rows, ``0 <= 1e6``) are dropped too.
* **Infinite bounds.** Solvers without native box constraints get only the *finite* bounds, as G rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taslel_bench.interfaces import QPProblem


@dataclass
class Reduced:
    """The problem as passed to the solver, with the maps back to the original rows.

    ``lb``/``ub`` are None in "rows" bound mode (bounds are then the last rows of ``G``)."""

    P: np.ndarray
    q: np.ndarray
    A: np.ndarray
    b: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray | None
    ub: np.ndarray | None
    g_rows: np.ndarray  # original G row of each kept G row
    upper_idx: np.ndarray  # variable of each appended  x_j <= ub_j  row
    lower_idx: np.ndarray  # variable of each appended -x_j <= -lb_j row
    g_mask: np.ndarray  # bool pattern of G as passed (for sparse conversion)

    def original_duals(
        self, n: int, m_in: int, z: np.ndarray | None, z_box: np.ndarray | None
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Multipliers of the original G rows and bounds (dropped rows get 0)."""
        if z is None:
            return None, None
        k = self.g_rows.size
        z_full = np.zeros(m_in)
        z_full[self.g_rows] = z[:k]
        zb = np.zeros(n) if z_box is None or np.size(z_box) != n else np.array(z_box, dtype=float, copy=True)
        if self.lb is None:
            nu = self.upper_idx.size
            zb[self.upper_idx] += z[k : k + nu]
            zb[self.lower_idx] -= z[k + nu :]
        return z_full, zb


def kept_rows(problem: QPProblem, drop_implied: bool) -> np.ndarray:
    """Indices of the G rows worth passing on (see module doc)."""
    G, h = problem.G, problem.h
    nonzero = G != 0.0
    keep = np.any(nonzero, axis=1) | (h < 0.0)  # a zero row with h < 0 is infeasible: let the solver say so
    if not drop_implied or problem.A.shape[0] == 0:
        return np.flatnonzero(keep)
    unit = np.count_nonzero(problem.A, axis=1) == 1
    if not np.any(unit):
        return np.flatnonzero(keep)
    rows = np.flatnonzero(unit)
    cols = np.argmax(problem.A[rows] != 0.0, axis=1)
    pinned = np.zeros(problem.n, bool)
    pinned[cols] = True
    x_pin = np.zeros(problem.n)
    x_pin[cols] = problem.b[rows] / problem.A[rows, cols]
    only_pinned = ~np.any(nonzero[:, ~pinned], axis=1)
    holds = G[:, pinned] @ x_pin[pinned] <= h
    keep &= ~(only_pinned & holds)
    return np.flatnonzero(keep)


def reduce(problem: QPProblem, bounds_as_rows: bool, drop_implied: bool) -> Reduced:
    """Build the solver-side problem. P, q, A, b (and lb, ub in native mode) are the caller's arrays, not
    copies: fine for a solver that is set up and run within one call."""
    g_rows = kept_rows(problem, drop_implied)
    G, h, mask = problem.G[g_rows], problem.h[g_rows], problem.G_pattern[g_rows]
    empty = np.zeros(0, dtype=int)
    if not bounds_as_rows:
        return Reduced(
            problem.P, problem.q, problem.A, problem.b, G, h, problem.lb, problem.ub, g_rows, empty, empty, mask,
        )  # fmt: skip
    up = np.flatnonzero(np.isfinite(problem.ub))
    lo = np.flatnonzero(np.isfinite(problem.lb))
    eye = np.eye(problem.n)
    G = np.vstack([G, eye[up], -eye[lo]])
    h = np.concatenate([h, problem.ub[up], -problem.lb[lo]])
    mask = np.vstack([mask, eye[up] != 0.0, eye[lo] != 0.0])
    return Reduced(
        problem.P, problem.q, problem.A, problem.b, G, h, None, None,
        g_rows, up, lo, mask,
    )  # fmt: skip
