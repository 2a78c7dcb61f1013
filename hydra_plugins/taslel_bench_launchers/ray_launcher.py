"""``hydra/launcher=ray``: run a sweep's jobs as Ray tasks.

Each job is one Ray task running the joblib launcher's per-job function
(``hydra_joblib_launcher._core.execute_job``), at most ``n_jobs`` in flight, after ``ray.init`` on a new
local instance (``address: local``) or a running cluster (``address: auto`` or ``<head>:6379``). Each job
writes its own run folder; the sweep callback aggregates the folder. As with the local launcher, a job list
mapping two jobs to one run folder is refused before anything runs (exit 2), a job that raised is an error
row, and a worker that dies (SIGKILL, the OOM killer) does not end the sweep: Ray runs its task once more
(``max_retries=1``) and, if that worker dies too, the job is an error row naming it; the other jobs run on.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

from hydra.core.singleton import Singleton
from hydra.core.utils import JobReturn, filter_overrides
from hydra.plugins.launcher import Launcher
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig, OmegaConf

from taslel_bench.sweep.jobs import begin_launch, error_return, settle
from taslel_bench.sweep.launchers import require_launcher_package

log = logging.getLogger(__name__)


class RayLauncher(Launcher):
    """Jobs as Ray tasks (at most ``n_jobs`` at once).

    ``address``: ``local`` starts a new instance even when ``RAY_ADDRESS`` is set or a cluster (or a stale
    record of one) is on this node; ``auto`` / ``<host>:<port>`` joins a running cluster (Ray's meanings);
    ``n_jobs``: concurrent jobs, -1 = every CPU of the Ray cluster (never more than the sweep's jobs);
    ``num_cpus``: CPUs of a new local instance (null = all cores; Ray refuses it when joining a cluster);
    ``ray_remote_args``: options of each job's task (e.g. ``{num_cpus: 2}``).
    """

    def __init__(
        self,
        address: str = "local",
        num_cpus: int | None = None,
        n_jobs: int = -1,
        ray_remote_args: dict[str, Any] | None = None,
    ) -> None:
        self.address = address or "local"
        self.num_cpus = num_cpus
        self.n_jobs = int(n_jobs)
        if self.n_jobs == 0 or self.n_jobs < -1:
            raise ValueError(f"hydra.launcher.n_jobs={n_jobs}: use a positive count or -1 (every Ray CPU)")
        self.ray_remote_args = dict(ray_remote_args or {})
        self.config: DictConfig | None = None
        self.task_function: TaskFunction | None = None
        self.hydra_context: HydraContext | None = None

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.config = config
        self.task_function = task_function
        self.hydra_context = hydra_context

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        require_launcher_package("ray")
        import ray
        from hydra_plugins.hydra_joblib_launcher._core import execute_job

        assert self.config is not None and self.task_function is not None and self.hydra_context is not None
        folders, sweep_dir = begin_launch(self.config, job_overrides, self.hydra_context, initial_job_idx)

        started_here = not ray.is_initialized()
        if started_here:
            ray.init(address=self.address, num_cpus=self.num_cpus, include_dashboard=False)
        cluster_cpus = int(ray.cluster_resources().get("CPU", 1))
        n_jobs = min(len(job_overrides), cluster_cpus if self.n_jobs == -1 else self.n_jobs)
        log.info(f"Ray ({cluster_cpus} CPUs) is launching {len(job_overrides)} jobs, {n_jobs} at a time")
        log.info(f"Launching jobs, sweep output dir : {sweep_dir}")
        for idx, overrides in enumerate(job_overrides):
            log.info(f"\t#{initial_job_idx + idx} : {' '.join(filter_overrides(overrides))}")

        state = Singleton.get_state()
        remote_args = OmegaConf.to_container(OmegaConf.create(self.ray_remote_args), resolve=True)
        task = ray.remote(max_retries=1, **remote_args)(execute_job)  # a dead worker: its task once more
        results: dict[int, JobReturn] = {}
        try:
            queue, in_flight = list(range(len(job_overrides))), {}
            while queue or in_flight:
                while queue and len(in_flight) < n_jobs:
                    i = queue.pop(0)
                    ref = task.remote(initial_job_idx + i, job_overrides[i], self.hydra_context, self.config,
                                      self.task_function, state)  # fmt: skip
                    in_flight[ref] = i
                done, _ = ray.wait(list(in_flight), num_returns=1)
                for ref in done:
                    i = in_flight.pop(ref)
                    results[i] = _outcome(ray, ref, job_overrides[i], folders[i])
        finally:
            if started_here:
                ray.shutdown()
        return [results[i] for i in range(len(job_overrides))]


def _outcome(ray, ref, overrides: Sequence[str], folder) -> JobReturn:
    """The job's return, or an error row: its worker died twice, or it raised outside the task function."""
    try:
        return settle(ray.get(ref), overrides, folder)
    except ray.exceptions.WorkerCrashedError as exc:
        log.warning(f"the Ray worker running {' '.join(overrides)} died twice; the other jobs run on")
        return error_return(overrides, folder, f"the worker running this job died twice (Ray: "
                            f"{type(exc).__name__}); the other jobs ran on")  # fmt: skip
    except ray.exceptions.RayTaskError as exc:
        return settle(exc.cause if isinstance(exc.cause, BaseException) else exc, overrides, folder)
    except Exception as exc:  # one job's error, not the sweep's
        return settle(exc, overrides, folder)
