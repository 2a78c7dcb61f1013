"""``hydra/launcher=local`` (the default): the sweep's jobs in loky worker processes, one per core, like
hydra-joblib-launcher (same settings, same per-job function), with three differences:

* the job list is checked first: two jobs that would write one run folder refuse the sweep (exit 2)
  naming both (:func:`taslel_bench.sweep.jobs.check_one_folder_per_job`);
* a worker that dies (SIGKILL, the OOM killer, a segfault) does not end the sweep. loky then fails every
  job in flight; a job that had not started yet (Hydra had not written its ``.hydra/``) is resubmitted, a
  job that had started is retried once alone, and if its worker dies again it becomes an error row
  naming the exit signal. The rest of the sweep runs on;
* a job that raises outside the task function (e.g. its folder cannot be written) is an error row, not
  the end of the sweep;
* SIGINT (Ctrl-C) or SIGTERM: the jobs not started yet are not started (their rows say so), the running
  jobs get the signal too (forwarded to the workers) and end as ``interrupted`` runs with their files
  written, the table is written and the sweep exits 128 + the signal's number;
* a worker whose sweep process is gone (killed: SIGKILL leaves loky's workers running) exits within
  :data:`ORPHAN_POLL_S` instead of running its job on, so a rerun of the sweep never races it (the job's
  folder keeps its temporary files and a stale ``run.lock``, which the rerun takes over and puts aside).
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import signal
import threading
import time
from collections.abc import Sequence
from concurrent.futures import CancelledError
from pathlib import Path
from typing import Self

from hydra.core.singleton import Singleton
from hydra.core.utils import JobReturn, filter_overrides
from hydra_plugins.hydra_joblib_launcher._core import execute_job
from hydra_plugins.hydra_joblib_launcher.joblib_launcher import JoblibLauncher
from joblib import cpu_count
from joblib.externals.loky import get_reusable_executor
from joblib.externals.loky.process_executor import BrokenProcessPool

from taslel_bench.sim.interrupt import hold_signals_between_runs
from taslel_bench.sweep.jobs import SWEEP_INTERRUPTED, begin_launch, error_return, settle

log = logging.getLogger(__name__)
MAX_RESUBMITS = 3  # rounds for jobs that had not started when a worker died
STOP_MARKER = ".sweep_interrupted"  # in the sweep folder while an interrupted sweep ends: start no job
ORPHAN_POLL_S = 0.5  # [s] how often a worker checks that the sweep process is alive
_WATCHED: list[int] = []  # the sweep process this worker watches (set once per worker)


def _exit_when_orphaned(sweep_pid: int) -> None:
    """In a worker: a daemon thread that SIGKILLs this process once ``sweep_pid`` is no longer its parent
    (the sweep process died and the worker was re-parented). Started once per worker."""
    if _WATCHED or os.getpid() == sweep_pid:
        return
    _WATCHED.append(sweep_pid)

    def watch() -> None:
        while os.getppid() == sweep_pid:
            time.sleep(ORPHAN_POLL_S)
        os.kill(os.getpid(), signal.SIGKILL)  # no cleanup: the rerun handles what the job left

    threading.Thread(target=watch, name="orphan-watch", daemon=True).start()


class JobNotStarted(Exception):
    """The sweep was interrupted before this job started (raised in the worker, turned into its row)."""


def watched_job(sweep_pid: int, stop_marker: str, *args):
    """``execute_job(*args)`` in a worker that exits when the sweep process dies, does not start a job once
    the sweep was interrupted (``stop_marker`` exists) and keeps a signal that comes between its runs for its
    next run (:func:`taslel_bench.sim.interrupt.hold_signals_between_runs`)."""
    _exit_when_orphaned(sweep_pid)
    hold_signals_between_runs()
    if Path(stop_marker).exists():
        raise JobNotStarted(stop_marker)
    return execute_job(*args)


def death_reason(exc: BaseException) -> str:
    """How loky says the worker died: its exit codes (``SIGKILL(-9)``: killed, e.g. by the OOM killer)."""
    codes = re.search(r"exit codes of the workers are \{([^}]*)\}", str(exc))
    return f"worker exit codes {codes.group(1)}" if codes else f"{type(exc).__name__}"


def _not_run(overrides: Sequence[str], folder: Path) -> JobReturn:
    """The row of a job the interrupted sweep never started (no folder is made for it)."""
    name = signal.Signals(SWEEP_INTERRUPTED[0]).name if SWEEP_INTERRUPTED else "a signal"
    return error_return(overrides, folder, f"not run: the sweep was interrupted by {name} before this job started",
                        status="interrupted")  # fmt: skip


class _SweepSignals:
    """While the sweep runs: SIGINT/SIGTERM cancel the jobs not started yet and are forwarded to the workers
    (a Ctrl-C reaches them already; a duplicate within a second is ignored by their run's guard)."""

    def __init__(self, launcher: RobustJoblibLauncher) -> None:
        self.launcher, self._previous = launcher, {}

    def _handle(self, signum: int, frame: object) -> None:
        if SWEEP_INTERRUPTED:
            return
        SWEEP_INTERRUPTED.append(signum)
        self.launcher._stop_marker.touch()  # workers start no further job (queued jobs cannot be cancelled)
        log.warning(f"{signal.Signals(signum).name}: the jobs not started are not run; the running ones end now")
        for future in getattr(self.launcher, "_futures", {}).values():
            future.cancel()  # only those not started yet
        for pid in list(getattr(getattr(self.launcher, "_executor", None), "_processes", {}) or {}):
            with contextlib.suppress(OSError):
                os.kill(pid, signum)

    def __enter__(self) -> Self:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._handle) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)


