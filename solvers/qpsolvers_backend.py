"""Any solver installed behind ``qpsolvers``, by name, with its native settings (set up on every call): the
per-call route, ``solver=qpsolvers solver.name=<name>`` (:func:`qpsolvers_route`)."""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from solvers.base import BackendSolution, checked, invalid_data, package_version
from solvers.checks import Tolerances
from solvers.presolve import Reduced, reduce
from solvers.qpsolvers_settings import qpsolvers_defaults
from solvers.settings import check_settings
from solvers.sparse import PatternCache
from taslel_bench.interfaces import QPProblem, choice, fail, flag

# Solvers whose qpsolvers interface passes lb/ub to the native solver (others turn them into G rows,
# infinite ones included): for the rest we pass only the finite bounds, as rows.
NATIVE_BOX = frozenset({"daqp", "proxqp", "piqp", "highs", "qpalm", "qpswift", "hpipm"})
# Solvers that need the implied swing-foot friction rows removed (see solvers.presolve).
NEEDS_PRESOLVE = frozenset({"quadprog"})
# Solvers that (practically) never return on NaN input: the problem is checked for NaN/inf first.
HANG_ON_NAN = frozenset({"proxqp"})
# Solvers whose qpsolvers interface uses ``initvals`` (a primal initial guess); the others ignore it.
USES_INITVALS = frozenset({"osqp", "proxqp", "daqp"})
# qpsolvers distribution name -> Python distribution to report the version of.
DISTRIBUTIONS = {"proxqp": "proxsuite", "highs": "highspy", "qpalm": "qpalm", "kvxopt": "kvxopt"}


def installed_solvers() -> list[str]:
    import qpsolvers

    return sorted(qpsolvers.available_solvers)


def failure_reason(native: str) -> str:
    """Short, solver-independent failure status from a native status string."""
    low = native.lower().replace("_", " ")
    if "infeas" in low:
        return "infeasible"
    if "max iter" in low or "maxiter" in low or "iteration limit" in low:
        return "max_iter"
    if "time" in low and "limit" in low:
        return "time_limit"
    return f"failed: {native}"


def _iterations(extras: Mapping[str, Any] | None) -> int | None:
    """Iteration count from ``Solution.extras``, wherever this solver's wrapper puts it."""
    if not extras:
        return None
    if "iterations" in extras:  # quadprog: [iterations, inactivated constraints]
        return int(np.atleast_1d(extras["iterations"])[0])
    info = extras.get("info")
    for attr in ("iter", "iterations", "iter_ext"):
        if info is not None and hasattr(info, attr):
            return int(getattr(info, attr))
    return None


