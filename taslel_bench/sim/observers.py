"""The episode's observers: parts that watch a run and never change it.

An observer is any object with some of these methods (each optional; the episode calls only those an
observer has):

* ``start(episode)`` -- a run begins (the plant at its initial state): open files, reset counters;
* ``after_tick(k, t, fres)`` -- control tick ``k`` at episode time ``t`` [s] is done: the plant has stepped,
  the trace (if any) holds the tick, ``episode.sensed`` is still the tick's proprioception (joint state at the
  tick's start, the torque applied on the previous tick) and ``episode.truth`` its ground truth, ``fres`` the
  filter's result (None: no filter this tick), the filter's QP is still the tick's (``episode.filter.backend_problem``);
* ``between_ticks(k, trace)`` -- after tick ``k`` outside the ticks' timers (work that may wait a while);
* ``on_chunk(trace, k0, k1)`` -- ticks ``k0 .. k1 - 1`` of the trace are complete and analysed (derived
  quantities, model residuals), in list order; the trace drops them afterwards (``record.chunk_ticks``);
* ``finish(result)`` -- the run ended (:class:`taslel_bench.record.result.EpisodeResult`).

The episode times every call of an observer and reports the time under the observer's ``clock`` (an
``EpisodeResult.extras`` key, default ``recording_s``), never in ``wall_time_s``: the loop's own cost is what
the benchmark reports. This module adapts the harness's recorders to that shape: the QP recorder
(``record.qps``), the reference check (``record.reference_every``), the MCAP stream (``record.mcap``), the
steps table (steps.parquet) and the summary's metrics stream.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable
from typing import Any, Protocol

from taslel_bench.record.trace import EpisodeTrace

HOOKS = ("start", "after_tick", "between_ticks", "on_chunk", "finish")
DEFAULT_CLOCK = "recording_s"


class QPRecorder(Protocol):
    """What records the filter's QP of a tick (:class:`taslel_bench.record.qpset.QPRecorder`)."""

    def on_tick(self, k: int, t_s: float, problem: Any, result: Any, /) -> None: ...  # called positionally


class FilterQPs:
    """Hands the filter's QP and result of every filtered tick to ``recorder`` (``record.qps``)."""

    def __init__(self, recorder: QPRecorder) -> None:
        self.recorder = recorder
        self._problem = None

    def start(self, episode) -> None:
        self._problem = episode.filter.backend_problem if episode.filter is not None else None

    def after_tick(self, k: int, t: float, fres) -> None:
        if fres is not None:
            self.recorder.on_tick(k, t, self._problem, fres)


class ReferenceChecks:
    """The backend's answers checked against the tight reference QP (``record.reference_every``,
    :class:`taslel_bench.qp.reference_check.ReferenceCheck`): the tick's QP is copied after the tick, solved
    between ticks when enough are kept and at every chunk's end; the errors go into the trace's
    ``qp_u_error_nm`` [N·m]. Must come before the observers that read that column."""

    clock = "reference_s"

    def __init__(self, check) -> None:
        self.check = check
        self._problem = None

    def start(self, episode) -> None:
        self._problem = episode.filter.backend_problem if episode.filter is not None else None
        self.check.reset()

    def after_tick(self, k: int, t: float, fres) -> None:
        if fres is not None:
            self.check.keep(k, self._problem, fres.solve)

    def between_ticks(self, k: int, trace: EpisodeTrace) -> None:
        if self.check.due:
            self._flush(trace)

    def on_chunk(self, trace: EpisodeTrace, k0: int, k1: int) -> None:
        self._flush(trace)

    def _flush(self, trace: EpisodeTrace) -> None:
        for k, error in self.check.flush():
            trace.qp_u_error_nm[k - trace.offset] = error


class StreamedChunks:
    """A stream of the trace's ticks (the MCAP file: :class:`taslel_bench.record.mcap.McapStream`), opened at the
    run's start by ``open_stream()`` and fed ``stream(trace, a, b)`` in pieces ending at multiples of
    ``piece_ticks`` from tick 0 on (one flushed MCAP chunk per second of simulated time). A failure is kept in
    ``error`` (its last traceback line), the stream is abandoned and fed no more; it never ends the episode."""

    def __init__(self, open_stream: Callable[[], Any], piece_ticks: int) -> None:
        self._open, self.piece_ticks = open_stream, max(1, int(piece_ticks))
        self.stream: Any = None
        self.error = ""

    def start(self, episode) -> None:
        if self.stream is None:
            self.stream = self._open()

    def on_chunk(self, trace: EpisodeTrace, k0: int, k1: int) -> None:
        a = k0
        while a < k1 and not self.error:
            b = min(k1, (a // self.piece_ticks + 1) * self.piece_ticks)
            try:
                self.stream(trace, a, b)
            except Exception:  # recording must not lose the run: the first error is kept, the stream stops
                self.error = traceback.format_exc().strip().splitlines()[-1]
                self.stream.abandon()
            a = b


class StepsTable:
    """Every chunk's rows, as a frame (:meth:`EpisodeTrace.frame`), to ``append`` (steps.parquet's writer)."""

    def __init__(self, append: Callable[[Any], None]) -> None:
        self.append = append

    def on_chunk(self, trace: EpisodeTrace, k0: int, k1: int) -> None:
        if k1 > k0 or k0 == 0:  # an episode that ended on its first tick still writes its (empty) table
            self.append(trace.frame(k0, k1))


class MetricsFeed:
    """Every chunk into the summary's metrics stream (:class:`taslel_bench.metrics.summary.SummaryStream`)."""

    def __init__(self, stream) -> None:
        self.stream = stream

    def on_chunk(self, trace: EpisodeTrace, k0: int, k1: int) -> None:
        self.stream.feed(trace, k1)


def hooks_of(observers, hook: str) -> list[tuple[Callable, str]]:
    """(bound method, clock key) of every observer that has ``hook``, in list order."""
    out = []
    for obs in observers:
        method = getattr(obs, hook, None)
        if callable(method):
            out.append((method, getattr(obs, "clock", DEFAULT_CLOCK)))
    return out
