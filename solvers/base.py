"""Shared pieces of every backend: the extended solution record, the layout key, the final check."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata

import numpy as np

from solvers.checks import Residuals, Tolerances, residuals_at_level, verdict
from taslel_bench.interfaces import SOLVED, QPProblem, QPSolution, all_finite


@dataclass
class BackendSolution(QPSolution):
    """:class:`QPSolution` plus what the benchmark reports.

    Timing split (all [s]):
      * ``solve_time_s`` -- the solver call itself (for qpsolvers: ``solve_problem``, which includes its own
        matrix packing and the native solver's setup; for persistent backends: update + solve);
      * ``setup_time_s`` -- the part of ``solve_time_s`` spent (re)building solver data, when known;
      * ``overhead_s`` -- harness work *outside* the timed call: conversions (sparse CSC, bound rows,
        presolve, pattern values) and the residual check of the answer;
      * ``solve_cpu_time_s`` -- the calling thread's CPU time over the same interval as ``solve_time_s``
        (time the thread waited for a CPU on a busy machine is in ``solve_time_s`` only); nan if not measured.
    """

    overhead_s: float = 0.0
    native_status: str = ""  # the solver's own status string
    residuals: Residuals | None = None
    y: np.ndarray | None = None  # equality multipliers (original rows)
    z: np.ndarray | None = None  # inequality multipliers (original G rows)
    z_box: np.ndarray | None = None  # bound multipliers (n)
    solve_cpu_time_s: float = float("nan")


def layout_key(problem: QPProblem) -> tuple:
    """Everything that forces a persistent solver to set up again: shapes, patterns, which bounds are finite."""
    return (
        problem.n,
        problem.A.shape[0],
        problem.G.shape[0],
        problem.P_pattern.tobytes(),
        problem.A_pattern.tobytes(),
        problem.G_pattern.tobytes(),
        np.isfinite(problem.lb).tobytes(),
        np.isfinite(problem.ub).tobytes(),
    )


def invalid_data(problem: QPProblem) -> str | None:
    """A reason if the problem holds NaN/inf where only finite numbers belong (some solvers loop forever
    on NaN, e.g. ProxQP through qpsolvers), else None. One reduction per array in the common case."""
    total = sum(float(np.sum(a)) for a in (problem.P, problem.q, problem.A, problem.b, problem.G, problem.h))
    if not np.isfinite(total):
        for label, a in (("P", problem.P), ("q", problem.q), ("A", problem.A), ("b", problem.b),
                         ("G", problem.G), ("h", problem.h)):  # fmt: skip
            if not np.all(np.isfinite(a)):
                return f"error: non-finite values in {label}"
    if np.isnan(np.sum(problem.lb)) or np.isnan(np.sum(problem.ub)):
        return "error: NaN or wrong-signed infinity in lb/ub"
    return None


def package_version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def checked(
    problem: QPProblem,
    x: np.ndarray | None,
    native_ok: bool,
    native_status: str,
    tol: Tolerances,
    solve_time_s: float,
    *,
    y: np.ndarray | None = None,
    z: np.ndarray | None = None,
    z_box: np.ndarray | None = None,
    iterations: int | None = None,
    setup_time_s: float = 0.0,
    overhead_s: float = 0.0,
) -> BackendSolution:
    """Turn a native result into a :class:`BackendSolution`, checking it against the original problem.

    A solver that reports failure keeps its own status; one that reports success must also pass
    :func:`solvers.checks.verdict`, else the status says which residual is bad (``x`` is still returned for
    diagnosis but ``ok`` is False)."""
    if x is None or not native_ok:
        return BackendSolution(
            None, native_status or "failed", solve_time_s, iterations, setup_time_s, overhead_s, native_status
        )
    x = np.array(x, dtype=float, copy=True)
    if not all_finite(x):
        return BackendSolution(
            None, "non-finite solution", solve_time_s, iterations, setup_time_s, overhead_s, native_status
        )
    res = residuals_at_level(problem, x, y, z, z_box, tol.level)
    status = verdict(res, tol)
    return BackendSolution(
        x, status, solve_time_s, iterations, setup_time_s, overhead_s, native_status, res, y, z, z_box
    )


__all__ = ["SOLVED", "BackendSolution", "checked", "invalid_data", "layout_key", "package_version"]
