"""Build one run from a composed config, run the episode, write the run folder.

Works with or without Hydra's runtime (tests compose configs directly): ``choices`` names the option of
each config group (``{"scenario": "flat", "solver": "daqp", ...}``).
"""

from __future__ import annotations

import hashlib
import logging
import math
import resource
import sys
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from taslel_bench.config.compose import CONF_DIR
from taslel_bench.config.settings import health_limits, robot_description, safety_limits
from taslel_bench.config.validate import memory_estimate_gb, validate
from taslel_bench.metrics.sections import RunSummary
from taslel_bench.metrics.summary import SummaryStream, summary_sections
from taslel_bench.plant.build import urdf_mesh_files
from taslel_bench.plant.comparison import plant_vs_model
from taslel_bench.qp.reference_check import reference_metrics
from taslel_bench.record import run_files
from taslel_bench.record.result import EpisodeResult
from taslel_bench.record.run_files import OVERRIDE_SEPARATOR
from taslel_bench.record.run_lock import RunFolderLocked, RunLock
from taslel_bench.sim.build import Built
from taslel_bench.sim.identity import RunIdentity, config_files, mjcf_files, run_identity, target_modules
from taslel_bench.sim.interrupt import INTERRUPTED, InterruptGuard, RunInterrupted, StopRequested
from taslel_bench.sim.run_recorders import SWEEP_LEVEL_KEYS, RunRecorders, chunk_ticks, run_config_yaml, run_recorders
from taslel_bench.sim.solve_clock import time_solves_by_cpu
from taslel_bench.util.fields import plain_dict
from taslel_bench.util.machine import CpuWatch
from taslel_bench.util.provenance import code_version

logger = logging.getLogger(__name__)


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def plant_identity(cfg: DictConfig, built: Built) -> dict[str, object]:
    """What was simulated and what the controller believed: the plant source (the URDF of
    example-robot-data or ``robot.plant_mjcf``) and the controller model's URDF, with their content hashes
    (masses, inertias, joint losses: :func:`taslel_bench.plant.comparison.plant_vs_model`)."""
    mjcf = cfg.robot.plant_mjcf
    plant_src = Path(mjcf) if mjcf else built.robot.urdf_path
    model_src = Path(built.episode.model.urdf_path)
    return {
        "plant_source": str(plant_src),
        "plant_sha256": file_sha256(plant_src),
        "model_source": str(model_src),
        "model_sha256": file_sha256(model_src),
    }


def peak_memory_gb() -> float:
    """[GB] peak resident memory of this process so far (Linux ru_maxrss is in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def _progress_printer(duration: float, enabled: bool):
    if not enabled:
        return None

    def show(t: float) -> None:
        print(f"\r  simulated {t:6.2f} / {duration:.2f} s", end="", file=sys.stderr, flush=True)

    return show


def summary_choices(cfg: DictConfig, choices: dict[str, str] | None) -> dict[str, str]:
    """The option of each config group as the summary and the QP test set name it (``solver=qpsolvers``:
    ``qpsolvers:<the solver it runs>``)."""
    out = dict(choices or {})
    if out.get("solver") == "qpsolvers":  # the per-call route: name the solver it runs
        out["solver"] = f"qpsolvers:{cfg.solver.name}"
    return out


def hashed_config(cfg: DictConfig) -> dict:
    """The resolved config as hashed: without ``progress``, ``force``, ``max_memory_gb`` (they only change what
    is printed or refused), the sweep-level keys and ``record.chunk_ticks`` (how the trace is processed)."""
    plain = plain_dict(cfg, "config")
    for key in ("progress", "force", "max_memory_gb", *SWEEP_LEVEL_KEYS):
        plain.pop(key, None)
    plain.get("record", {}).pop("chunk_ticks", None)
    return plain


def identity_of(cfg: DictConfig, input_files: Iterable[Path] = (),
                choices: dict[str, str] | None = None) -> RunIdentity:  # fmt: skip
    """Everything that decides a run's results (:mod:`taslel_bench.sim.identity`): the resolved config, the
    plant files as MuJoCo reads them, the controller model's URDF and ``model.from`` file, ``input_files`` (the
    estimator's checkpoints), the project code the run imports and its ``_target_`` modules, the composed config files
    (``choices``: the option of each config group) and the result-deciding package versions."""
    plain = hashed_config(cfg)
    mjcf = cfg.robot.plant_mjcf
    robot_urdf = robot_description(cfg).urdf_path
    return run_identity(
        OmegaConf.to_yaml(OmegaConf.create(plain)),
        plant=mjcf_files(Path(mjcf)) if mjcf else [robot_urdf, *urdf_mesh_files(robot_urdf)],
        model=[Path(cfg.model.urdf or robot_urdf), *([Path(cfg.model["from"])] if cfg.model["from"] else [])],
        checkpoints=sorted(Path(p).resolve() for p in input_files),
        targets=target_modules(plain),
        config=config_files(CONF_DIR, choices or {}),
    )


def config_sha256(cfg: DictConfig, input_files: Iterable[Path] = (), choices: dict[str, str] | None = None) -> str:
    """The hash of :func:`identity_of`."""
    return identity_of(cfg, input_files, choices).config_sha256


def estimator_files(built: Built) -> list[Path]:
    """The files the run's estimator and controller loaded (an estimator's optional ``input_files()``: checkpoints;
    a learned policy's ONNX file), [] if none."""
    files: Callable[[], Iterable[str | Path]] | None = getattr(built.estimator, "input_files", None)
    policy = getattr(getattr(built.controller, "policy", None), "path", None)  # controller=policy's ONNX file
    loaded = [Path(p) for p in files()] if callable(files) else []
    return loaded + ([Path(policy)] if policy is not None else [])


