"""``hydra/launcher=ray``: run a sweep's jobs on Ray through joblib's ``"ray"`` backend.

The joblib launcher plugin fixes its backend to loky; this launcher runs the same per-job function
(``hydra_joblib_launcher._core.execute_job``) with ``joblib.Parallel(backend="ray")`` instead, after
``ray.init`` on a new local instance (``address: local``) or a running cluster (``address: auto`` or
``<head>:6379``). Each job writes its own run folder; the sweep callback aggregates the folder. As with the
local launcher, a job list mapping two jobs to one run folder is refused before anything runs (exit 2), and a
job that raised is an error row; a Ray worker that dies still ends the batch (Ray's joblib backend raises;
not handled here, unlike the local launcher).
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

from taslel_bench.sweep.jobs import begin_launch, settle
from taslel_bench.sweep.launchers import require_launcher_package

log = logging.getLogger(__name__)


class RayLauncher(Launcher):
    """Jobs as tasks of a Ray actor pool (one actor per concurrent job).

    ``address``: ``local`` starts a new instance even when ``RAY_ADDRESS`` is set or a cluster (or a stale
    record of one) is on this node; ``auto`` / ``<host>:<port>`` joins a running cluster (Ray's meanings);
    ``n_jobs``: concurrent jobs, -1 = every CPU of the Ray cluster (never more than the sweep's jobs);
    ``num_cpus``: CPUs of a new local instance (null = all cores; Ray refuses it when joining a cluster);
    ``ray_remote_args``: options of each pool actor (e.g. ``{num_cpus: 1}`` to spread them over nodes).
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
        from joblib import Parallel, delayed
        from ray.util.joblib import register_ray

        assert self.config is not None and self.task_function is not None and self.hydra_context is not None
        folders, sweep_dir = begin_launch(self.config, job_overrides, self.hydra_context, initial_job_idx)

        started_here = not ray.is_initialized()
        if started_here:
            ray.init(address=self.address, num_cpus=self.num_cpus, include_dashboard=False)
        register_ray()
        # joblib hands the pool a multiprocessing context that Ray ignores; its warning about it is noise
        logging.getLogger("ray.util.multiprocessing.pool").setLevel(logging.ERROR)
        cluster_cpus = int(ray.cluster_resources().get("CPU", 1))
        n_jobs = min(len(job_overrides), cluster_cpus if self.n_jobs == -1 else self.n_jobs)
        log.info(f"Ray ({cluster_cpus} CPUs) is launching {len(job_overrides)} jobs, {n_jobs} at a time")
        log.info(f"Launching jobs, sweep output dir : {sweep_dir}")
        for idx, overrides in enumerate(job_overrides):
            log.info(f"\t#{initial_job_idx + idx} : {' '.join(filter_overrides(overrides))}")

        state = Singleton.get_state()
        remote_args = OmegaConf.to_container(OmegaConf.create(self.ray_remote_args), resolve=True)
        try:
            runs = Parallel(n_jobs=n_jobs, backend="ray", ray_remote_args=remote_args)(
                delayed(execute_job)(
                    initial_job_idx + idx,
                    overrides,
                    self.hydra_context,
                    self.config,
                    self.task_function,
                    state,
                )
                for idx, overrides in enumerate(job_overrides)
            )
        finally:
            if started_here:
                ray.shutdown()
        # a job that raised outside the task function is an error row, not the end of the sweep
        return [settle(r, overrides, folder) for r, overrides, folder in zip(runs, job_overrides, folders)]
