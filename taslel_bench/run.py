"""Build one run from a composed config, run the episode, write the run folder.

Works with or without Hydra's runtime (tests compose configs directly): ``choices`` names the option of
each config group (``{"scenario": "flat", "solver": "daqp", ...}``).
"""

from __future__ import annotations

import hashlib
import math
import sys
import traceback
from pathlib import Path

import mujoco
import numpy as np
from omegaconf import DictConfig, OmegaConf

from taslel_bench import plant, qpset, recording, robot
from taslel_bench.config import ConfigError, build_axis, build_backend, build_model, plant_options, validate
from taslel_bench.controller import NominalController, PDGains
from taslel_bench.episode import Episode, EpisodeResult, EpisodeSettings
from taslel_bench.gait import GaitParams
from taslel_bench.health import HealthLimits
from taslel_bench.interfaces import Estimator, QPBackend, Scenario
from taslel_bench.metrics import summarize
from taslel_bench.model_report import plant_vs_model
from taslel_bench.safety_filter import FilterSettings, SafetyFilter

FRICTION_CHECK_TOL = 1e-9


class FrictionMismatch(RuntimeError):
    """The plant's foot contacts do not get the friction the scenario configured."""


def build_plant_model(cfg: DictConfig, scenario: Scenario, rng: np.random.Generator) -> mujoco.MjModel:
    options = plant_options(cfg)
    if cfg.robot.get("plant_mjcf"):
        spec = plant.mjcf_spec(Path(cfg.robot.plant_mjcf), options)
    else:
        spec = plant.a1_spec(options)
    scenario.build(spec, rng)
    return plant.compile_plant(spec)


def build_controller(cfg: DictConfig) -> NominalController:
    c = cfg.controller
    gait = GaitParams(
        period_s=float(c.period),
        duty=float(c.duty),
        swing_height_m=float(c.swing_height),
        stand_height_m=float(c.stand_height),
        speed_mps=float(c.speed),
    )
    return NominalController(
        gait,
        PDGains(kp=float(c.kp), kd=float(c.kd)),
        stand_duration_s=float(c.stand_duration),
        torque_limit_nm=float(cfg.robot.torque_limit_nm),
        fd_dt_s=1.0 / float(cfg.control_rate_hz),
    )


def filter_settings(cfg: DictConfig) -> FilterSettings:
    f = cfg.filter
    return FilterSettings(
        enabled=bool(f.enabled),
        regularization=float(f.regularization),
        regularization_target=str(f.get("regularization_target", "nominal")),
        lambda_min_n=float(f.lambda_min_n),
        contact_velocity_gain=float(f.get("contact_velocity_gain", 0.0)),
        torque_limit_nm=float(cfg.robot.torque_limit_nm),
        ecbf_enabled=bool(f.ecbf.enabled),
        ecbf_alpha1=float(f.ecbf.alpha1),
        ecbf_alpha2=float(f.ecbf.alpha2),
        fallback=str(f.fallback),
        stance_source=str(f.stance_source),
        formulation=str(f.get("formulation", "full")),
    )


def episode_settings(cfg: DictConfig) -> EpisodeSettings:
    return EpisodeSettings(
        duration_s=float(cfg.duration),
        physics_dt_s=1.0 / float(cfg.physics_rate_hz),
        control_dt_s=1.0 / float(cfg.control_rate_hz),
        fall_height_m=float(cfg.robot.fall_height_m),
        fall_tilt_rad=float(np.radians(cfg.robot.fall_tilt_deg)),
        init_joint_noise_rad=float(cfg.robot.init_joint_noise_rad),
        init_base_vel_noise_mps=float(cfg.robot.init_base_vel_noise_mps),
        filter_start_s=float(cfg.filter.get("start_time", 0.0)),
    )


def check_friction(episode: Episode) -> list[tuple[str, float, float]]:
    """Compare, on the initial stand, the friction of every foot contact (MuJoCo contact data) with the
    scenario's friction under that foot. Raises :class:`FrictionMismatch`; returns the triples checked."""
    m, d = episode.m, episode.d
    checked = []
    for foot, mu_plant in plant.measure_contact_friction(m, d):
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, foot)
        mu_cfg = episode.scenario.friction_at(d.site_xpos[site, :2])
        checked.append((foot, mu_plant, mu_cfg))
        if abs(mu_plant - mu_cfg) > FRICTION_CHECK_TOL:
            raise FrictionMismatch(
                f"scenario {episode.scenario.name!r} configures friction {mu_cfg} under {foot} but the plant "
                f"contact has {mu_plant} (check terrain geom priority and friction)"
            )
    if not checked:
        raise FrictionMismatch("no foot touches the ground in the initial stand; cannot check friction")
    return checked


