"""What the sweep's launchers share (``hydra_plugins/taslel_bench_launchers/``): the check that every job
has its own run folder, and the sweep's record of jobs that ended without writing their folder (a dead
worker, a full disk, a folder that cannot be written), read by the callback so the table still has a row
for each.

A launcher returns a completed :class:`hydra.core.utils.JobReturn` for every job, whatever happened to it:
Hydra's sweeper re-raises the exception of a failed one and the sweep would end without its table.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hydra.core.utils import JobReturn, JobStatus, configure_log, filter_overrides, setup_globals
from hydra.types import HydraContext
from omegaconf import DictConfig

from taslel_bench.record.run_files import OVERRIDE_SEPARATOR, read_summary, write_error_folder

EXIT_BAD_INPUT = 2

# run folder (absolute, as text) -> the row of a job that could not leave a readable summary.json
JOB_OUTCOMES: dict[str, dict[str, Any]] = {}
# run folder -> the job's axes (scenario, solver, estimator, seed) from its composed config, for its error row
JOB_AXES: dict[str, dict[str, Any]] = {}


# the signal that interrupted the sweep (SIGINT / SIGTERM), if one did: the sweep then exits 128 + its number
SWEEP_INTERRUPTED: list[int] = []
PROGRESS_EVERY_S = 5.0  # [s] a line on stderr this often while the jobs' configs are composed (~0.17 s each)


class SweepRefused(SystemExit):
    """The job list cannot run as given (exit code 2, one line on stderr, nothing run)."""


def job_folders(config: DictConfig, job_overrides: Sequence[Sequence[str]],
                hydra_context: HydraContext) -> list[Path]:  # fmt: skip
    """The run folder of each job (``hydra.sweep.dir/hydra.sweep.subdir`` of its composed config). Composing
    takes ~0.17 s a job (minutes for a study of a thousand): a progress line every PROGRESS_EVERY_S."""
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import OmegaConf

    folders = []
    before = HydraConfig.instance().cfg
    start = last = time.monotonic()
    for k, overrides in enumerate(job_overrides):
        if time.monotonic() - last >= PROGRESS_EVERY_S:
            last = time.monotonic()
            print(f"composing the jobs' configs before any runs: {k}/{len(job_overrides)} "
                  f"({last - start:.0f} s)", file=sys.stderr, flush=True)
        job_cfg = hydra_context.config_loader.load_sweep_config(config, list(overrides))
        HydraConfig.instance().set_config(job_cfg)  # ${hydra:...} in the folder pattern
        sweep_dir = str(OmegaConf.select(job_cfg, "hydra.sweep.dir"))
        subdir = str(OmegaConf.select(job_cfg, "hydra.sweep.subdir"))
        folders.append(Path(sweep_dir, subdir).absolute())
        JOB_AXES[str(folders[-1])] = _axes(job_cfg)
    if before is not None:
        HydraConfig.instance().set_config(before)  # pyright: ignore[reportArgumentType] hydra annotates cfg as HydraConf; it holds the DictConfig set_config was given
    return folders


def _axes(job_cfg: DictConfig) -> dict[str, Any]:
    """The axes of a job's composed config (the option chosen in each axis group, the seed)."""
    from omegaconf import OmegaConf

    choices = OmegaConf.select(job_cfg, "hydra.runtime.choices") or {}
    axes: dict[str, Any] = {k: str(choices[k]) for k in ("scenario", "solver", "estimator") if choices.get(k)}
    seed = OmegaConf.select(job_cfg, "seed", default=None, throw_on_resolution_failure=False)
    if isinstance(seed, int) and not isinstance(seed, bool):
        axes["seed"] = seed
    return axes


def check_one_folder_per_job(config: DictConfig, job_overrides: Sequence[Sequence[str]],
                             hydra_context: HydraContext, first_idx: int = 0) -> list[Path]:  # fmt: skip
    """The jobs' run folders; :class:`SweepRefused` (exit 2) naming both jobs' overrides when two jobs would
    write one folder (e.g. ``seed=0,0``, or ``record.mcap=true,false``: ``record.*`` keys are not part of the
    folder name), before any job runs."""
    folders = job_folders(config, job_overrides, hydra_context)
    seen: dict[Path, int] = {}
    for i, folder in enumerate(folders):
        if folder in seen:
            j = seen[folder]
            a, b = (" ".join(filter_overrides(job_overrides[k])) or "(no overrides)" for k in (j, i))
            message = (f"error: jobs #{first_idx + j} ({a}) and #{first_idx + i} ({b}) would write the same run "
                       f"folder {folder}: two writers in one folder corrupt each other's results. Sweep a value "
                       f"only once, or make the differing key part of the folder name (it is in "
                       f"hydra.job.config.override_dirname.exclude_keys), or run them into separate sweeps")
            print(message, file=sys.stderr)
            raise SweepRefused(EXIT_BAD_INPUT)
        seen[folder] = i
    return folders


