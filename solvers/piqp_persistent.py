"""Persistent PIQP (proximal interior point): set up once per layout, ``update`` with new values each tick.

``backend="dense"`` (default; the QP is small and fairly dense) uses ``piqp.DenseSolver``;
``backend="sparse"`` uses ``piqp.SparseSolver`` with CSC matrices on the constant masks. Inequalities go in
as ``-inf <= G x <= h``, bounds natively (PIQP accepts infinite entries).

Inert rows: PIQP 0.7 reports PRIMAL_INFEASIBLE on feasible QPs that contain an identically-zero G row with
a large right-hand side (the filter's inactive ECBF rows, ``0 <= 1e6``); setting that h to +inf instead is
accepted at setup but not across ``update`` calls (rows switching between inert and active break it again).
So the inert rows are left out, and the set of inert rows is part of the layout: a stance change (every
half gait period) costs one new setup. An interior-point method cannot
use the previous solution as a starting point, so "warm" here means: no new setup, factorisation
structures reused.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solvers.persistent import NativeResult, PersistentBackend, failure_reason
from solvers.sparse import PatternCSC
from taslel_bench.interfaces import QPProblem, choice

DEFAULT_SETTINGS: dict[str, Any] = {"eps_abs": 1e-9, "eps_rel": 0.0, "verbose": False}


class PiqpPersistent(PersistentBackend):
    name = "piqp"
    package = "piqp"

    def __init__(self, settings: dict[str, Any] | None = None, backend: str = "dense", **kwargs: Any) -> None:
        choice("solver.backend", backend, ("dense", "sparse"))
        super().__init__({**DEFAULT_SETTINGS, **dict(settings or {})}, **kwargs)
        self.backend = backend
        self._solver = None

    def describe(self) -> dict[str, object]:
        return {**super().describe(), "backend": self.backend}

    def _forget(self) -> None:
        self._solver = None

    def _layout_key(self, problem: QPProblem) -> tuple:
        return super()._layout_key(problem) + (self.vacuous_rows(problem).tobytes(),)

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        if fresh:
            self._m_in = problem.G.shape[0]
            self._rows = np.flatnonzero(~self.vacuous_rows(problem))
            self._hl = np.full(self._rows.size, -np.inf)
            if self.backend == "sparse":
                self._pats = [PatternCSC(problem.P_pattern | problem.P_pattern.T, upper_only=True),
                              PatternCSC(problem.A_pattern), PatternCSC(problem.G_pattern[self._rows])]  # fmt: skip
        G = problem.G[self._rows]
        if self.backend == "dense":
            self._P, self._A, self._G = (np.asfortranarray(m) for m in (problem.P, problem.A, G))
        else:
            self._P, self._A, self._G = (
                p.matrix(m) for p, m in zip(self._pats, (problem.P, problem.A, G), strict=True)
            )
        self._c, self._b, self._h = problem.q.copy(), problem.b.copy(), problem.h[self._rows]
        self._xl, self._xu = problem.lb.copy(), problem.ub.copy()

    def _setup(self, problem: QPProblem) -> None:
        import piqp

        self._solver = piqp.DenseSolver() if self.backend == "dense" else piqp.SparseSolver()
        for key, value in self.settings.items():
            setattr(self._solver.settings, key, value)
        self._solver.setup(self._P, self._c, self._A, self._b, self._G, self._hl, self._h, self._xl, self._xu)

    def _update(self, problem: QPProblem) -> None:
        self._solver.update(
            P=self._P, c=self._c, A=self._A, b=self._b, G=self._G, h_u=self._h, x_l=self._xl, x_u=self._xu
        )

    def _solve(self) -> NativeResult:
        import piqp

        status = self._solver.solve()
        r = self._solver.result
        iters = int(r.info.iter)
        if status != piqp.Status.PIQP_SOLVED:
            return NativeResult(None, False, failure_reason(status), iters)
        z = np.zeros(self._m_in)
        z[self._rows] = np.asarray(r.z_u) - np.asarray(r.z_l)
        return NativeResult(
            np.array(r.x), True, str(status), iters,
            y=np.array(r.y), z=z, z_box=np.asarray(r.z_bu) - np.asarray(r.z_bl),
        )  # fmt: skip
