"""Persistent Clarabel (interior point): one ``clarabel.DefaultSolver`` per layout, ``update`` each tick.

Clarabel solves  min 0.5 x'Px + q'x  s.t.  C x + s = d,  s in K. The rows passed: the equalities (zero cone,
``A x + s = b``), the inequalities except vacuous ones (``G x + s = h``, non-negative cone), then for every
finite bound one row ``x_j + s = ub_j`` and one ``-x_j + s = -lb_j`` (non-negative cone). Vacuous rows --
identically zero with h >= 0 (inactive swing-foot friction rows, inactive ECBF rows) -- are left out as in
:mod:`solvers.osqp_persistent`; the pattern of the kept rows is part of the layout.

Data updates (``DefaultSolver.update(P=, q=, A=, b=)``, matrices as their CSC value vectors in the fixed
pattern order) are allowed only with Clarabel's presolve off and structural zeros kept
(``presolve_enable = False``, ``input_sparse_dropzeros = False``); :meth:`_setup` forces both and checks
``is_data_update_allowed()``. An interior-point method does not start from the previous iterate: "warm" here
means no new setup (equilibration and the KKT factorisation's symbolic structure are reused); the iteration
count is the cold one.

Duals: Clarabel's stationarity is P x + q + C'z = 0 with z in K* -- the convention of :mod:`solvers.checks`
for y (zero-cone rows) and z (G rows); a bound's multiplier is z_upper - z_lower.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numba import njit

from solvers.persistent import NativeResult, PersistentBackend, failure_reason
from solvers.sparse import PatternCSC
from taslel_bench.interfaces import QPProblem

# Tolerances: see conf/solver/clarabel.yaml for the u error they give (the YAML is the one place they are
# chosen; these are the fallback for make_backend without it).
DEFAULT_SETTINGS: dict[str, Any] = {
    "tol_gap_abs": 1e-9,
    "tol_gap_rel": 1e-9,
    "tol_feas": 1e-9,
    "iterative_refinement_reltol": 1e-14,
    "iterative_refinement_abstol": 1e-14,
    "iterative_refinement_max_iter": 50,
    "verbose": False,
}
FORCED = {"presolve_enable": False, "input_sparse_dropzeros": False}  # what data updates need


class ClarabelPersistent(PersistentBackend):
    name = "clarabel"
    package = "clarabel"

    def __init__(self, settings: dict[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__({**DEFAULT_SETTINGS, **dict(settings or {}), **FORCED}, **kwargs)
        self.warm_start = False  # an interior-point method starts cold; only the setup is kept
        self._solver = None
        self._kept: dict[bytes, tuple] = {}

    def _forget(self) -> None:
        self._solver = None

    def _layout_key(self, problem: QPProblem) -> tuple:
        vac = self.vacuous_rows(problem).tobytes()
        pattern = self._kept.get(vac)
        if pattern is None:
            if len(self._kept) > 64:
                self._kept.clear()
            kept = problem.G_pattern[~self._vacuous]
            pattern = self._kept[vac] = (vac, kept.shape, kept.tobytes())
        return super()._layout_key(problem) + pattern

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        if fresh:
            self._structures(problem)
        p = problem
        _gather(p.P, p.q, p.A, p.b, p.G, p.h, p.lb, p.ub, self._g_rows, self._upper, self._lower,
                self._P_pat.rows, self._P_pat.cols, self._C_pat.rows, self._C_pat.cols, self._Px, self._Cx,
                self._q, self._d)  # fmt: skip

    def _structures(self, problem: QPProblem) -> None:
        n, m_eq = problem.n, problem.A.shape[0]
        self._g_rows = np.flatnonzero(~self.vacuous_rows(problem))
        self._upper = np.flatnonzero(np.isfinite(problem.ub))
        self._lower = np.flatnonzero(np.isfinite(problem.lb))
        self._n, self._m_eq, self._m_in, self._m_in_all = n, m_eq, self._g_rows.size, problem.G.shape[0]
        eye = np.eye(n, dtype=bool)
        self._P_pat = PatternCSC(problem.P_pattern | problem.P_pattern.T | eye, upper_only=True)
        self._C_pat = PatternCSC(np.vstack([problem.A_pattern, problem.G_pattern[self._g_rows], eye[self._upper],
                                            eye[self._lower]]))  # fmt: skip
        self._Px, self._Cx = np.zeros(self._P_pat.nnz), np.zeros(self._C_pat.nnz)
        self._q, self._d = np.zeros(n), np.zeros(self._C_pat.shape[0])

    def _setup(self, problem: QPProblem) -> None:
        import clarabel

        settings = clarabel.DefaultSettings()
        for key, value in self.settings.items():
            setattr(settings, key, value)
        P = sp.csc_matrix((self._Px, self._P_pat.indices, self._P_pat.indptr), shape=self._P_pat.shape)
        C = sp.csc_matrix((self._Cx, self._C_pat.indices, self._C_pat.indptr), shape=self._C_pat.shape)
        n_ineq = self._C_pat.shape[0] - self._m_eq
        cones = ([clarabel.ZeroConeT(self._m_eq)] if self._m_eq else []) + (
            [clarabel.NonnegativeConeT(n_ineq)] if n_ineq else [])  # fmt: skip
        self._solver = clarabel.DefaultSolver(P, self._q, C, self._d, cones, settings)
        if not self._solver.is_data_update_allowed():
            raise RuntimeError("Clarabel refuses data updates (presolve or dropped zeros active)")

    def _update(self, problem: QPProblem) -> None:
        self._solver.update(P=self._Px, q=self._q, A=self._Cx, b=self._d)

    def _solve(self) -> NativeResult:
        r = self._solver.solve()
        status = str(r.status)
        iters = int(r.iterations)
        if status != "Solved":
            return NativeResult(None, False, failure_reason(status), iters)
        zc = np.asarray(r.z)
        m_eq, m_in, nu = self._m_eq, self._m_in, self._upper.size
        z = np.zeros(self._m_in_all)  # left-out rows: multiplier 0
        z[self._g_rows] = zc[m_eq : m_eq + m_in]
        z_box = np.zeros(self._n)
        z_box[self._upper] += zc[m_eq + m_in : m_eq + m_in + nu]
        z_box[self._lower] -= zc[m_eq + m_in + nu :]
        return NativeResult(np.array(r.x), True, status, iters, y=np.array(zc[:m_eq]), z=z, z_box=z_box)


@njit(cache=True, nogil=True)
def _gather(P, q, A, b, G, h, lb, ub, g_rows, upper, lower, P_rows, P_cols, C_rows, C_cols, Px, Cx, q_out,
            d):  # pragma: no cover - compiled  # fmt: skip
    """Clarabel's data in the fixed CSC orders: P's upper triangle, C = [A; G[g_rows]; I[upper]; -I[lower]];
    d = (b, h[g_rows], ub[upper], -lb[lower])."""
    m_eq, m_in, nu = A.shape[0], g_rows.shape[0], upper.shape[0]
    for k in range(Px.shape[0]):
        Px[k] = P[P_rows[k], P_cols[k]]
    for k in range(Cx.shape[0]):
        r, c = C_rows[k], C_cols[k]
        if r < m_eq:
            Cx[k] = A[r, c]
        elif r < m_eq + m_in:
            Cx[k] = G[g_rows[r - m_eq], c]
        else:
            Cx[k] = 1.0 if r < m_eq + m_in + nu else -1.0
    q_out[:] = q
    for r in range(m_eq):
        d[r] = b[r]
    for r in range(m_in):
        d[m_eq + r] = h[g_rows[r]]
    for i in range(nu):
        d[m_eq + m_in + i] = ub[upper[i]]
    for i in range(lower.shape[0]):
        d[m_eq + m_in + nu + i] = -lb[lower[i]]