def begin_launch(config: DictConfig, job_overrides: Sequence[Sequence[str]], hydra_context: HydraContext,
                 first_idx: int = 0) -> tuple[list[Path], Path]:
    """What every launcher of this package does before it runs a job: Hydra's globals and logging, the
    one-folder-per-job check (:func:`check_one_folder_per_job`), the sweep folder made. Returns (the jobs' run
    folders, the sweep folder)."""
    setup_globals()
    configure_log(config.hydra.hydra_logging, config.hydra.verbose)
    folders = check_one_folder_per_job(config, job_overrides, hydra_context, first_idx)
    sweep_dir = Path(str(config.hydra.sweep.dir))
    sweep_dir.mkdir(parents=True, exist_ok=True)
    return folders, sweep_dir


def error_return(overrides: Sequence[str], folder: Path, message: str, tb: str = "",
                 status: str = "error") -> JobReturn:  # fmt: skip
    """A completed JobReturn holding an error summary (``status``: "error", or "interrupted" for a job the
    interrupted sweep never started) for a job that could not run or finish; the error is written into its
    folder when possible (else kept for the callback in :data:`JOB_OUTCOMES`)."""
    summary: dict[str, Any] = {"status": status, "message": message, "fell": False, "seed": -1,
                               "overrides": OVERRIDE_SEPARATOR.join(sorted(overrides))}  # fmt: skip
    summary.update(JOB_AXES.get(str(folder), {}))
    for item in overrides:
        key, _, value = item.partition("=")
        if key in ("scenario", "solver", "estimator"):
            summary[key] = value
        elif key == "seed" and value.isdigit():
            summary["seed"] = int(value)
    try:
        if status == "error":  # a job never started leaves no folder; its row lives in the table
            write_error_folder(folder, dict(summary), tb or message)
    except OSError as exc:  # a full disk, a read-only folder: the row lives on in the sweep's table
        summary["message"] = f"{message}; its error summary could not be written either ({exc})"
    JOB_OUTCOMES[str(folder)] = summary
    ret = JobReturn(overrides=list(overrides), working_dir=str(folder), task_name="taslel_bench")
    ret.status = JobStatus.COMPLETED
    ret.return_value = summary
    return ret


OUTCOME_KEYS = ("status", "message", "config_sha256", "scenario", "solver", "estimator", "seed")


def settle(ret: Any, overrides: Sequence[str], folder: Path) -> JobReturn:
    """``ret`` if the job completed, else an :func:`error_return` naming what it raised. Every job's outcome
    is kept in :data:`JOB_OUTCOMES` (the whole summary when its folder holds none, e.g. the disk was full),
    so the table never shows an old summary in the folder in place of what this job did."""
    if isinstance(ret, JobReturn) and ret.status == JobStatus.COMPLETED:
        value = ret._return_value
        if isinstance(value, dict) and "status" in value:
            joined = OVERRIDE_SEPARATOR.join(sorted(overrides))
            full = read_summary(folder) is None or value.get("status") not in ("ok", "degraded")
            kept = {k: v for k, v in value.items() if k != "identity"} if full else \
                {k: value[k] for k in OUTCOME_KEYS if k in value}
            axes = {k: v for k, v in JOB_AXES.get(str(folder), {}).items() if kept.get(k) in (None, "", -1)}
            JOB_OUTCOMES[str(folder)] = {**kept, **axes, "overrides": joined}
        return ret
    exc = ret._return_value if isinstance(ret, JobReturn) else ret
    tb = "".join(traceback.format_exception(exc)) if isinstance(exc, BaseException) else ""
    return error_return(overrides, folder, f"{type(exc).__name__}: {exc}", tb)


__all__ = ["EXIT_BAD_INPUT", "JOB_AXES", "JOB_OUTCOMES", "SWEEP_INTERRUPTED", "SweepRefused",
           "check_one_folder_per_job", "error_return", "job_folders", "settle"]
