"""Persistent OSQP: one ``osqp.OSQP`` per layout, values updated in the fixed pattern order, warm started.

Constraint rows passed to OSQP (l <= C x <= u): the equalities (l = u = b), the inequalities
(l = -inf, u = h) except vacuous ones, then one unit row per variable with a finite bound (l = lb, u = ub).
Vacuous rows -- identically zero with h >= 0, such as the inactive friction rows of a swing foot and the
inactive ECBF rows of stance feet -- are left out (``drop_vacuous_rows``): with the condensed
formulation's dense pattern they are half of G, and leaving them out cuts OSQP's time per iteration about
2.5x (measured: 177 -> 68 µs per QP, same iterations and answers). The sparsity pattern of the kept rows is
part of the layout: a change (e.g. standing -> walking) sets OSQP up again. P is passed as its
upper triangle. The CSC structures come from the problem's constant masks (:mod:`solvers.sparse`), so
the compiled solver's ``update_data_mat`` can take all values in one go every tick. Updates and solves go to
the compiled solver (``osqp.OSQP``'s ``_solver``) directly: the same calls without the wrapper's copies.

Warm start: OSQP keeps its last iterate (x, y) in the workspace and starts the next solve from it when
its ``warm_starting`` setting is on; ``warm_start=False`` sets it off (every solve starts from zero).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numba import njit

from solvers.persistent import NativeResult, PersistentBackend, failure_reason
from solvers.settings import check_settings
from solvers.sparse import PatternCSC
from taslel_bench.interfaces import QPProblem, flag

# Accurate u (docs/concepts.md, measured facts: defaults are off by ~0.05-0.08 N·m): tight absolute tolerance, no
# relative one. Measured on consecutive filter QPs of obstacle and low_friction runs (warm started, against DAQP):
# * condensed QPs (12 variables in u, no equality rows, P ~ I: well scaled): eps_abs 1e-6 without Ruiz
#   scaling, rho adapted every 25 iterations -> max |du| 1e-6 N·m in 35 iterations, 28 % less time than
#   eps_abs 1e-7 with scaling (7e-8 N·m); no answer rejected by the KKT check;
# * full QPs (42 variables, 30 equality rows, 1e-5 regularisation on vdot and lambda): the weak curvature
#   turns residuals into torque error -- eps_abs 1e-6 -> 3.5e-3 N·m, 1e-7 -> 3e-4, 1e-8 (with scaling)
#   -> 5e-5 N·m at +5 % time. Hence ``settings_with_equalities``, merged over ``settings`` for problems
#   with equality rows.
# Polishing is off: it factorises a new KKT per solve and prints to stdout when no constraint is active.
# Termination is tested every 5 iterations instead of 25 (fewer wasted iterations when warm started).
DEFAULT_SETTINGS: dict[str, Any] = {
    "eps_abs": 1e-6,
    "eps_rel": 0.0,
    "scaling": 0,
    "adaptive_rho_interval": 25,
    "polishing": False,
    "check_termination": 5,
    "max_iter": 20000,
    "verbose": False,
}
DEFAULT_SETTINGS_WITH_EQUALITIES: dict[str, Any] = {"eps_abs": 1e-8, "scaling": 10}
# OSQP's infinity (osqp.constant("OSQP_INFTY")): bounds beyond it are clipped to it, as osqp.OSQP does
OSQP_INFTY = 1e30


class OsqpPersistent(PersistentBackend):
    name = "osqp"
    package = "osqp"

    def __init__(self, settings: dict[str, Any] | None = None,
                 settings_with_equalities: dict[str, Any] | None = None, drop_vacuous_rows: bool = True,
                 **kwargs: Any) -> None:  # fmt: skip
        super().__init__({**DEFAULT_SETTINGS, **dict(settings or {})}, **kwargs)
        self.drop_vacuous_rows = flag("solver.drop_vacuous_rows", drop_vacuous_rows)
        self._kept_patterns: dict[bytes, tuple] = {}  # vacuous-row mask -> pattern of the kept G rows
        self._vac_bytes = self._g_rows_of = b""
        self.settings["warm_starting"] = self.warm_start  # off: every solve starts from zero
        with_eq = settings_with_equalities
        if with_eq is None:
            with_eq = DEFAULT_SETTINGS_WITH_EQUALITIES
        self.settings_with_equalities = check_settings(with_eq, "solver.settings_with_equalities")
        self._solver = None

    def settings_for(self, problem: QPProblem) -> dict[str, Any]:
        """The OSQP settings used for ``problem``: ``settings``, with ``settings_with_equalities`` merged
        over them when it has equality rows."""
        if problem.A.shape[0]:
            return {**self.settings, **self.settings_with_equalities}
        return dict(self.settings)

    def describe(self) -> dict[str, object]:
        return {**super().describe(), "settings_with_equalities": dict(self.settings_with_equalities),
                "drop_vacuous_rows": self.drop_vacuous_rows}  # fmt: skip

    def _layout_key(self, problem: QPProblem) -> tuple:
        """The base layout plus the sparsity pattern of the G rows passed to OSQP (vacuous ones left out):
        with the condensed formulation's dense G the same for every stance set with the same number of
        vacuous rows, so a stance change keeps the solver and its warm start."""
        key = super()._layout_key(problem)
        if not self.drop_vacuous_rows:
            return key
        vac = self._vac_bytes = self.vacuous_rows(problem).tobytes()
        pattern = self._kept_patterns.get(vac)
        if pattern is None:
            if len(self._kept_patterns) > 64:
                self._kept_patterns.clear()
            kept = problem.G_pattern[~self._vacuous]
            pattern = self._kept_patterns[vac] = (kept.shape, kept.tobytes())
        return key + pattern

    def _forget(self) -> None:
        self._solver = None

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        if fresh:
            self._structures(problem)
        elif self.drop_vacuous_rows and self._vac_bytes != self._g_rows_of:  # same pattern, other rows
            self._g_rows = np.flatnonzero(~self._vacuous)
            self._g_rows_of = self._vac_bytes
        self._gather(problem)

    def _structures(self, problem: QPProblem) -> None:
        n, m_eq = problem.n, problem.A.shape[0]
        vacuous = self.vacuous_rows(problem) if self.drop_vacuous_rows else np.zeros(problem.G.shape[0], bool)
        self._g_rows = np.flatnonzero(~vacuous)  # G rows passed to OSQP
        self._g_rows_of = vacuous.tobytes()
        m_in = self._g_rows.shape[0]
        self._n, self._m_eq, self._m_in, self._m_in_all = n, m_eq, m_in, problem.G.shape[0]
        self._bounded = np.flatnonzero(np.isfinite(problem.lb) | np.isfinite(problem.ub))
        eye_rows = np.eye(n, dtype=bool)[self._bounded]
        self._P_pat = PatternCSC(problem.P_pattern | problem.P_pattern.T, upper_only=True)
        self._C_pat = PatternCSC(np.vstack([problem.A_pattern, problem.G_pattern[self._g_rows], eye_rows]))
        m = self._C_pat.shape[0]
        self._Px, self._Cx = np.zeros(self._P_pat.nnz), np.zeros(self._C_pat.nnz)
        self._q, self._l, self._u = np.zeros(n), np.empty(m), np.empty(m)

    def _gather(self, problem: QPProblem) -> None:
        p = problem
        _gather(p.P, p.q, p.A, p.b, p.G, p.h, p.lb, p.ub, self._g_rows, self._bounded, self._P_pat.rows,
                self._P_pat.cols, self._C_pat.rows, self._C_pat.cols, self._Px, self._Cx, self._q, self._l,
                self._u)  # fmt: skip

    def _setup(self, problem: QPProblem) -> None:
        import osqp

        P = sp.csc_matrix((self._Px, self._P_pat.indices, self._P_pat.indptr), shape=self._P_pat.shape)
        C = sp.csc_matrix((self._Cx, self._C_pat.indices, self._C_pat.indptr), shape=self._C_pat.shape)
        wrapper = osqp.OSQP()
        wrapper.setup(P, self._q, C, self._l, self._u, **self.settings_for(problem))
        self._solver = wrapper._solver  # the compiled solver: updates and solves go to it directly (below)
        self._solved = int(osqp.SolverStatus.OSQP_SOLVED)

    def _update(self, problem: QPProblem) -> None:
        # The compiled solver's own calls, as osqp.OSQP.update makes them, without its Python bookkeeping
        # (a clip of l and u, a copy for its derivative cache: ~20 µs a tick). _gather writes the bounds
        # clipped to +-OSQP_INFTY already, the values OSQP.update would pass.
        self._solver.update_data_vec(q=self._q, l=self._l, u=self._u)
        self._solver.update_data_mat(P_x=self._Px, P_i=None, A_x=self._Cx, A_i=None)

    def _solve(self) -> NativeResult:
        s = self._solver
        s.solve()  # osqp.OSQP.solve calls this, then copies every info field into a namespace (~15 µs)
        info = s.info
        status, iterations = str(info.status), int(info.iter)
        if int(info.status_val) != self._solved:
            return NativeResult(None, False, failure_reason(status, max_iter_marker="max"), iterations)
        m_eq, m_in = self._m_eq, self._m_in
        x, y = s.solution.x, s.solution.y
        z_box, z = np.zeros(self._n), np.zeros(self._m_in_all)  # left-out rows: multiplier 0
        z_box[self._bounded] = y[m_eq + m_in :]
        z[self._g_rows] = y[m_eq : m_eq + m_in]
        return NativeResult(np.array(x), True, status, iterations, y=np.array(y[:m_eq]), z=z, z_box=z_box)


@njit(cache=True, nogil=True)
def _gather(P, q, A, b, G, h, lb, ub, g_rows, bounded, P_rows, P_cols, C_rows, C_cols, Px, Cx, q_out, l_out,
            u_out):  # pragma: no cover - compiled  # fmt: skip
    """OSQP's data in the fixed CSC orders: P's upper triangle, C = [A; G[g_rows]; unit rows of the
    bounded variables]; l_out <= C x <= u_out with (b, b), (-inf, h), (lb, ub)."""
    m_eq, m_in = A.shape[0], g_rows.shape[0]
    for k in range(Px.shape[0]):
        Px[k] = P[P_rows[k], P_cols[k]]
    for k in range(Cx.shape[0]):
        r, c = C_rows[k], C_cols[k]
        Cx[k] = A[r, c] if r < m_eq else (G[g_rows[r - m_eq], c] if r < m_eq + m_in else 1.0)
    q_out[:] = q
    for r in range(m_eq):
        l_out[r], u_out[r] = max(b[r], -OSQP_INFTY), min(b[r], OSQP_INFTY)
    for r in range(m_in):
        l_out[m_eq + r], u_out[m_eq + r] = -OSQP_INFTY, min(h[g_rows[r]], OSQP_INFTY)
    for i in range(bounded.shape[0]):
        l_out[m_eq + m_in + i] = max(lb[bounded[i]], -OSQP_INFTY)
        u_out[m_eq + m_in + i] = min(ub[bounded[i]], OSQP_INFTY)
