"""``python -m taslel_bench [overrides]`` — one episode; ``-m`` sweeps (joblib launcher, one job per core).

Each run writes its folder (summary.json, steps.parquet, events.json, episode.mcap); at the end of a
multirun the :class:`taslel_bench.sweep.aggregate.SweepCallback` aggregates the sweep folder and writes the report.

Exit codes (docs, "Exit codes"): 0 every run ``ok`` (and the sweep's table and report written); 1 a run
``error`` or ``degraded``, a failed report, a full disk; 2 bad input (a value refused before anything
ran, an unknown group option or key, a ``+key`` no part of the run reads (:mod:`taslel_bench.cli_checks`),
any other mistake Hydra refuses before the first job, a job list that maps two jobs to one run folder).
"""

# The GL check runs before the imports that load MuJoCo, which reads MUJOCO_GL once, at import:
# ruff: noqa: E402

from __future__ import annotations

import errno
import shutil
import sys
import time
from pathlib import Path

from taslel_bench.gl_hint import import_mujoco_or_exit

import_mujoco_or_exit()  # MUJOCO_GL naming a library that cannot be loaded: one line, not a traceback

import hydra  # after the GL check: the imports below load MuJoCo
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from taslel_bench.cli_checks import CliError, check_overrides
from taslel_bench.config.compose import CONF_DIR
from taslel_bench.config.schema import register as register_schema
from taslel_bench.sim.console import print_summary
from taslel_bench.sim.interrupt import INTERRUPTED, RunInterrupted
from taslel_bench.sim.run import earlier_unfinished, record_job_error
from taslel_bench.sweep import callback as sweep_callback
from taslel_bench.sweep.jobs import SWEEP_INTERRUPTED
from taslel_bench.sweep.launchers import (
    LauncherNotInstalled,
    check_launcher_overrides,
    register_submitit_launchers,
)
from taslel_bench.util.fields import ConfigError
from taslel_bench.util.log import console_logging

register_schema()  # the run config's structured schema, before Hydra composes conf/config.yaml
EXIT_OK, EXIT_RUNS_FAILED, EXIT_BAD_INPUT = 0, 1, 2
_single_run_exit = [EXIT_OK]
_task_started = [False]  # a Hydra error before the first job is a mistake on the command line: exit 2
HELP_FLAGS = ("--help", "-h")


def _labelled_progress(label: str):
    """In a sweep, jobs run in parallel: each prints its progress on its own labelled line, once per simulated
    second (the single run's in-place counter would put two jobs on one line)."""

    def printer(duration: float, enabled: bool):
        if not enabled:
            return None
        last = [-1]

        def show(t: float) -> None:
            if int(t) != last[0]:
                last[0] = int(t)
                print(f"  [{label}] simulated {t:6.2f} / {duration:.2f} s", file=sys.stderr, flush=True)

        return show

    return printer


_STARTED_S = time.time()  # [s, epoch] this process's start: a run folder Hydra made since is this process's
HYDRA_FILES = {".hydra"}  # what Hydra writes into a run folder before the task runs (plus <job>.log)


def _remove_refused_folder(out_dir: Path) -> None:
    """Remove the run folder Hydra made for a run that was refused before anything ran: only when it holds
    nothing but Hydra's own files, all written by this process (a folder with anything else is left)."""
    try:
        entries = list(out_dir.iterdir())
    except OSError:
        return
    ours = all((e.name in HYDRA_FILES or e.suffix == ".log") and e.stat().st_mtime >= _STARTED_S - 1.0 for e in entries)
    if ours:
        shutil.rmtree(out_dir, ignore_errors=True)


def _interrupted_line(out_dir: Path, summary: dict | None, exc: RunInterrupted | None = None) -> str:
    """The one line of a run ended by a signal."""
    if summary is not None and summary.get("status") == INTERRUPTED:
        return f"{summary.get('message')}; partial results (summary.json status interrupted) in {out_dir}"
    what = exc.args[0] if exc is not None else "interrupted"
    if exc is not None and exc.summary is not None:
        return f"{what} after the episode ended; its result in {out_dir} is complete"
    return f"{what}; {out_dir} holds no complete result (a rerun puts what is there aside and names it)"


