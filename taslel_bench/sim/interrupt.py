"""A run stopped by its user (Ctrl-C: SIGINT) or its scheduler (SIGTERM) ends cleanly, with one line.

While a run holds its folder, :class:`InterruptGuard` owns SIGINT and SIGTERM. During the episode a signal
asks it to stop at its next progress point (every ``PROGRESS_EVERY_TICKS`` ticks, well under a second): the
episode then processes what it simulated like the end of any run, so ``steps.parquet``, ``events.json`` and
``episode.mcap`` are finished and readable and ``summary.json`` says ``status: interrupted`` with the time
reached. A second signal, or one outside the episode (building, writing), raises :class:`RunInterrupted`
at once. The CLI exits 128 + the signal's number (130 for SIGINT, 143 for SIGTERM).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Self

INTERRUPTED = "interrupted"  # summary status of a run stopped by a signal
HANDLED = (signal.SIGINT, signal.SIGTERM)
DUPLICATE_S = 1.0  # [s] the same signal again within this is one delivery (a second Ctrl-C later ends at once)


class RunInterrupted(BaseException):
    """A signal ended the run before its episode could be stopped cleanly (BaseException: no ``except
    Exception`` of a solver or recorder keeps it from ending the run)."""

    def __init__(self, signum: int, summary: dict | None = None) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum
        self.summary = summary  # the signal came once the episode had ended: the run's (complete) summary

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


PENDING: list[int] = []  # a signal a sweep's worker got outside a run (see hold_signals_between_runs)


def hold_signals_between_runs() -> None:
    """In a sweep's worker process: a SIGINT/SIGTERM that comes outside a run (between jobs, while a job's
    config is composed) is kept, not raised (no traceback, no dead worker); the next run of this worker
    raises :class:`RunInterrupted` before it starts."""

    def keep(signum: int, frame: FrameType | None) -> None:
        if not PENDING:
            PENDING.append(signum)

    if threading.current_thread() is threading.main_thread():
        for signum in HANDLED:
            signal.signal(signum, keep)


class StopRequested(Exception):
    """Raised by the progress hook inside the episode: the episode's own fault handling ends the loop and
    processes the ticks simulated so far (the run then reports ``interrupted``, not an error)."""


class InterruptGuard:
    """``with InterruptGuard() as guard:`` SIGINT/SIGTERM handled as the module doc says (main thread only;
    elsewhere Python's handling stays). ``guard.progress(show)`` is the episode's progress callback."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.defer = False  # True while the episode runs and its files are written: a first signal waits
        self._first_s = 0.0  # [s, monotonic] when the first signal came
        self._previous: dict[int, object] = {}

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        now = time.monotonic()
        if self.signum == signum and now - self._first_s < DUPLICATE_S:
            return  # the same signal twice at once (a Ctrl-C reaches a sweep's worker and is forwarded to it)
        if self.signum is not None or not self.defer:
            self.signum = signum
            raise RunInterrupted(signum)
        self.signum, self._first_s = signum, now  # the episode stops at its next progress point

    def progress(self, show: Callable[[float], None] | None) -> Callable[[float], None]:
        """The episode's progress callback: ``show(t)`` (if any), and the stop when a signal came."""

        def hook(t_s: float) -> None:
            if self.signum is not None:
                raise StopRequested(signal.Signals(self.signum).name)
            if show is not None:
                show(t_s)

        return hook

    @property
    def signal_name(self) -> str:
        return signal.Signals(self.signum).name if self.signum is not None else ""

    def __enter__(self) -> Self:
        if PENDING:  # a signal came to this worker before its run began: the run does not begin
            raise RunInterrupted(PENDING[0])
        if threading.current_thread() is threading.main_thread():
            for signum in HANDLED:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)  # type: ignore[arg-type]
        self._previous.clear()


__all__ = ["INTERRUPTED", "PENDING", "InterruptGuard", "RunInterrupted", "StopRequested", "hold_signals_between_runs"]