class RobustJoblibLauncher(JoblibLauncher):
    """Joblib-launcher settings (``n_jobs``; -1 = every core); see the module doc for what it adds."""

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        assert self.config is not None and self.task_function is not None and self.hydra_context is not None
        folders, sweep_dir = begin_launch(self.config, job_overrides, self.hydra_context, initial_job_idx)
        n_jobs = int(self.joblib.get("n_jobs", -1) or -1)
        n_jobs = cpu_count() if n_jobs < 0 else n_jobs
        log.info(f"launching {len(job_overrides)} jobs, {n_jobs} at a time, sweep output dir: {sweep_dir}")
        for idx, overrides in enumerate(job_overrides):
            log.info(f"\t#{initial_job_idx + idx} : {' '.join(filter_overrides(overrides))}")
        self._started_at = time.time()
        results: dict[int, JobReturn] = {}
        self._stop_marker = sweep_dir / STOP_MARKER
        self._stop_marker.unlink(missing_ok=True)  # one left by a sweep killed before it could remove it
        try:
            with _SweepSignals(self):
                self._rounds(job_overrides, folders, initial_job_idx, n_jobs, results)
        finally:
            self._stop_marker.unlink(missing_ok=True)
        for i in range(len(job_overrides)):  # never started: the sweep was interrupted first
            if i not in results:
                results[i] = _not_run(job_overrides[i], folders[i])
        return [results[i] for i in range(len(job_overrides))]

    def _rounds(self, job_overrides: Sequence[Sequence[str]], folders: list[Path], first: int, n_jobs: int,
                results: dict[int, JobReturn]) -> None:  # fmt: skip
        """Every job, resubmitting those of a dead worker (none once the sweep is interrupted)."""
        pending, suspects = list(range(len(job_overrides))), []
        for _ in range(MAX_RESUBMITS):
            if not pending or SWEEP_INTERRUPTED:
                break
            died = self._round(pending, job_overrides, folders, first, n_jobs, results)
            suspects += [i for i in died if self._started(folders[i])]
            pending = [i for i in died if i not in suspects]
        suspects += pending
        for i in suspects:  # retry once, alone: a second death is this job's
            if SWEEP_INTERRUPTED:
                return
            died = self._round([i], job_overrides, folders, first, 1, results)
            if died:
                results[i] = error_return(job_overrides[i], folders[i], f"the worker running this job died twice "
                                          f"({died[i]}); the other jobs ran on")  # fmt: skip

    def _started(self, folder: Path) -> bool:
        """Hydra wrote the job's ``.hydra/`` during this launch (the job had begun when its worker died)."""
        marker = folder / ".hydra" / "overrides.yaml"
        return marker.is_file() and marker.stat().st_mtime >= self._started_at - 1.0

    def _round(self, indices: list[int], job_overrides: Sequence[Sequence[str]], folders: list[Path],
               first: int, n_jobs: int, results: dict[int, JobReturn]) -> dict[int, str]:  # fmt: skip
        """Run ``indices`` on a pool of ``n_jobs`` workers; fill ``results``; returns {index: why} of the jobs
        whose worker died (or that the broken pool never ran)."""
        assert self.config is not None and self.task_function is not None and self.hydra_context is not None
        executor = get_reusable_executor(max_workers=min(n_jobs, len(indices)))
        self._executor = executor
        state = Singleton.get_state()
        marker = str(self._stop_marker)
        futures = {i: executor.submit(watched_job, os.getpid(), marker, first + i, job_overrides[i], self.hydra_context,
                                      self.config, self.task_function, state) for i in indices}  # fmt: skip
        self._futures = futures
        died: dict[int, str] = {}
        for i, future in futures.items():
            try:
                results[i] = settle(future.result(), job_overrides[i], folders[i])
            except (CancelledError, JobNotStarted):  # the sweep was interrupted before this job started
                results[i] = _not_run(job_overrides[i], folders[i])
            except BrokenProcessPool as exc:  # TerminatedWorkerError is one
                died[i] = death_reason(exc)
            except Exception as exc:  # e.g. unpicklable result: one job's error, not the sweep's
                results[i] = settle(exc, job_overrides[i], folders[i])
        if died:
            log.warning(f"a worker died; {len(died)} job(s) in flight are resubmitted: "
                        f"{sorted(first + i for i in died)}")
        return died
