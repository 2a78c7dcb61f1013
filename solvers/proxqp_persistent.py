"""Persistent ProxQP (``proxsuite.proxqp.dense.QP``): ``init`` once per layout, ``update`` each tick, warm
started from the previous primal-dual solution (``WARM_START_WITH_PREVIOUS_RESULT``).

Accuracy trap (docs/concepts.md, measured facts): warm started at ``eps_abs >= 1e-7`` ProxQP can stop after an
iteration or two, primal/dual residuals fine, with u wrong by N·m -- its default termination does not look at the
duality gap. So ``check_duality_gap`` is on with a tight absolute gap tolerance, and the harness check
(:mod:`solvers.checks`) tests the gap again on the original problem.

Inequalities are ``-inf <= G x <= h`` (ProxQP takes infinite entries); bounds go in as ProxQP's native
box constraints.

Warm-start failure: after a stance change the warm-started solve sometimes ends in PRIMAL_INFEASIBLE on a
feasible QP (18 of 500 fixture QPs, in runs of consecutive ticks). A failed warm solve is therefore
redone once with no initial guess (counted in ``cold_retries``, flagged in the native status); a genuinely
infeasible QP fails both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solvers.persistent import NativeResult, PersistentBackend, failure_reason
from taslel_bench.interfaces import QPProblem

DEFAULT_SETTINGS: dict[str, Any] = {
    "eps_abs": 1e-9,
    "eps_rel": 0.0,
    "check_duality_gap": True,
    "eps_duality_gap_abs": 1e-9,
    "eps_duality_gap_rel": 0.0,
    "max_iter": 10000,
    "verbose": False,
}


class ProxqpPersistent(PersistentBackend):
    name = "proxqp"
    package = "proxsuite"
    validate_input = True  # ProxQP loops (practically) forever on NaN input

    def __init__(self, settings: dict[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__({**DEFAULT_SETTINGS, **dict(settings or {})}, **kwargs)
        self._qp = None
        self.cold_retries = 0  # warm-started solves that failed and were redone from scratch

    def _forget(self) -> None:
        self._qp = None

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        if fresh:
            self._l = np.full(problem.G.shape[0], -np.inf)
        self._H, self._g = problem.P.copy(), problem.q.copy()
        self._A, self._b = problem.A.copy(), problem.b.copy()
        self._C, self._u = problem.G.copy(), problem.h.copy()
        self._lb, self._ub = problem.lb.copy(), problem.ub.copy()

    def _setup(self, problem: QPProblem) -> None:
        from proxsuite import proxqp

        n, m_eq, m_in = problem.n, problem.A.shape[0], problem.G.shape[0]
        self._m_in = m_in
        self._qp = proxqp.dense.QP(n, m_eq, m_in, True)
        for key, value in self.settings.items():
            setattr(self._qp.settings, key, value)
        self._qp.settings.initial_guess = (
            proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            if self.warm_start
            else proxqp.InitialGuess.NO_INITIAL_GUESS
        )
        self._qp.init(self._H, self._g, self._A, self._b, self._C, self._l, self._u, self._lb, self._ub)

    def _update(self, problem: QPProblem) -> None:
        self._qp.update(self._H, self._g, self._A, self._b, self._C, self._l, self._u, self._lb, self._ub)

    def _solve(self) -> NativeResult:
        from proxsuite import proxqp

        self._qp.solve()
        r = self._qp.results
        status, iters = r.info.status, int(r.info.iter)
        retried = False
        if status != proxqp.QPSolverOutput.PROXQP_SOLVED and self.warm_start:
            # a warm start across a stance change can end in a false PRIMAL_INFEASIBLE: retry cold
            self._qp.settings.initial_guess = proxqp.InitialGuess.NO_INITIAL_GUESS
            self._qp.solve()
            self._qp.settings.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            r = self._qp.results
            status, iters, retried = r.info.status, iters + int(r.info.iter), True
            self.cold_retries += 1
        if status != proxqp.QPSolverOutput.PROXQP_SOLVED:
            return NativeResult(None, False, failure_reason(status), iters)
        z = np.array(r.z)
        return NativeResult(
            np.array(r.x), True, str(status) + (" (cold retry)" if retried else ""), iters,
            y=np.array(r.y), z=z[: self._m_in], z_box=z[self._m_in :],
        )  # fmt: skip
