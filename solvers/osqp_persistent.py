"""Persistent OSQP: one ``osqp.OSQP`` per layout, values updated in the fixed pattern order, warm started.

Constraint rows passed to OSQP (l <= C x <= u): the equalities (l = u = b), the inequalities
(l = -inf, u = h), then one unit row per variable with a finite bound (l = lb, u = ub). P is passed as its
upper triangle. The CSC structures come from the problem's constant masks (:mod:`solvers.sparse`), so
``update(Px=..., Ax=...)`` can send all values in one go every tick.

Warm start: OSQP keeps its last iterate (x, y) in the workspace and starts the next solve from it when
its ``warm_starting`` setting is on; ``warm_start=False`` sets it off (every solve starts from zero).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from solvers.persistent import NativeResult, PersistentBackend, failure_reason
from solvers.sparse import PatternCSC
from taslel_bench.interfaces import QPProblem

# Accurate u (DESIGN.md: defaults are off by ~0.05-0.08 N·m): tight absolute tolerance, no relative one.
# Measured on 1500 consecutive episode QPs: eps_abs 1e-6 -> max |du| 2e-5 N·m (polishing changes nothing
# but costs ~25 % time); 1e-7 -> 2e-6 N·m at about the same speed; 1e-5 -> 56 answers rejected by the check.
# Termination is tested every 5 iterations instead of 25 (fewer wasted iterations when warm started).
DEFAULT_SETTINGS: dict[str, Any] = {
    "eps_abs": 1e-7,
    "eps_rel": 0.0,
    "polishing": False,
    "check_termination": 5,
    "max_iter": 20000,
    "verbose": False,
}


class OsqpPersistent(PersistentBackend):
    name = "osqp_persistent"
    package = "osqp"

    def __init__(self, settings: dict[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__({**DEFAULT_SETTINGS, **dict(settings or {})}, **kwargs)
        self.settings["warm_starting"] = self.warm_start  # off: every solve starts from zero
        self._solver = None

    def _forget(self) -> None:
        self._solver = None

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        if fresh:
            self._structures(problem)
        self._gather(problem)

    def _structures(self, problem: QPProblem) -> None:
        n, m_eq, m_in = problem.n, problem.A.shape[0], problem.G.shape[0]
        self._n, self._m_eq, self._m_in = n, m_eq, m_in
        self._bounded = np.flatnonzero(np.isfinite(problem.lb) | np.isfinite(problem.ub))
        eye_rows = np.eye(n, dtype=bool)[self._bounded]
        self._P_pat = PatternCSC(problem.P_pattern | problem.P_pattern.T, upper_only=True)
        self._C_pat = PatternCSC(np.vstack([problem.A_pattern, problem.G_pattern, eye_rows]))
        self._C = np.zeros(self._C_pat.shape)
        self._C[m_eq + m_in :] = np.eye(n)[self._bounded]
        m = self._C.shape[0]
        self._l, self._u = np.empty(m), np.empty(m)
        self._l[m_eq : m_eq + m_in] = -np.inf

    def _gather(self, problem: QPProblem) -> None:
        m_eq, m_in = self._m_eq, self._m_in
        self._C[:m_eq] = problem.A
        self._C[m_eq : m_eq + m_in] = problem.G
        self._Px = self._P_pat.values(problem.P)
        self._Cx = self._C_pat.values(self._C)
        self._q = problem.q.copy()
        self._l[:m_eq] = self._u[:m_eq] = problem.b
        self._u[m_eq : m_eq + m_in] = problem.h
        self._l[m_eq + m_in :] = problem.lb[self._bounded]
        self._u[m_eq + m_in :] = problem.ub[self._bounded]

    def _setup(self, problem: QPProblem) -> None:
        import osqp

        P = sp.csc_matrix((self._Px, self._P_pat.indices, self._P_pat.indptr), shape=self._P_pat.shape)
        C = sp.csc_matrix((self._Cx, self._C_pat.indices, self._C_pat.indptr), shape=self._C_pat.shape)
        self._solver = osqp.OSQP()
        self._solver.setup(P, self._q, C, self._l, self._u, **self.settings)

    def _update(self, problem: QPProblem) -> None:
        self._solver.update(q=self._q, l=self._l, u=self._u, Px=self._Px, Ax=self._Cx)

    def _solve(self) -> NativeResult:
        import osqp

        r = self._solver.solve(raise_error=False)
        status = str(r.info.status)
        ok = r.info.status_val == osqp.SolverStatus.OSQP_SOLVED
        if not ok:
            return NativeResult(None, False, failure_reason(status, max_iter_marker="max"), int(r.info.iter))
        m_eq, m_in = self._m_eq, self._m_in
        z_box = np.zeros(self._n)
        z_box[self._bounded] = r.y[m_eq + m_in :]
        return NativeResult(
            np.array(r.x), True, status, int(r.info.iter),
            y=np.array(r.y[:m_eq]), z=np.array(r.y[m_eq : m_eq + m_in]), z_box=z_box,
        )  # fmt: skip
