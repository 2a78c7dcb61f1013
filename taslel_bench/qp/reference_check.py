"""Correctness in every run: the tight reference solve of the backend's own QP on every k-th filtered tick.

On tick k with ``k % every == 0`` the QP the backend was given this tick (:attr:`SafetyFilter.backend_problem`,
full or condensed, untouched until the next tick) is solved again by the reference (``conf/solver/reference.yaml``:
quadprog cross-checked by DAQP, exact up to round-off), *off the clock*: the episode subtracts its time from
``wall_time_s`` like the recording's. The torque error [N·m] is max_j |u_j - u_ref,j| of the backend's answer
(``qp_u_error_nm`` in ``steps.parquet``, NaN on unchecked ticks). A tick whose backend said "solved" but whose u
is farther than ``tol_nm`` from the reference is *solved but wrong*.

In the episode the checks are amortised (:meth:`ReferenceCheck.keep` and :meth:`ReferenceCheck.flush`): a
checked tick only copies its QP and the backend's answer; the reference solves them in a batch between ticks
(every :data:`DEFAULT_BATCH` checks and at the end of each chunk of the trace), with the same results as
solving each at once (both reference solvers set up from scratch on every call). One reference solve inside
the loop every k-th tick evicted the tick's code and data from the caches: the next three ticks ran ~100 µs
slower in total.

Summary keys (:func:`reference_metrics`): ``qp_reference_checks`` (ticks compared), ``qp_reference_every``,
``qp_reference_tol_nm``, ``qp_reference_failed`` (ticks whose reference itself did not confirm an answer),
``u_error_nm_max``, ``u_error_nm_p99``, ``qp_wrong_rate`` (share of compared ticks solved but wrong), and the
deadline misses of the backend's solve time: ``qp_deadline_miss_rate`` (solve longer than the control period),
``qp_solve_over_1ms_rate``.
"""

from __future__ import annotations

import math

import numpy as np
from omegaconf import DictConfig, OmegaConf

from taslel_bench.config.compose import CONF_DIR
from taslel_bench.interfaces import QPBackend, QPProblem

ONE_MS_US = 1000.0  # [µs]
DEFAULT_BATCH = 100  # checks kept before the episode solves them (bounded memory: ~3.3 MB for the full QP)


class ReferenceCheck:
    """See module doc."""

    def __init__(self, reference: QPBackend, every: int, tol_nm: float, batch: int = DEFAULT_BATCH) -> None:
        self.reference = reference
        self.every = int(every)
        self.tol_nm = float(tol_nm)
        self.batch = int(batch)
        self.failed = 0  # ticks whose reference did not confirm an answer
        self._kept: list[tuple[int, QPProblem, np.ndarray]] = []  # (tick, QP, backend's x) awaiting the reference

    def reset(self) -> None:
        self.failed = 0
        self._kept = []
        self.reference.reset()

    def checks(self, k: int, solution) -> bool:
        """Whether tick ``k``'s answer (a :class:`QPSolution`, or None when the backend raised) is checked: a
        k-th tick whose backend solved (a failed solve is counted by ``qp_failed_rate``)."""
        return not (k % self.every or solution is None or not solution.ok)

    def on_tick(self, k: int, problem: QPProblem, solution) -> float:
        """max |u - u_ref| [N·m] of tick ``k``'s answer to ``problem``, solved at once; NaN when the tick is
        not checked (:meth:`checks`) or the reference confirms no answer."""
        return self._error(problem, solution.x) if self.checks(k, solution) else math.nan

    def keep(self, k: int, problem: QPProblem, solution) -> None:
        """Tick ``k``'s check for later (:meth:`flush`): copies of ``problem``'s values and the answer's x,
        if the tick is checked (:meth:`checks`). ``due`` says when enough are kept."""
        if self.checks(k, solution):
            self._kept.append((k, problem.copy(), solution.x.copy()))

    @property
    def due(self) -> bool:
        """``batch`` checks are kept: time to :meth:`flush` them."""
        return len(self._kept) >= self.batch

    def flush(self) -> list[tuple[int, float]]:
        """Solve the kept checks by the reference, in tick order: (tick, max |u - u_ref| [N·m] or NaN)."""
        out = [(k, self._error(problem, x)) for k, problem, x in self._kept]
        self._kept = []
        return out

    def _error(self, problem: QPProblem, x: np.ndarray) -> float:
        """max |u - u_ref| [N·m] of the backend's ``x`` against the reference's answer to ``problem`` (NaN
        and counted in ``failed`` when the reference confirms none)."""
        ref = self.reference.solve(problem)
        if not ref.ok:
            self.failed += 1
            return math.nan
        assert ref.x is not None  # ok: a solution
        u = problem.layout.get("u", slice(None))
        return float(np.max(np.abs(x[u] - ref.x[u])))


def reference_metrics(check: ReferenceCheck | None, u_error_nm: np.ndarray, qp_solve_us: np.ndarray,
                      control_dt_s: float) -> dict[str, float]:  # fmt: skip
    """The summary keys of the module doc from the trace's per-tick ``u_error_nm`` and ``qp_solve_us``."""
    n = u_error_nm.shape[0]
    solve = qp_solve_us[:n]
    solve = solve[np.isfinite(solve)]
    period_us = control_dt_s * 1e6
    out: dict[str, float] = {
        "qp_deadline_miss_rate": float(np.mean(solve > period_us)) if solve.size else math.nan,
        "qp_solve_over_1ms_rate": float(np.mean(solve > ONE_MS_US)) if solve.size else math.nan,
    }
    if check is None:
        return out
    err = u_error_nm[np.isfinite(u_error_nm)]
    out.update(
        qp_reference_every=check.every,
        qp_reference_tol_nm=check.tol_nm,
        qp_reference_checks=int(err.size),
        qp_reference_failed=int(check.failed),
        u_error_nm_max=float(err.max()) if err.size else math.nan,
        u_error_nm_p99=float(np.percentile(err, 99)) if err.size else math.nan,
        qp_wrong_rate=float(np.mean(err > check.tol_nm)) if err.size else math.nan,
    )
    return out


def reference_check(cfg: DictConfig) -> ReferenceCheck | None:
    """The run's check from ``record.reference_every`` (0: None) and ``record.reference_tol_nm``; the
    reference is built from ``conf/solver/reference.yaml`` (the core never imports the solver package)."""
    from hydra.utils import instantiate

    every = int(cfg.record.reference_every)
    if every == 0:
        return None
    tol = float(cfg.record.reference_tol_nm)
    return ReferenceCheck(instantiate(OmegaConf.load(CONF_DIR / "solver" / "reference.yaml")), every, tol)


__all__ = ["ReferenceCheck", "reference_check", "reference_metrics"]