SUPERSEDE_WHY = {
    "no-summary": "a run that did not finish (no summary.json)",
    "summary-unreadable": "summary.json unreadable (truncated or not JSON)",
    "forced": "force=true",
}


def _supersede_tag(problem: str, same: bool, previous: dict | None, out_dir: Path) -> tuple[str, str]:
    """(folder tag, reason in words) for putting the folder's result files aside before a rerun."""
    from taslel_bench.record.mcap import PARTIAL_NAME

    if problem == "no-summary" and (out_dir / PARTIAL_NAME).exists():
        return "killed", "a killed run (partial episode.mcap, no summary.json)"
    if problem == INTERRUPTED:
        return INTERRUPTED, f"an interrupted run ({previous.get('message') if previous else 'partial episode'})"
    if problem:
        kind, _, name = problem.partition("-")
        why = {"missing": f"{name} of the result is missing", "size": f"{name} differs from the size the run "
               f"wrote (truncated or replaced)", "extra": f"{name} is not part of the result"}.get(kind)  # fmt: skip
        return f"incomplete-{problem}", why or SUPERSEDE_WHY[problem]
    if same:
        return "forced", SUPERSEDE_WHY["forced"]
    sha = str(previous.get("config_sha256", "unknown")) if previous else "unknown"
    return f"config-{sha[:8]}", f"a run of another config or inputs (config_sha256 {sha[:12]})"


def prepare_folder(cfg: DictConfig, out_dir: Path, config_hash: str) -> tuple[dict | None, dict[str, object]]:
    """(summary of a complete run to skip, or None; notes for the new run's summary). A complete run of the
    same identity is skipped unless ``force``; any other set of result files in the folder (a complete run
    of another config, a forced rerun, a killed run, a truncated summary, a missing steps.parquet, a stray
    traceback.txt) is moved to ``superseded/`` first, never overwritten, and the notes say what was moved
    and why; files of interrupted writes are removed and named."""
    previous, problem = run_files.folder_state(out_dir)
    if not problem and previous is not None and previous.get("status") == INTERRUPTED:
        problem = INTERRUPTED  # a partial episode: never reused as complete
    same = previous is not None and previous.get("config_sha256") == config_hash
    if not problem and same and previous is not None and not cfg.force:
        return {**previous, "skipped": True}, {}
    notes: dict[str, object] = {}
    stale = run_files.remove_stale(out_dir)
    if stale:
        notes["stale_files_removed"] = ",".join(stale)
    if problem == "empty":
        return None, notes
    tag, why = _supersede_tag(problem, same, previous, out_dir)
    moved = run_files.supersede(out_dir, tag)
    if moved is not None:
        notes["superseded"] = str(moved.relative_to(out_dir))
        notes["superseded_files"] = ",".join(sorted(p.name for p in moved.iterdir()))
        notes["superseded_why"] = why
        logger.warning("%s: held %s; moved %s to %s", out_dir, why, notes["superseded_files"], moved)
    return None, notes