class QpsolversBackend:
    """``qpsolvers.solve_problem`` with a given solver.

    Args:
        solver: a name in ``qpsolvers.available_solvers``.
        settings: native solver settings forwarded as keyword arguments (e.g. ``eps_abs`` for OSQP).
        matrices: ``"dense"``, ``"sparse"`` or ``"auto"`` (dense if the solver has a dense interface).
        bounds: ``"native"`` (lb/ub with +-inf), ``"rows"`` (finite bounds as G rows) or ``"auto"``.
        presolve: drop implied / zero G rows (:mod:`solvers.presolve`); None = only where needed.
        check: tolerances for accepting a solution the solver calls optimal (:mod:`solvers.checks`).
        warm_start: pass the previous solved call's x as ``initvals`` (only solvers in
            :data:`USES_INITVALS` use it; :attr:`supports_warm_start` says so). ``reset()`` forgets it.
    """

    def __init__(
        self,
        solver: str,
        settings: Mapping[str, Any] | None = None,
        matrices: str = "auto",
        bounds: str = "auto",
        presolve: bool | None = None,
        check: Mapping[str, float] | None = None,
        warm_start: bool = False,
    ) -> None:
        import qpsolvers

        available = installed_solvers()
        if solver not in available:
            raise fail("solver.solver", solver,
                       f"this qpsolvers solver is not installed; available: {', '.join(available)}")
        choice("solver.matrices", matrices, ("auto", "dense", "sparse"))
        choice("solver.bounds", bounds, ("auto", "native", "rows"))
        if presolve is not None:
            flag("solver.presolve", presolve)
        if matrices == "auto":
            matrices = "dense" if solver in qpsolvers.dense_solvers else "sparse"
        if matrices == "sparse" and solver not in qpsolvers.sparse_solvers:
            raise fail("solver.matrices", matrices, f"{solver} has no sparse interface in qpsolvers")
        if bounds == "auto":
            bounds = "native" if solver in NATIVE_BOX else "rows"
        self.solver = solver
        self.name = solver
        self.settings = check_settings(settings)
        self.matrices, self.bounds = matrices, bounds
        self.presolve = (solver in NEEDS_PRESOLVE) if presolve is None else bool(presolve)
        self.tol = Tolerances(**dict(check or {}))
        self._patterns = PatternCache()
        self.warm_start = flag("solver.warm_start", warm_start)
        self.supports_warm_start = solver in USES_INITVALS
        self._x_prev: np.ndarray | None = None

    def reset(self) -> None:
        """Set up on every call: only the warm-start guess (``warm_start=True``) is forgotten."""
        self._x_prev = None

    def describe(self) -> dict[str, object]:
        return {
            "name": self.name,
            "kind": "qpsolvers",
            "package": DISTRIBUTIONS.get(self.solver, self.solver),
            "version": package_version(DISTRIBUTIONS.get(self.solver, self.solver)),
            "qpsolvers": package_version("qpsolvers"),
            "settings": dict(self.settings),
            "matrices": self.matrices,
            "bounds": self.bounds,
            "presolve": self.presolve,
            "warm_start": self.warm_start,
            "check": self.tol.as_dict(),
        }

    def _qpsolvers_problem(self, red: Reduced, problem: QPProblem):
        import qpsolvers

        P, G, A = red.P, red.G, red.A
        if self.matrices == "sparse":
            P = self._patterns.get(problem.P_pattern).matrix(P)
            A = self._patterns.get(problem.A_pattern).matrix(A)
            G = self._patterns.get(red.g_mask).matrix(G) if G.shape[0] else None
        elif not G.shape[0]:
            G = None
        return qpsolvers.Problem(P, red.q, G, red.h if G is not None else None, A, red.b, red.lb, red.ub)

    def solve(self, problem: QPProblem) -> BackendSolution:
        import qpsolvers

        t0 = time.perf_counter()
        bad = invalid_data(problem) if self.solver in HANG_ON_NAN else None
        if bad:
            return BackendSolution(None, bad, 0.0, overhead_s=time.perf_counter() - t0)
        try:
            red = reduce(problem, self.bounds == "rows", self.presolve)
            qpp = self._qpsolvers_problem(red, problem)
        except Exception as exc:  # malformed problem: report, do not raise
            return BackendSolution(None, f"error: {type(exc).__name__}: {exc}", 0.0)
        t1, cpu1 = time.perf_counter(), time.thread_time()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # failures are reported through the status instead
                sol = qpsolvers.solve_problem(qpp, solver=self.solver, initvals=self._x_prev, **self.settings)
            t2, cpu2 = time.perf_counter(), time.thread_time()
        except Exception as exc:  # qpsolvers raises ProblemError / SolverError on some failures
            return BackendSolution(None, f"error: {type(exc).__name__}: {exc}", time.perf_counter() - t1)
        overhead = t1 - t0
        z, z_box = red.original_duals(problem.n, problem.G.shape[0], sol.z, sol.z_box)
        native = "found" if sol.found else "not found"
        if sol.extras and "status" in sol.extras:
            native = str(sol.extras["status"])
        elif sol.extras and hasattr(sol.extras.get("info"), "status"):
            native = str(sol.extras["info"].status)
        out = checked(
            problem, sol.x, bool(sol.found), native if sol.found else failure_reason(native), self.tol, t2 - t1,
            y=sol.y, z=z, z_box=z_box, iterations=_iterations(sol.extras),
            setup_time_s=float(getattr(sol, "build_time", 0.0) or 0.0), overhead_s=overhead,
        )  # fmt: skip
        out.solve_cpu_time_s = cpu2 - cpu1  # the thread's CPU time over the solve_time_s interval
        if self.warm_start:
            self._x_prev = out.x if out.ok else None
        out.overhead_s += time.perf_counter() - t2
        return out


def qpsolvers_route(name: str, settings: Mapping[str, Any] | None = None, tuned: bool = True,
                    **kwargs: Any) -> QpsolversBackend:  # fmt: skip
    """The per-call route of solver ``name`` (``conf/solver/qpsolvers.yaml``): its accurate settings from
    :mod:`solvers.qpsolvers_settings` (``tuned=False``: the solver's own defaults) with ``settings`` merged
    over them; ``check``, ``presolve`` ... given in ``kwargs`` replace the table's. Its :attr:`name` is
    ``qpsolvers:<name>``."""
    if not isinstance(name, str):
        raise fail("solver.name", name, "must be a qpsolvers solver name")
    defaults = qpsolvers_defaults(name) if flag("solver.tuned", tuned) else {}
    native = {**dict(defaults.pop("settings", None) or {}), **dict(check_settings(settings))}
    kwargs = {**defaults, **{k: v for k, v in kwargs.items() if v is not None}}
    try:
        backend = QpsolversBackend(name, settings=native, **kwargs)
    except ValueError as exc:
        if str(exc).startswith("solver.solver="):
            raise fail("solver.name", name, str(exc).split(": ", 1)[1]) from None
        raise
    backend.name = f"qpsolvers:{name}"
    return backend