class Built:
    """Everything one run needs, built (and validated) before simulation starts."""

    def __init__(self, cfg: DictConfig) -> None:
        validate(cfg)
        self.cfg = cfg
        self.rng = np.random.default_rng(int(cfg.seed))
        self.scenario: Scenario = build_axis(cfg, "scenario")  # each axis checks its arguments (ConfigError)
        self.estimator: Estimator = build_axis(cfg, "estimator")
        fs = filter_settings(cfg)
        self.backend: QPBackend | None = build_backend(cfg) if fs.enabled else None
        self.mj_model = build_plant_model(cfg, self.scenario, self.rng)
        self.controller = build_controller(cfg)
        self.filter = (
            SafetyFilter(fs, self.backend, self.scenario.clearance_profile(), self.scenario.obstacles())
            if self.backend is not None
            else None
        )
        self.episode = Episode(
            episode_settings(cfg),
            self.scenario,
            self.mj_model,
            self.controller,
            self.filter,
            self.estimator,
            self.rng,
            stance_from_contact=fs.stance_source == "contact",
            model=build_model(cfg),
        )
        self.friction_checked = check_friction(self.episode)  # on the state every run of the episode starts from


def health_limits(cfg: DictConfig) -> HealthLimits:
    h = cfg.get("health") or {}
    return HealthLimits(**{k: float(v) for k, v in h.items()})


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def plant_identity(cfg: DictConfig, built: Built) -> dict[str, object]:
    """What was simulated and what the controller believed: the plant source (the URDF of
    example-robot-data or ``robot.plant_mjcf``) with its content hash, and the controller model's source,
    hash and total mass (the filter's equations of motion)."""
    mjcf = cfg.robot.get("plant_mjcf")
    plant_src = Path(mjcf) if mjcf else robot.a1_urdf_path()
    return {
        "plant_source": str(plant_src),
        "plant_sha256": file_sha256(plant_src),
        "plant_total_mass_kg": float(sum(built.mj_model.body_mass)),
        "model_source": str(robot.a1_urdf_path()),
        "model_sha256": file_sha256(robot.a1_urdf_path()),
        "model_total_mass_kg": float(built.episode.model.total_mass_kg),
    }


def _progress_printer(duration: float, enabled: bool):
    if not enabled:
        return None

    def show(t: float) -> None:
        print(f"\r  simulated {t:6.2f} / {duration:.2f} s", end="", file=sys.stderr, flush=True)

    return show