def run(cfg: DictConfig, out_dir: Path, choices: dict[str, str] | None = None,
        overrides: list[str] | None = None) -> dict[str, object]:  # fmt: skip
    """Run one episode and write ``out_dir``. Returns the summary. Config errors raise before simulating;
    faults during the episode give ``status: "error"`` in the summary. ``overrides``: the command-line
    overrides of this run (Hydra's task overrides), kept in the summary so reports can group by them."""
    validate(cfg)  # every bad value is refused (naming it) before the folder is touched
    out_dir = Path(out_dir)
    labels = summary_choices(cfg, choices)
    # raises ConfigError / ValueError before anything is simulated or written (the recorders open their
    # files when the episode starts)
    built = Built(cfg, lambda b: run_recorders(cfg, b, out_dir, labels), chunk_ticks(cfg))
    identity = identity_of(cfg, estimator_files(built), choices)
    config_hash = identity.config_sha256
    out_dir.mkdir(parents=True, exist_ok=True)
    with RunLock(out_dir) as lock, InterruptGuard() as guard:  # one writer per run folder; SIGINT/SIGTERM
        skipped, notes = prepare_folder(cfg, out_dir, config_hash)
        if skipped is not None:
            return skipped
        if lock.stale_taken_over:
            notes["stale_lock_taken_over"] = lock.stale_taken_over
        notes["identity"] = identity.record()
        return _run_into(cfg, out_dir, built, labels, overrides, config_hash, notes, guard)


def _run_into(cfg: DictConfig, out_dir: Path, built: Built, choices: dict[str, str], overrides: list[str] | None,
              config_hash: str, notes: dict[str, object], guard: InterruptGuard) -> dict[str, object]:
    """The episode and its files, in a folder prepared (and locked) by :func:`run`. A signal during the
    episode stops it at its next progress point and the ticks simulated so far are written as an
    ``interrupted`` run (:mod:`taslel_bench.sim.interrupt`); a signal while the files are written is held
    until they are complete, then ends the run (:class:`RunInterrupted`)."""
    run_files.atomic_write(out_dir / "config.yaml", lambda p: p.write_text(run_config_yaml(cfg)))
    recorders = built.recorders  # steps.parquet, metrics, record.mcap, record.qps
    assert isinstance(recorders, RunRecorders)  # run() builds them with run_recorders
    show = _progress_printer(float(cfg.controller.stand_duration) + float(cfg.duration), bool(cfg.progress))
    time_solves_by_cpu(built)  # each solve also by the thread's CPU time (qp_solve_cpu_us)
    guard.defer = True
    try:
        with CpuWatch() as watch:  # the machine's load and this run's share of a CPU during the episode
            res: EpisodeResult = built.episode.run(progress=guard.progress(show))
        if show is not None:
            print(file=sys.stderr)
        stopped = _stopped_by_signal(res, guard)
        sections = _episode_summary(cfg, built, res, recorders.metrics)
        sections.identity = {**_run_identity(cfg, built, choices, overrides, config_hash), **notes}
        sections.plant = _plant_summary(cfg, built)
        assert watch.result is not None  # set when the with block ends
        sections.machine = watch.result.record()  # machine_cpu_share, machine_busy, ... (taslel_bench.util.machine)
        summary = sections.flat()  # the run's files add their keys when they are written
        if stopped:
            summary.update(_interrupted_fields(cfg, res, guard))
        events = _events(cfg, res, out_dir, recorders.metrics)
        video = None if stopped else _video(cfg, built, out_dir)  # record.video: once steps.parquet is written
        _write_results(out_dir, res, summary, events, recorders, video)
    except BaseException:
        recorders.steps.abandon()  # no half-written table under any name
        raise
    finally:
        guard.defer = False
    if guard.signum is not None and not stopped:  # came while the files were written: they are complete
        raise RunInterrupted(guard.signum, summary)
    return summary


def _stopped_by_signal(res: EpisodeResult, guard: InterruptGuard) -> bool:
    """The episode ended because the guard stopped it (its fault handling caught :class:`StopRequested`):
    the run is ``interrupted``, not an error (no traceback)."""
    if guard.signum is None or res.status != "error" or not str(res.message).startswith(StopRequested.__name__):
        return False
    res.status, res.message = "ok", ""  # the ticks simulated are a valid (shorter) episode; the summary says why
    res.extras.pop("traceback", None)
    return True


def _interrupted_fields(cfg: DictConfig, res: EpisodeResult, guard: InterruptGuard) -> dict[str, object]:
    """``status: interrupted`` with the signal and the time reached [s, simulated, stand included]."""
    total_s = float(cfg.controller.stand_duration) + float(cfg.duration)
    reached_s = float(res.n_ticks) / float(cfg.control_rate_hz)
    return {"status": INTERRUPTED, "interrupted_by": guard.signal_name, "interrupted_at_s": reached_s,
            "message": f"interrupted by {guard.signal_name} at t = {reached_s:.2f} s of {total_s:.2f} s simulated"}


