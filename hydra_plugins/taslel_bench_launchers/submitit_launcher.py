"""``hydra/launcher=submitit_local`` and ``submitit_slurm`` (``slurm``): hydra-submitit-launcher's launchers
with what this project's other launchers do, so a sweep on SLURM always ends with its table:

* the job list is checked first (two jobs, one run folder: refused, exit 2);
* a job that is lost (its process killed, a node failure, a SLURM timeout or preemption: submitit raises for
  it when the sweep collects the results) is an error row naming what submitit said, instead of an
  exception that ends the sweep before its callback writes the table;
* every job's outcome is kept for the table (:func:`taslel_bench.sweep.jobs.settle`).

The two launchers are registered under hydra-submitit-launcher's own names (``submitit_local``,
``submitit_slurm``), replacing its registrations, with the same settings, by :func:`register` (the CLI calls
it after Hydra's plugin scan). Nothing here is loaded unless the
``slurm`` extra (hydra-submitit-launcher) is installed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import replace
from typing import Any

from hydra.core.config_store import ConfigStore
from hydra.core.utils import JobReturn

from taslel_bench.sweep.jobs import begin_launch, settle

try:  # the slurm extra; without it this module defines nothing (plugin discovery imports it anyway)
    from hydra_plugins.hydra_submitit_launcher import config as submitit_config  # registers its options first
    from hydra_plugins.hydra_submitit_launcher.submitit_launcher import LocalLauncher, SlurmLauncher
except ImportError:
    submitit_config = None

_HERE = "hydra_plugins.taslel_bench_launchers.submitit_launcher"


class LostJob(RuntimeError):
    """submitit could not give a job's result (the job's process died, the scheduler ended it)."""


@contextlib.contextmanager
def _results_never_raise() -> Iterator[None]:
    """While launching: ``Job.results()`` returns ``[the exception]`` for a lost job instead of raising it."""
    from submitit.core.core import Job

    original = Job.results

    def results(job: Any) -> list[Any]:
        try:
            return original(job)
        except Exception as exc:  # the job's error becomes its row, not the sweep's end
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            return [LostJob(f"submitit job {getattr(job, 'job_id', '?')}: {type(exc).__name__}: {first}")]

    Job.results = results  # type: ignore[method-assign]
    try:
        yield
    finally:
        Job.results = original  # type: ignore[method-assign]


if submitit_config is not None:

    class _RobustSubmitit:
        """The launch of both launchers (a mixin before submitit's launcher class)."""

        def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
            folders, _ = begin_launch(self.config, job_overrides, self.hydra_context, initial_job_idx)  # type: ignore[attr-defined]
            with _results_never_raise():
                returns = super().launch(job_overrides, initial_job_idx)  # type: ignore[misc]
            return [
                settle(ret, overrides, folder)
                for ret, overrides, folder in zip(returns, job_overrides, folders, strict=True)
            ]

    class RobustLocalLauncher(_RobustSubmitit, LocalLauncher):
        """``hydra/launcher=submitit_local``: jobs as local processes through submitit."""


    class RobustSlurmLauncher(_RobustSubmitit, SlurmLauncher):
        """``hydra/launcher=submitit_slurm`` (and ``slurm``): jobs as SLURM tasks through submitit."""



def register() -> None:
    """hydra-submitit-launcher's two options, same settings, with these launchers (called after Hydra's plugin
    scan by :func:`taslel_bench.sweep.launchers.register_submitit_launchers`)."""
    if submitit_config is None:
        return
    local = replace(submitit_config.LocalQueueConf(), _target_=f"{_HERE}.RobustLocalLauncher")
    slurm = replace(submitit_config.SlurmQueueConf(), _target_=f"{_HERE}.RobustSlurmLauncher")
    ConfigStore.instance().store(group="hydra/launcher", name="submitit_local", node=local, provider="taslel_bench")
    ConfigStore.instance().store(group="hydra/launcher", name="submitit_slurm", node=slurm, provider="taslel_bench")
