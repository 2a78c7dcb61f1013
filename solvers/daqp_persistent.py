"""Persistent DAQP (dual active set): one ``daqp.Model`` workspace per layout, ``update`` each tick.

DAQP's constraint layout: the first n entries of ``blower <= . <= bupper`` are simple bounds on x (infinite
bounds become +-1e30, DAQP's infinity), then the rows of ``[G; A]`` (G: ``-1e30 <= G x <= h``; A: equality,
``sense = 5``). Hot start: the workspace keeps the previous working set, and ``update`` without ``sense``
leaves it in place, so the next solve starts from the last active set (about 1 iteration per tick vs ~3
from scratch on a recorded episode). ``warm_start=False`` passes the initial ``sense`` again each tick.
"""

from __future__ import annotations

from ctypes import c_int
from typing import Any

import numpy as np

from solvers.persistent import NativeResult, PersistentBackend
from taslel_bench.interfaces import QPProblem

DAQP_INF = 1e30
DEFAULT_SETTINGS: dict[str, Any] = {}  # exact active-set method: the defaults are accurate here
EQUALITY = 5


class DaqpPersistent(PersistentBackend):
    name = "daqp_persistent"
    package = "daqp"

    def __init__(self, settings: dict[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__({**DEFAULT_SETTINGS, **dict(settings or {})}, **kwargs)
        self._model = None

    def _forget(self) -> None:
        self._model = None

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        n, m_in, m_eq = problem.n, problem.G.shape[0], problem.A.shape[0]
        if fresh:
            self._dims = (n, m_in, m_eq)
            self._M = np.zeros((m_in + m_eq, n))
            self._bu, self._bl = np.empty(n + m_in + m_eq), np.empty(n + m_in + m_eq)
            self._bl[n : n + m_in] = -DAQP_INF
            self._sense = np.zeros(n + m_in + m_eq, dtype=c_int)
            self._sense[n + m_in :] = EQUALITY
            self._y = np.empty(n + m_in + m_eq)  # scratch: (x, G x, A x)
        self._M[:m_in], self._M[m_in:] = problem.G, problem.A
        self._H, self._f = problem.P.copy(), problem.q.copy()
        np.minimum(problem.ub, DAQP_INF, out=self._bu[:n])
        np.maximum(problem.lb, -DAQP_INF, out=self._bl[:n])
        self._bu[n : n + m_in] = problem.h
        self._bu[n + m_in :] = self._bl[n + m_in :] = problem.b

    def _primal_residual(self, x: np.ndarray | None) -> float | None:
        """Largest violation of ``blower <= (x, G x, A x) <= bupper``: the problem's bounds and rows as
        copied this tick (infinite bounds as +-1e30), one matrix product."""
        n = self._dims[0]
        y = self._y
        y[:n] = x
        np.matmul(self._M, x, out=y[n:])
        r = max((y - self._bu).max(), (self._bl - y).max(), 0.0)
        return float(r)  # nan if x had a nan (max() propagates it from the first operand)

    def _setup(self, problem: QPProblem) -> None:
        import daqp

        self._model = daqp.Model()
        self._model.setup(self._H, self._f, self._M, self._bu, self._bl, self._sense)
        if self.settings:
            self._model.settings = dict(self.settings)

    def _update(self, problem: QPProblem) -> None:
        sense = None if self.warm_start else self._sense
        self._model.update(H=self._H, f=self._f, A=self._M, bupper=self._bu, blower=self._bl, sense=sense)

    def _solve(self) -> NativeResult:
        x, _, exitflag, info = self._model.solve()
        iters = int(info["iterations"])
        if exitflag <= 0:
            reason = {-1: "infeasible", -4: "max_iter"}.get(int(exitflag), f"failed: exitflag {exitflag}")
            return NativeResult(None, False, reason, iters)
        n, m_in, _ = self._dims
        lam = info["lam"]  # a new array per solve (as is x): views are safe
        return NativeResult(
            x, True, f"exitflag {exitflag}", iters, y=lam[n + m_in :], z=lam[n : n + m_in], z_box=lam[:n]
        )  # fmt: skip