def _run_identity(cfg: DictConfig, built: Built, choices: dict[str, str], overrides: list[str] | None,
                  config_hash: str) -> dict[str, object]:
    """What was run: the axes, the filter's settings, rates, seed, overrides, the config and code versions,
    the plant and the controller's model."""
    filt = built.filter
    out: dict[str, object] = {
        "scenario": choices.get("scenario", built.scenario.name),
        "solver": choices.get("solver", "") if built.backend is not None else "none",
        "estimator": choices.get("estimator", getattr(built.estimator, "name", "")),
        "filter_enabled": filt is not None,
        "filter_formulation": filt.settings.formulation if filt is not None else "none",
        # [1/s] k_v of the stance-contact rows (nan: filter off)
        "filter_contact_velocity_gain": float(filt.settings.contact_velocity_gain) if filt is not None else math.nan,
        "seed": int(cfg.seed),
        "duration_s": float(cfg.duration),
        "control_rate_hz": float(cfg.control_rate_hz),
        "physics_rate_hz": float(cfg.physics_rate_hz),
        "robot": built.robot.name,
        "commanded_speed_mps": float(built.controller.commanded_speed_mps),
        "friction_true": float(built.scenario.terrain.friction_at(np.zeros(2))),
        "overrides": OVERRIDE_SEPARATOR.join(sorted(overrides or [])),
        "config_sha256": config_hash,
        "memory_estimate_gb": memory_estimate_gb(cfg),  # [GB] checked against max_memory_gb before the run
        **code_version(),  # git_commit, git_dirty
    }
    if built.backend is not None:
        out["solver_settings"] = str(built.backend.describe())
    return out


def _plant_summary(cfg: DictConfig, built: Built) -> dict[str, object]:
    """The plant and the controller's model: their files and how far they agree at the stand."""
    return {**plant_identity(cfg, built),
            **plant_vs_model(built.mj_model, built.episode.model, built.controller.stand_configuration())}


def _episode_summary(cfg: DictConfig, built: Built, res: EpisodeResult, metrics: SummaryStream) -> RunSummary:
    """The episode's metrics in sections (:func:`taslel_bench.metrics.summary.summary_sections`), with the
    time spent off the loop's clock, the reference check, the estimator's own diagnostics (optional
    ``diagnostics()``), the filter's relaxations and the contact estimate's counts."""
    dt = 1.0 / float(cfg.control_rate_hz)
    stance_s, _ = built.controller.stance_swing_s
    out = summary_sections(res, dt, float(cfg.controller.stand_duration), stance_s, health_limits(cfg),
                           safety_limits(cfg), metrics)  # fmt: skip
    out.timing["recording_s"] = float(res.extras.get("recording_s", 0.0))
    out.timing["reference_s"] = float(res.extras.get("reference_s", 0.0))
    out.filter.update(_reference_summary(built, metrics, dt))  # record.reference_every: u error against the reference
    diagnostics: Callable[[], dict[str, float]] | None = getattr(built.estimator, "diagnostics", None)
    if callable(diagnostics):
        out.estimator.update({f"estimator_{k}": v for k, v in diagnostics().items()})
    if built.filter is not None:  # filter.relaxation=priority: ticks solved only after dropping barrier families
        out.filter["filter_relaxed_ticks"] = int(built.filter.relaxed_ticks)
        out.filter["filter_released_ticks"] = int(built.filter.released_ticks)
        out.filter.update({f"filter_relaxed_{k}_ticks": int(v) for k, v in built.filter.relaxed_by_family.items()})
    estimate = getattr(built.stance, "estimate", None)
    if estimate is not None:  # filter.stance_source=estimate: early touchdowns taken as stance
        out.contacts["contact_early_touchdowns"] = int(estimate.early_touchdowns)
        out.contacts["contact_late_touchdown_foot_ticks"] = int(estimate.late_touchdown_ticks)
    return out


def _reference_summary(built: Built, stream: SummaryStream, dt: float) -> dict[str, float]:
    """:func:`taslel_bench.qp.reference_check.reference_metrics` from the episode's metrics stream (the
    deadline rates as means, the u errors of the checked ticks as their series)."""
    errors = stream.u_errors()
    out = reference_metrics(built.reference_check, errors, np.zeros(0), dt)
    rates = stream.reference.result()
    for key in ("qp_deadline_miss_rate", "qp_solve_over_1ms_rate"):
        out[key] = rates.get(key, math.nan)
    return out