def run(cfg: DictConfig, out_dir: Path, choices: dict[str, str] | None = None,
        overrides: list[str] | None = None) -> dict[str, object]:  # fmt: skip
    """Run one episode and write ``out_dir``. Returns the summary. Config errors raise before simulating;
    faults during the episode give ``status: "error"`` in the summary. ``overrides``: the command-line
    overrides of this run (Hydra's task overrides), kept in the summary so reports can group by them."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if not cfg.get("force", False):
        done = recording.completed_summary(out_dir)
        if done is not None:
            done["skipped"] = True
            return done
    built = Built(cfg)  # raises ConfigError / ValueError before anything is simulated
    choices = dict(choices or {})
    recording.atomic_write(out_dir / "config.yaml", lambda p: p.write_text(OmegaConf.to_yaml(cfg, resolve=True)))
    qp_recorder = _qp_recorder(cfg, built, choices)  # record.qps (None when off)
    show = _progress_printer(float(cfg.controller.stand_duration) + float(cfg.duration), bool(cfg.progress))
    res: EpisodeResult = built.episode.run(progress=show)
    if show is not None:
        print(file=sys.stderr)
    dt = 1.0 / float(cfg.control_rate_hz)
    summary: dict[str, object] = {
        "scenario": choices.get("scenario", built.scenario.name),
        "solver": choices.get("solver", "") if built.backend is not None else "none",
        "estimator": choices.get("estimator", getattr(built.estimator, "name", "")),
        "filter_enabled": built.filter is not None,
        "filter_formulation": built.filter.settings.formulation if built.filter is not None else "none",
        "filter_contact_velocity_gain": (  # [1/s] k_v of the stance-contact rows (nan: filter off)
            float(built.filter.settings.contact_velocity_gain) if built.filter is not None else math.nan
        ),
        "seed": int(cfg.seed),
        "duration_s": float(cfg.duration),
        "control_rate_hz": float(cfg.control_rate_hz),
        "physics_rate_hz": float(cfg.physics_rate_hz),
        "commanded_speed_mps": float(cfg.controller.speed),
        "friction_true": float(built.scenario.friction_at(np.zeros(2))),
        "overrides": ",".join(sorted(overrides or [])),
    }
    summary.update(plant_identity(cfg, built))
    summary.update(plant_vs_model(built.mj_model, built.episode.model,
                                  built.controller.stand_configuration()))
    stance_s = float(cfg.controller.period) * float(cfg.controller.duty)
    summary.update(summarize(res, dt, float(cfg.controller.stand_duration), stance_s, health_limits(cfg)))
    if built.backend is not None:
        summary["solver_settings"] = str(built.backend.describe())
    events = list(res.trace.events)
    if res.fell:
        events.append({"t_s": res.time_to_fall_s, "kind": "fall", "message": res.fall_reason})
    if res.status == "error":
        events.append({"t_s": res.trace.n * dt, "kind": "error", "message": res.message})
        if "traceback" in res.extras:
            recording.atomic_write(out_dir / "traceback.txt", lambda p: p.write_text(str(res.extras["traceback"])))
    mcap_error = None
    if cfg.record.mcap:
        try:
            from taslel_bench.mcap_log import write_episode_mcap

            write_episode_mcap(out_dir / "episode.mcap", res.trace, events, summary)
        except Exception:  # noqa: BLE001 - recording must not lose the run: note it and keep the other files
            mcap_error = traceback.format_exc()
            summary["mcap_error"] = mcap_error.strip().splitlines()[-1]
    if qp_recorder is not None:  # record.qps: the run's QP test set (taslel_bench.qpset)
        try:
            qp_recorder.save(out_dir / qpset.FILENAME, {"source": "taslel_bench.run"})
            summary["qps_recorded"] = len(qp_recorder)
        except Exception:  # noqa: BLE001 - recording must not lose the run
            summary["qps_error"] = traceback.format_exc().strip().splitlines()[-1]
    recording.write_parquet(out_dir / recording.STEPS, res.trace.to_frame(dt))
    recording.write_json(out_dir / recording.EVENTS, events)
    recording.write_json(out_dir / recording.SUMMARY, summary)  # written last: marks the run complete
    return summary


def _qp_recorder(cfg: DictConfig, built: Built, choices: dict[str, str]):
    """A :class:`taslel_bench.qpset.QPRecorder` hooked into the episode when ``record.qps`` is on."""
    if not cfg.record.get("qps", False) or built.filter is None:
        return None
    info = {
        "scenario": choices.get("scenario", built.scenario.name), "solver": choices.get("solver", ""),
        "estimator": choices.get("estimator", getattr(built.estimator, "name", "")), "seed": int(cfg.seed),
        "control_rate_hz": float(cfg.control_rate_hz), "backend": str(built.backend.describe()),
    }  # fmt: skip
    rec = qpset.QPRecorder(info, every=int(cfg.record.get("qps_every", 1)))
    built.episode.qp_recorder = rec
    return rec


def record_job_error(out_dir: Path, choices: dict[str, str], cfg: DictConfig, exc: BaseException,
                     overrides: list[str] | None = None) -> dict:  # fmt: skip
    """Summary of a job that raised before or outside the episode (status "error", traceback saved)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    tb = traceback.format_exc()
    recording.atomic_write(out_dir / "traceback.txt", lambda p: p.write_text(tb))
    summary = {
        "scenario": choices.get("scenario", ""),
        "solver": choices.get("solver", ""),
        "estimator": choices.get("estimator", ""),
        "seed": _seed_or_minus_one(cfg),
        "status": "error",
        "message": f"{type(exc).__name__}: {exc}",
        "fell": False,
        "overrides": ",".join(sorted(overrides or [])),
    }
    recording.write_json(out_dir / recording.SUMMARY, summary)
    return summary


def _seed_or_minus_one(cfg: DictConfig) -> int:
    """The run's seed for an error summary, -1 when it is not a valid one (``seed=abc``, ``seed=${oops}``)."""
    try:
        seed = cfg.get("seed")
    except Exception:  # noqa: BLE001 - an interpolation error must not hide the job's own error
        return -1
    return seed if isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0 else -1


__all__ = ["Built", "ConfigError", "FrictionMismatch", "check_friction", "run"]
