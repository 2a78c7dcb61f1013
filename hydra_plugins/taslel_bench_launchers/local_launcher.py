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
* a worker whose sweep process is gone (killed: SIGKILL leaves loky's workers running) exits within
  :data:`ORPHAN_POLL_S` instead of running its job on, so a rerun of the sweep never races it (the job's
  folder keeps its temporary files and a stale ``run.lock``, which the rerun takes over and puts aside).
"""

from __future__ import annotations

import logging
import os
import re
import signal
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from hydra.core.singleton import Singleton
from hydra.core.utils import JobReturn, filter_overrides
from hydra_plugins.hydra_joblib_launcher._core import execute_job
from hydra_plugins.hydra_joblib_launcher.joblib_launcher import JoblibLauncher
from joblib import cpu_count
from joblib.externals.loky import get_reusable_executor
from joblib.externals.loky.process_executor import BrokenProcessPool

from taslel_bench.sweep.jobs import begin_launch, error_return, settle

log = logging.getLogger(__name__)
MAX_RESUBMITS = 3  # rounds for jobs that had not started when a worker died
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


def watched_job(sweep_pid: int, *args):
    """``execute_job(*args)`` in a worker that exits when the sweep process dies."""
    _exit_when_orphaned(sweep_pid)
    return execute_job(*args)


def death_reason(exc: BaseException) -> str:
    """How loky says the worker died: its exit codes (``SIGKILL(-9)``: killed, e.g. by the OOM killer)."""
    codes = re.search(r"exit codes of the workers are \{([^}]*)\}", str(exc))
    return f"worker exit codes {codes.group(1)}" if codes else f"{type(exc).__name__}"


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
        pending, suspects = list(range(len(job_overrides))), []
        for _ in range(MAX_RESUBMITS):
            if not pending:
                break
            died = self._round(pending, job_overrides, folders, initial_job_idx, n_jobs, results)
            suspects += [i for i in died if self._started(folders[i])]
            pending = [i for i in died if i not in suspects]
        suspects += pending
        for i in suspects:  # retry once, alone: a second death is this job's
            died = self._round([i], job_overrides, folders, initial_job_idx, 1, results)
            if died:
                results[i] = error_return(job_overrides[i], folders[i], f"the worker running this job died twice "
                                          f"({died[i]}); the other jobs ran on")  # fmt: skip
        return [results[i] for i in range(len(job_overrides))]

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
        state = Singleton.get_state()
        futures = {i: executor.submit(watched_job, os.getpid(), first + i, job_overrides[i], self.hydra_context,
                                      self.config, self.task_function, state) for i in indices}  # fmt: skip
        died: dict[int, str] = {}
        for i, future in futures.items():
            try:
                results[i] = settle(future.result(), job_overrides[i], folders[i])
            except BrokenProcessPool as exc:  # TerminatedWorkerError is one
                died[i] = death_reason(exc)
            except Exception as exc:  # noqa: BLE001 - e.g. unpicklable result: one job's error, not the sweep's
                results[i] = settle(exc, job_overrides[i], folders[i])
        if died:
            log.warning(f"a worker died; {len(died)} job(s) in flight are resubmitted: {sorted(first + i for i in died)}")
        return died
