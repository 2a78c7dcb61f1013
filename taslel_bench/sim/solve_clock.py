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
    spent in the solve) and ``setup`` (``qp_setup``: True when a persistent backend built its solver for a QP
    layout it had not been built for before in this episode -- a controller can build its layouts before
    its loop starts; a rebuild for a layout seen before is part of the loop's cost and is not flagged). Every
    other attribute is the wrapped backend's."""

    def __init__(self, backend: Any) -> None:
        self.wrapped = backend
        self._layouts_built: set = set()

    def solve(self, problem: Any) -> Any:
        setups = getattr(self.wrapped, "setups", None)  # a persistent backend counts its (re)builds
        cpu0 = time.thread_time_ns()
        solution = self.wrapped.solve(problem)
        cpu_s = (time.thread_time_ns() - cpu0) * 1e-9
        try:
            if not math.isfinite(getattr(solution, "solve_cpu_time_s", math.nan)):
                solution.solve_cpu_time_s = cpu_s  # else the backend measured it over its own timed interval
            solution.setup = self._first_build(setups)
        except AttributeError:  # an answer type with __slots__: the columns stay NaN / False
            pass
        return solution

    def reset(self) -> None:
        """A new episode (the filter resets its backend): its layouts are built anew, each once judged apart."""
        self._layouts_built.clear()
        self.wrapped.reset()

    def _first_build(self, setups_before: int | None) -> bool:
        """The backend was (re)built in this call, for a layout it had not been built for before."""
        if setups_before is None or getattr(self.wrapped, "setups", None) == setups_before:
            return False
        layout = getattr(self.wrapped, "layout", None)
        if layout is None or layout in self._layouts_built:
            return False
        self._layouts_built.add(layout)
        return True

    def __getattr__(self, name: str) -> Any:
        return getattr(self.wrapped, name)


def time_solves_by_cpu(built: Any) -> None:
    """Wrap the run's filter backend (none without a filter) in :class:`ThreadTimedBackend`."""
    filt = getattr(built, "filter", None)
    if filt is not None and not isinstance(filt.backend, ThreadTimedBackend):
        filt.backend = ThreadTimedBackend(filt.backend)


__all__ = ["ThreadTimedBackend", "time_solves_by_cpu"]
