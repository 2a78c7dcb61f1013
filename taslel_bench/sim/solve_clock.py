"""Each QP solve timed twice: the backend's own wall-clock timer (``solve_time_s``, ``qp_solve_us``) and the
thread's CPU time over the backend call (``solve_cpu_time_s``, ``qp_solve_cpu_us``).

On a busy machine the wall clock also counts the time the thread waited for a CPU (other processes ran):
a 90 µs solve can read 8 ms. The thread's CPU time (``CLOCK_THREAD_CPUTIME_ID``) counts only the time it
ran, so it measures the solver, not the machine. The project's backends (``solvers/``) measure it over the
same interval as their wall timer; for another backend (one that does not set ``solve_cpu_time_s``) the
wrapper measures it over the whole call (input check, setup or update, solve, answer check): at least the
solver's own CPU time, so a deadline it meets the solve meets. (CPU time is not free of the machine either:
a neighbour's cache pressure makes the same work cost more.)
"""

from __future__ import annotations

import math
import time
from typing import Any


class ThreadTimedBackend:
    """A QP backend whose every answer also carries ``solve_cpu_time_s`` [s] (the calling thread's CPU time
    spent in the solve) and ``setup`` (True: a persistent backend built its solver for a new QP layout in this
    call, ``qp_setup``). Every other attribute is the wrapped backend's."""

    def __init__(self, backend: Any) -> None:
        self.wrapped = backend

    def solve(self, problem: Any) -> Any:
        setups = getattr(self.wrapped, "setups", None)  # a persistent backend counts its (re)builds
        cpu0 = time.thread_time_ns()
        solution = self.wrapped.solve(problem)
        cpu_s = (time.thread_time_ns() - cpu0) * 1e-9
        try:
            if not math.isfinite(getattr(solution, "solve_cpu_time_s", math.nan)):
                solution.solve_cpu_time_s = cpu_s  # else the backend measured it over its own timed interval
            solution.setup = setups is not None and getattr(self.wrapped, "setups", None) != setups
        except AttributeError:  # an answer type with __slots__: the columns stay NaN / False
            pass
        return solution

    def __getattr__(self, name: str) -> Any:
        return getattr(self.wrapped, name)


def time_solves_by_cpu(built: Any) -> None:
    """Wrap the run's filter backend (none without a filter) in :class:`ThreadTimedBackend`."""
    filt = getattr(built, "filter", None)
    if filt is not None and not isinstance(filt.backend, ThreadTimedBackend):
        filt.backend = ThreadTimedBackend(filt.backend)


__all__ = ["ThreadTimedBackend", "time_solves_by_cpu"]