def _events(cfg: DictConfig, res: EpisodeResult, out_dir: Path, metrics: SummaryStream) -> list[dict]:
    """QP failures, residual alarms, the fall and the error of the run (with simulated times); an error's
    traceback goes to ``traceback.txt``."""
    dt = 1.0 / float(cfg.control_rate_hz)
    trace = res.traced()
    events = list(trace.events)
    if trace.qp_failures_not_listed:
        events.append({"t_s": trace.n * dt, "kind": "qp_failure",
                       "message": f"{trace.qp_failures_not_listed} more QP failures not listed "
                                  "(every one is counted in summary.json's qp_failed)"})  # fmt: skip
    events += metrics.alarm_events()
    if res.fell:
        events.append({"t_s": res.time_to_fall_s, "kind": "fall", "message": res.fall_reason})
    if res.status == "error":
        events.append({"t_s": trace.n * dt, "kind": "error", "message": res.message})
        if "traceback" in res.extras:
            run_files.atomic_write(out_dir / "traceback.txt", lambda p: p.write_text(str(res.extras["traceback"])))
    return events


def _write_results(out_dir: Path, res: EpisodeResult, summary: dict, events: list[dict], recorders: RunRecorders,
                   video=None) -> None:
    """episode.mcap (finished), qps.npz, steps.parquet (streamed: renamed now), events.json, video.mp4 and,
    last (it marks the run complete), summary.json; a recording failure is noted in the summary, never
    loses the run."""
    recorders.close_mcap(res, events, summary)
    recorders.save_qps(out_dir, summary)  # record.qps: the run's QP test set (taslel_bench.record.qpset)
    recorders.steps.finish()
    run_files.write_json(out_dir / run_files.EVENTS, events)
    if video is not None:
        video(summary)
    summary["memory_peak_gb"] = peak_memory_gb()
    summary[run_files.MANIFEST_KEY] = run_files.manifest(out_dir)  # the complete set, checked by a rerun
    run_files.write_json(out_dir / run_files.SUMMARY, summary)


def _video(cfg: DictConfig, built: Built, out_dir: Path):
    """record.video: a callable rendering video.mp4 from the run folder (taslel_bench.record.video), or None."""
    if not cfg.record.video:
        return None
    from taslel_bench.record.video import render_at_end_of_run

    return lambda summary: render_at_end_of_run(out_dir, built.mj_model, summary, cfg.record)


def record_job_error(out_dir: Path, choices: dict[str, str], cfg: DictConfig, exc: BaseException,
                     overrides: list[str] | None = None) -> dict:  # fmt: skip
    """Summary of a job that raised before or outside the episode (status "error", traceback saved). A
    folder another live process writes (:class:`RunFolderLocked`) is left alone: the summary is returned,
    not written."""
    summary = {
        "scenario": choices.get("scenario", ""),
        "solver": choices.get("solver", ""),
        "estimator": choices.get("estimator", ""),
        "seed": _seed_or_minus_one(cfg),
        "status": "error",
        "message": f"{type(exc).__name__}: {exc}",
        "fell": False,
        "overrides": OVERRIDE_SEPARATOR.join(sorted(overrides or [])),
    }
    if not isinstance(exc, RunFolderLocked):
        run_files.write_error_folder(out_dir, summary, traceback.format_exc())
    return summary


def _seed_or_minus_one(cfg: DictConfig) -> int:
    """The run's seed for an error summary, -1 when it is not a valid one (``seed=abc``, ``seed=${oops}``)."""
    try:
        seed = cfg.get("seed")
    except Exception:  # an interpolation error must not hide the job's own error
        return -1
    return seed if isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0 else -1


def earlier_unfinished(out_dir: Path, cfg: DictConfig) -> list[str]:
    """One line per sibling of ``out_dir`` (another timestamped folder of ``outputs/runs/``) that holds a run
    of the same config (same ``config.yaml``) that did not finish: interrupted (its summary says when) or
    killed (no summary.json). A rerun of the same command names them; it does not reuse them."""
    out_dir = Path(out_dir)
    try:
        mine = run_config_yaml(cfg)
    except Exception:  # a config that does not resolve is refused by run() itself
        return []
    lines = []
    for folder in sorted(out_dir.parent.iterdir()) if out_dir.parent.is_dir() else []:
        config = folder / "config.yaml"
        if folder == out_dir or not config.is_file():
            continue
        try:
            if config.read_text() != mine:
                continue
        except (OSError, UnicodeDecodeError):
            continue
        summary = run_files.read_summary(folder)
        if summary is None:
            lines.append(f"{folder}: an earlier run of this config that was killed (no summary.json)")
        elif summary.get("status") == INTERRUPTED:
            lines.append(f"{folder}: an earlier run of this config, {summary.get('message', INTERRUPTED)}")
    return lines


__all__ = ["earlier_unfinished", "record_job_error", "run"]
