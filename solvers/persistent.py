"""Skeleton of a persistent, warm-started native backend.

The solver is set up once per QP *layout* (shapes, sparsity masks, which bounds are finite:
:func:`solvers.base.layout_key`), then each tick only its values are updated and it starts from the last
solution. The filter overwrites one :class:`QPProblem` in place every tick, so subclasses copy whatever
they keep. A layout change (e.g. a problem without ECBF rows after one with) triggers a new setup;
:meth:`reset` forgets the solver and the warm start.

After a failed solve the backend resets itself, so the next tick sets up from scratch instead of warm
starting from a failed (possibly NaN) iterate.

Subclasses implement :meth:`_setup`, :meth:`_update` and :meth:`_solve`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from solvers.base import BackendSolution, checked, invalid_data, layout_key, package_version
from solvers.checks import Tolerances
from solvers.settings import check_settings
from taslel_bench.interfaces import QPProblem, flag

BIG = 1e20  # finite stand-in for an infinite bound, where a solver needs one


@dataclass
class NativeResult:
    """What a native solve returns, duals already in the convention of :mod:`solvers.checks`."""

    x: np.ndarray | None
    ok: bool
    status: str  # native status (or the failure reason when not ok)
    iterations: int | None = None
    y: np.ndarray | None = None
    z: np.ndarray | None = None
    z_box: np.ndarray | None = None


def failure_reason(status: object, max_iter_marker: str = "max_iter") -> str:
    """Short reason for a native status that is not "solved": infeasible, max_iter or failed: <status>."""
    low = str(status).lower()
    if "infeasible" in low:
        return "infeasible"
    if max_iter_marker in low:
        return "max_iter"
    return f"failed: {status}"


class PersistentBackend:
    """Common machinery; see module doc."""

    name = "persistent"
    package = ""
    validate_input = False  # check the problem for NaN/inf first (for solvers that hang on NaN)

    def __init__(self, settings: Mapping[str, Any] | None = None, check: Mapping[str, float] | None = None,
                 warm_start: bool = True) -> None:  # fmt: skip
        self.settings = check_settings(settings)
        self.tol = Tolerances(**dict(check or {}))
        self.warm_start = flag("solver.warm_start", warm_start)
        self._key: tuple | None = None
        self._masks: tuple | None = None  # pattern masks of the last layout key (see _pattern_key)
        self._masks_key: tuple = ()
        self._vacuous: np.ndarray | None = None  # scratch of vacuous_rows
        self.setups = 0  # how many times the solver was (re)built -- for tests and reports

    @property
    def layout(self) -> tuple | None:
        """The QP layout the solver is built for now (None before the first solve)."""
        return self._key

    # ------------------------------------------------------------------ to implement
    def _setup(self, problem: QPProblem) -> None:
        raise NotImplementedError

    def _update(self, problem: QPProblem) -> None:
        raise NotImplementedError

    def _solve(self) -> NativeResult:
        raise NotImplementedError

    def _layout_key(self, problem: QPProblem) -> tuple:
        """What forces a new setup (override to add solver-specific reasons): the shapes and patterns
        (:meth:`_pattern_key`) and which bounds are finite (read every call)."""
        bounds = (np.isfinite(problem.lb).tobytes(), np.isfinite(problem.ub).tobytes())
        return self._pattern_key(problem) + bounds

    def _pattern_key(self, problem: QPProblem) -> tuple:
        """Shapes and sparsity patterns. The pattern masks are constant for a layout (:class:`QPProblem`
        contract), so their bytes are read once per mask object (the objects are kept alive, so ``is``
        cannot match a different, new mask)."""
        masks = (problem.P_pattern, problem.A_pattern, problem.G_pattern)
        if self._masks is None or any(a is not b for a, b in zip(masks, self._masks, strict=True)):
            self._masks = masks
            self._masks_key = layout_key(problem)[:6]
        return self._masks_key

    def vacuous_rows(self, problem: QPProblem) -> np.ndarray:
        """Mask of the G rows that constrain nothing: identically zero with h >= 0 (the inactive friction
        rows of a swing foot, the inactive ECBF rows of stance feet). The array is reused: copy to keep."""
        if self._vacuous is None or self._vacuous.shape[0] != problem.G.shape[0]:
            self._vacuous = np.zeros(problem.G.shape[0], bool)
        _vacuous_rows(problem.G, problem.h, self._vacuous)
        return self._vacuous

    def _prepare(self, problem: QPProblem, fresh: bool) -> None:
        """Gather this tick's values into the backend's own buffers (harness overhead, not timed); on a
        ``fresh`` layout, build those buffers first."""

    def _forget(self) -> None:
        """Drop the native solver object."""

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        self._forget()
        self._key = None

    def describe(self) -> dict[str, object]:
        return {
            "name": self.name,
            "kind": "persistent",
            "package": self.package,
            "version": package_version(self.package),
            "settings": dict(self.settings),
            "warm_start": self.warm_start,
            "check": self.tol.as_dict(),
        }

    def solve(self, problem: QPProblem) -> BackendSolution:
        t0 = time.perf_counter()
        bad = invalid_data(problem) if self.validate_input else None
        if bad:  # keep the solver and its warm start: the next good tick continues from them
            return BackendSolution(None, bad, 0.0, overhead_s=time.perf_counter() - t0)
        try:
            key = self._layout_key(problem)
            fresh = key != self._key
            if fresh:
                self.reset()
            self._prepare(problem, fresh)
            t1, cpu1 = time.perf_counter(), time.thread_time()
            if fresh:
                self._setup(problem)
                self._key = key
                self.setups += 1
            else:
                self._update(problem)
            t2 = time.perf_counter()
            res = self._solve()
            t3, cpu3 = time.perf_counter(), time.thread_time()
        except Exception as exc:  # a native failure must not end the episode
            self.reset()
            return BackendSolution(None, f"error: {type(exc).__name__}: {exc}", time.perf_counter() - t0)
        out = checked(
            problem, res.x, res.ok, res.status, self.tol, t3 - t1, y=res.y, z=res.z, z_box=res.z_box,
            iterations=res.iterations, setup_time_s=t2 - t1, overhead_s=t1 - t0,
        )  # fmt: skip
        out.solve_cpu_time_s = cpu3 - cpu1  # the thread's CPU time over the solve_time_s interval
        if not out.ok:  # never warm start from a failed (possibly NaN) iterate: set up afresh next tick
            self.reset()
        out.overhead_s += time.perf_counter() - t3
        return out


@njit(cache=True, nogil=True)
def _vacuous_rows(G, h, out):  # pragma: no cover - compiled
    """out[r] = G row r is identically zero and 0 <= h[r]."""
    for r in range(G.shape[0]):
        zero = h[r] >= 0.0
        for j in range(G.shape[1]):
            if not zero:
                break
            zero = G[r, j] == 0.0
        out[r] = zero