def _one_line(exc: BaseException) -> str:
    """The error in one line; a full disk says so."""
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return f"disk full: {exc.strerror} writing {exc.filename or '(a run file)'}"
    return f"{type(exc).__name__}: {exc}"


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def main(cfg: DictConfig) -> dict:
    from taslel_bench.sim import run as sim_run
    from taslel_bench.sim.run import run

    _task_started[0] = True
    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if "/" not in k and not k.startswith("hydra")}
    multirun = hc.mode == RunMode.MULTIRUN
    if multirun:
        sim_run._progress_printer = _labelled_progress(hc.job.override_dirname or f"job #{hc.job.num}")
    else:
        for line in earlier_unfinished(out_dir, cfg):  # the same command, interrupted or killed before
            print(f"note: {line}; this run starts afresh in {out_dir}", file=sys.stderr)
    try:
        summary = run(cfg, out_dir, choices, list(hc.overrides.task))
    except RunInterrupted as exc:
        print(f"error: {_interrupted_line(out_dir, None, exc)}", file=sys.stderr)
        _single_run_exit[0] = exc.exit_code
        return exc.summary if exc.summary is not None else {"status": INTERRUPTED, "message": str(exc)}
    except Exception as exc:
        if not multirun:
            if isinstance(exc, ConfigError):  # the refusal (naming the field, the value, what is valid) is the output
                print(f"error: ConfigError: {exc}", file=sys.stderr)
                _remove_refused_folder(out_dir)  # nothing is left behind for a refused value
                _single_run_exit[0] = EXIT_BAD_INPUT
                return {"status": "error", "message": str(exc)}
            if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
                print(f"error: {_one_line(exc)}", file=sys.stderr)
                _single_run_exit[0] = EXIT_RUNS_FAILED
                return {"status": "error", "message": _one_line(exc)}
            raise
        # in a sweep one bad job must not stop the others: leave an error summary the report lists
        try:
            summary = record_job_error(out_dir, choices, cfg, exc, list(hc.overrides.task))
        except OSError as write_exc:  # e.g. the disk is full: the launcher keeps the row for the table
            summary = {"status": "error", "message": f"{_one_line(exc)}; its error summary could not be written "
                                                     f"({_one_line(write_exc)})"}
            print(f"{out_dir}: {summary['message']}", file=sys.stderr)
            return summary
    if summary.get("status") == INTERRUPTED:
        print(f"error: {_interrupted_line(out_dir, summary)}", file=sys.stderr)
        if not multirun:
            _single_run_exit[0] = 128 + int(_signal_number(str(summary.get("interrupted_by", "SIGINT"))))
        return summary
    if not multirun:
        _single_run_exit[0] = EXIT_OK if summary.get("status") == "ok" else EXIT_RUNS_FAILED
    print_summary(summary, out_dir)
    if multirun:
        from taslel_bench.sweep.aggregate import run_folders

        sweep_dir = Path(hc.sweep.dir)
        done = sum(1 for d in run_folders(sweep_dir) if (d / "summary.json").is_file())
        job = hc.job.override_dirname or f"#{hc.job.num}"
        print(f"sweep progress: job #{hc.job.num} ({job}) ended {summary.get('status')}; {done} runs complete "
              f"in {sweep_dir}", flush=True)
    return summary


def _signal_number(name: str) -> int:
    import signal

    return int(getattr(signal, name, signal.SIGINT))


def cli() -> None:
    """``python -m taslel_bench`` and the ``taslel-bench`` command."""
    console_logging()
    argv = sys.argv[1:]
    if any(a in HELP_FLAGS for a in argv) and not any(a.startswith("hydra/help=") for a in argv):
        sys.argv.append("hydra/help=taslel")  # conf/hydra/help/taslel.yaml: groups and options, one line each
    else:
        try:
            check_launcher_overrides(argv)
        except LauncherNotInstalled as exc:
            print(f"error: {exc}", file=sys.stderr)
            sys.exit(EXIT_RUNS_FAILED)
        try:
            check_overrides(argv)
        except CliError as exc:
            print(f"error: {exc}", file=sys.stderr)
            sys.exit(EXIT_BAD_INPUT)
    register_submitit_launchers()  # lost submitit/SLURM jobs become error rows
    try:
        main()
    except SystemExit as exc:
        # Hydra exits 1 on its own errors (an unknown option, a bad override, a missing key): before the first
        # job ran, that is bad input
        if exc.code == 1 and not _task_started[0]:
            sys.exit(EXIT_BAD_INPUT)
        raise
    except KeyboardInterrupt:  # Ctrl-C before a run held its folder (composing the config, building): nothing written
        print("error: interrupted (SIGINT) before the run started; nothing was written", file=sys.stderr)
        sys.exit(130)
    # a sweep's code is set by its callback (table and report written, every run ok?)
    code = sweep_callback.exit_code() if sweep_callback.sweep_ended() else _single_run_exit[0]
    if SWEEP_INTERRUPTED:  # Ctrl-C / SIGTERM of a sweep: its table is written, the exit says it was stopped
        code = 128 + SWEEP_INTERRUPTED[0]
    sys.exit(code)


if __name__ == "__main__":
    cli()
