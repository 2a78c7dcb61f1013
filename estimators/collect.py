"""Collect friction-labelled proprioception windows from MuJoCo episodes (``python -m estimators.collect``).

Each episode: the A1 stands ``stand_duration_s`` then trots under the nominal controller (trot, IK, joint PD
at 1 kHz) on a flat floor whose friction and plant parameters are drawn by :mod:`estimators.randomisation`.
Every ``WINDOW_DT_S`` the 36 features (q, qdot, commanded tau; core joint order; tau is the torque commanded
on the previous tick, exactly what the core episode runner passes as ``Proprioception.tau_joints``) are
sampled; windows of ``WINDOW_STEPS`` samples, starting every ``stride`` samples from ``first_window_s`` on,
are labelled with the floor friction. Splits are by episode (train / val / test from the training ranges,
``shifted`` from :data:`SHIFTED_RANGES`). Episodes run in the core episode loop (:mod:`taslel_bench.api`), so
a fall is the benchmark's (:mod:`taslel_bench.sim.terminations`) and ends the episode; windows ending later
than ``fall_margin_s`` before the fall are dropped. Episodes run in parallel processes, or with ``--batch N``
N nominal episodes at a time through the core's batched rollout (:mod:`estimators.collect_batch`; the same
windows and labels); the throughput is printed in env-steps/s (physics steps).

With ``--filter-fraction f`` a fraction f of the episodes (drawn per episode from a stream separate from
the plant draws, so the plant parameters of a seed do not change) runs with the ID-CBF-QP safety filter
in the loop, built through the core's façade :mod:`taslel_bench.api` from the project config
(``--filter-overrides``, e.g. ``solver=daqp``); the features then hold the *filtered* torque, as
the episode runner feeds estimators. The filter's friction is the true floor friction times a factor drawn
per episode from ``--filter-mu-scale lo hi`` (default 1 1): in the loop the filter gets an estimate, not
the truth, and a model that only learned the filter's clipping at the true mu would read its own estimate
back. With ``--filter-mu-range lo hi`` the filter's friction is drawn from U(lo, hi) independent of the
truth instead (for models that read the filter's mu as an input: a mu tied to the truth would hand them the
label). Which episodes were filtered, and the filter's mu, are saved per episode (``filtered``,
``filter_mu``) and per window (``window_filtered``) and counted in the manifest. Splits and the manifest are
written whole and then renamed into place.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS, sample_vector
from estimators.randomisation import (
    PATCH_COLUMNS,
    PATCH_RANGES,
    PLANT_FACTORS,
    TRAIN_RANGES,
    EpisodeParams,
    PatchRanges,
    Ranges,
    SurfacePatch,
    draw,
    draw_patch,
    ranges_dict,
    shifted_ranges,
)
from estimators.simple import FixedEstimator
from taslel_bench import api
from taslel_bench.interfaces import FrictionStrips, Plane, Proprioception, Terrain, quad

if TYPE_CHECKING:
    from mujoco import MjModel

PAPER_STEPS_PER_S = 100_000  # Isaac Gym, 4096 A1s, RTX 3080 (paper, "Data Collection")


@dataclass(frozen=True)
class EpisodeConfig:
    duration_s: float = 5.0  # [s] episode length including the stand
    timestep_s: float = 0.001  # [s] physics and control period
    stand_duration_s: float = 0.5  # [s] standing before the trot starts
    first_window_s: float = 0.3  # [s] earliest window start
    stride: int = 4  # [samples] between window starts
    fall_margin_s: float = 0.3  # [s] windows must end this long before a fall
    filter_overrides: tuple[str, ...] = ()  # Hydra overrides of the project config for the safety filter


@dataclass
class EpisodeResult:
    windows: np.ndarray  # (n, WINDOW_STEPS, N_FEATURES) float32
    fell: bool
    fall_time_s: float  # [s] nan if it did not fall
    steps: int  # physics steps simulated
    params: EpisodeParams
    filtered: bool = False  # the safety filter was in the loop
    filter_failures: int = 0  # ticks on which the filter's QP failed (fallback torque used)
    filter_mu: float = float("nan")  # [-] friction the filter assumed (nan: no filter)
    wall_s: float = 0.0  # [s] wall time of the episode
    # per window, at its last sample: friction under the trunk (the loop's ground truth) [-], under each foot
    # (LEGS order) [-], and whether each foot touched the floor (its contact sensor found a contact)
    y: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    y_foot: np.ndarray = field(default_factory=lambda: np.zeros((0, quad.N_LEGS), np.float32))
    foot_loaded: np.ndarray = field(default_factory=lambda: np.zeros((0, quad.N_LEGS), bool))
    patch: SurfacePatch | None = None  # the floor's patch (None: uniform floor)


_WORKER: dict[str, object] = {}


def _worker_config(overrides: tuple[str, ...]):
    """The project config (composed once per worker process and overrides)."""
    key = ("cfg", overrides)
    if key not in _WORKER:
        _WORKER[key] = api.compose(list(overrides))
    return _WORKER[key]


class WindowSampler:
    """An observer of the core episode loop (:mod:`taslel_bench.sim.observers`) that records every
    ``every_ticks`` control ticks the 36 features the loop hands estimators (q and qdot at the tick's start,
    the torque applied on the previous tick: the tick's ``Proprioception``), the friction under the trunk
    (the tick's ``GroundTruth``: the label) and the plant's sensors after the tick's physics (the feet's contact
    sensors); it counts the ticks on which the filter's QP failed (fallback torque used)."""

    def __init__(self, every_ticks: int) -> None:
        self.every = int(every_ticks)
        self._episode = None
        self._clear()

    def _clear(self) -> None:
        self.samples: list[np.ndarray] = []
        self.trunk_friction: list[float] = []  # [-] the friction under the trunk at each sample
        self.sensors: list[np.ndarray] = []  # MuJoCo sensordata after each sample's tick
        self.ticks: list[int] = []  # control tick of each sample
        self.filter_fallbacks = 0

    def start(self, episode) -> None:
        self._episode, self._sensordata = episode, episode.d.sensordata
        self._clear()

    def after_tick(self, k: int, t: float, fres) -> None:
        if fres is not None and fres.used_fallback:
            self.filter_fallbacks += 1
        if k % self.every == 0:
            sensed: Proprioception = self._episode.sensed
            self.samples.append(sample_vector(sensed.q_joints, sensed.qd_joints, sensed.tau_joints))
            self.trunk_friction.append(self._episode.truth.friction_under_trunk)
            self.sensors.append(self._sensordata.copy())
            self.ticks.append(k)


def episode_terrain(p: EpisodeParams, patch: SurfacePatch | None = None) -> Terrain:
    """The flat floor of friction ``p.friction`` [-], with ``patch`` across the path if given (floor strips
    along world x, as ``scenario=friction_patch`` builds them)."""
    if patch is None:
        return Terrain((Plane(p.friction),))
    edges, mus = patch.edges_and_frictions(p.friction)
    return Terrain((FrictionStrips(edges, mus, 50.0, 0.1),))


@dataclass(frozen=True)
class EpisodeParts:
    """What the core episode of one draw is built from (:func:`episode_parts`)."""

    settings: api.EpisodeSettings
    world: api.StaticWorld
    plant: MjModel
    controller: api.NominalController
    rng: np.random.Generator


def episode_parts(p: EpisodeParams, cfg: EpisodeConfig, patch: SurfacePatch | None = None) -> EpisodeParts:
    """The parts of the core episode of one draw: the flat floor (:func:`episode_terrain`, with ``patch``) with the
    draw's friction and plant perturbation, the draw's gait and gains, the benchmark's loop and fall rule
    (``api.episode_settings`` of the project config), no initial-state noise, the draw's seed."""
    project = _worker_config(cfg.filter_overrides)
    world = api.StaticWorld(episode_terrain(p, patch), perturbation=p.perturbation())
    plant = api.build_plant(world, api.PlantOptions(timestep_s=cfg.timestep_s), seed=p.seed)
    gait = api.GaitParams(period_s=p.period_s, swing_height_m=p.swing_height_m, speed_mps=p.speed_mps)
    controller = api.NominalController(gait, api.PDGains(kp=100.0 * p.kp_scale, kd=3.0 * p.kd_scale),
                                       stand_duration_s=cfg.stand_duration_s, fd_dt_s=cfg.timestep_s)
    settings = replace(api.episode_settings(project), duration_s=cfg.duration_s - cfg.stand_duration_s,
                       physics_dt_s=cfg.timestep_s, control_dt_s=cfg.timestep_s, init_joint_noise_rad=0.0,
                       init_base_vel_noise_mps=0.0, filter_start_s=0.0, analyse=False)
    return EpisodeParts(settings, world, plant, controller, np.random.default_rng(p.seed))


def build_episode(p: EpisodeParams, cfg: EpisodeConfig, estimator, filtered: bool = False,
                  patch: SurfacePatch | None = None, observers=(), trace: bool = True):
    """The core episode of one draw (:func:`episode_parts`), ``estimator`` in the estimator slot, the project's
    safety filter if ``filtered``, ``observers`` watching it; ``trace``: record the benchmark's per-tick trace too."""
    parts = episode_parts(p, cfg, patch)
    safety_filter = api.build_safety_filter(_worker_config(cfg.filter_overrides)) if filtered else None
    return api.Episode(parts.settings, parts.world, parts.plant, parts.controller, safety_filter, estimator,
                       parts.rng, observers=observers, trace=trace)


def run_episode(p: EpisodeParams, cfg: EpisodeConfig = EpisodeConfig(), filtered: bool = False,
                filter_mu: float | None = None, patch: SurfacePatch | None = None) -> EpisodeResult:
    """Simulate one episode (:func:`build_episode`) and cut its windows (see the module docstring);
    ``filtered``: the safety filter between the nominal controller and the plant, assuming friction
    ``filter_mu`` [-] (None: the true floor friction); ``patch``: a strip of other friction across the path."""
    wall0 = time.perf_counter()
    if not filtered:
        filter_mu = float("nan")
    elif filter_mu is None:
        filter_mu = float(p.friction)
    elif not (math.isfinite(filter_mu) and filter_mu > 0):
        raise ValueError(f"filter_mu must be positive and finite, got {filter_mu!r}")
    sampler = WindowSampler(round(WINDOW_DT_S / cfg.timestep_s))
    estimator = FixedEstimator(filter_mu if filtered else float(p.friction))  # the friction the filter assumes
    episode = build_episode(p, cfg, estimator, filtered, patch, observers=[sampler], trace=False)
    res = episode.run()
    if res.status == "error":
        raise RuntimeError(f"collection episode (seed {p.seed}) failed: {res.message}")
    fall_t = res.time_to_fall_s if res.fell else float("nan")
    samples = _Samples(np.stack(sampler.samples), np.array(sampler.trunk_friction), np.asarray(sampler.sensors))
    return _episode_result(samples, fall_t, res.n_ticks * episode.physics_per_tick, p, cfg, episode.contacts,
                           episode.terrain, patch, filtered=filtered, filter_failures=sampler.filter_fallbacks,
                           filter_mu=filter_mu, wall_s=time.perf_counter() - wall0)


@dataclass(frozen=True)
class _Samples:
    """One episode's samples, one row per sampled tick: features (n, N_FEATURES) float32, the friction under the
    trunk [-] (n,) and MuJoCo's sensordata after the tick (n, nsensordata)."""

    features: np.ndarray
    trunk_friction: np.ndarray
    sensors: np.ndarray


def _episode_result(samples: _Samples, fall_t: float, steps: int, p: EpisodeParams, cfg: EpisodeConfig, contacts,
                    terrain: Terrain, patch: SurfacePatch | None, *, filtered: bool = False, filter_failures: int = 0,
                    filter_mu: float = float("nan"), wall_s: float = 0.0) -> EpisodeResult:
    """The windows of one episode's ``samples`` (see the module docstring) and their labels: the friction under the
    trunk and under each foot (the feet's positions from the sensors, through ``contacts``, a
    ``FootContactReader`` of the plant, on ``terrain``) and the feet's contact flags at each window's last
    sample; ``fall_t`` [s] (nan: no fall), ``steps`` the physics steps simulated."""
    starts = _window_starts(len(samples.features), fall_t, cfg)
    ends = starts + WINDOW_STEPS - 1
    feet = contacts.from_sensor_log(samples.sensors[ends])
    return EpisodeResult(_cut_windows(samples.features, starts), not math.isnan(fall_t), fall_t, steps, p, filtered,
                         filter_failures, filter_mu, wall_s, y=samples.trunk_friction[ends].astype(np.float32),
                         y_foot=terrain.friction_under(feet["foot_pos_in_world"][..., :2]).astype(np.float32),
                         foot_loaded=feet["in_contact"], patch=patch)


def _window_starts(n_samples: int, fall_t: float, cfg: EpisodeConfig) -> np.ndarray:
    """First sample of each window: one every ``cfg.stride`` samples from ``first_window_s`` on, each window
    ending at least ``fall_margin_s`` before a fall (``fall_t`` [s], nan: none)."""
    first = int(np.ceil(cfg.first_window_s / WINDOW_DT_S))
    last_end = n_samples if np.isnan(fall_t) else int((fall_t - cfg.fall_margin_s) / WINDOW_DT_S)
    return np.arange(first, last_end - WINDOW_STEPS + 1, cfg.stride, dtype=np.int64)


def _cut_windows(samples: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(len(starts), WINDOW_STEPS, N_FEATURES) windows of ``samples`` from ``starts``."""
    if len(starts) == 0:
        return np.zeros((0, WINDOW_STEPS, N_FEATURES), np.float32)
    return np.stack([samples[i : i + WINDOW_STEPS] for i in starts])


def _run(args: tuple[EpisodeParams, EpisodeConfig, bool, float | None, SurfacePatch | None]) -> EpisodeResult:
    return run_episode(*args)


def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {"python": platform.python_version(), "platform": platform.platform(), "cpus": str(os.cpu_count())}
    for pkg in ("mujoco", "numpy", "pin", "taslel_bench"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "n/a"
    return out


_SPLITS = ("train", "val", "test", "shifted")  # in the order their random streams are spawned


def _positive_range(name: str, value: tuple[float, float]) -> tuple[float, float]:
    """``value`` as a (lo, hi) pair of floats with 0 < lo <= hi; a ValueError naming ``name`` otherwise."""
    lo, hi = (float(v) for v in value)
    if not 0.0 < lo <= hi:
        raise ValueError(f"{name} must be (lo, hi) with 0 < lo <= hi, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class _FilterDraws:
    """How each episode's safety filter is drawn: in the loop with probability ``fraction`` [-]; its
    friction [-] is the true one times U(``mu_scale``), or U(``mu_range``) independent of the truth when
    that is given."""

    fraction: float
    mu_scale: tuple[float, float]
    mu_range: tuple[float, float] | None

    @classmethod
    def checked(cls, fraction: float, mu_scale: tuple[float, float],
                mu_range: tuple[float, float] | None) -> _FilterDraws:
        """The draws of the ``collect`` arguments, after checking them (ValueError on a bad one)."""
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"filter_fraction must be in [0, 1], got {fraction!r}")
        scale = _positive_range("filter_mu_scale", mu_scale)
        rng = None
        if mu_range is not None:
            rng = _positive_range("filter_mu_range", mu_range)
            if scale != (1.0, 1.0):
                raise ValueError("give filter_mu_scale or filter_mu_range, not both")
        return cls(fraction, scale, rng)

    def draw(self, ep_seed: int, friction: float) -> tuple[bool, float]:
        """(filter in the loop, the filter's friction [-]) of the episode ``ep_seed`` whose floor friction is
        ``friction`` [-], from a stream separate from the plant draws (so the plant draws of a seed are the
        same for every filter_fraction)."""
        filt_rng = np.random.default_rng(np.random.SeedSequence([ep_seed, 0xF117]))
        filtered = bool(filt_rng.random() < self.fraction)
        u = float(filt_rng.random())  # one draw, so the stream is the same for both modes
        if self.mu_range is None:
            lo_s, hi_s = self.mu_scale
            mu_f = friction * (lo_s + (hi_s - lo_s) * u)
        else:
            lo_r, hi_r = self.mu_range
            mu_f = lo_r + (hi_r - lo_r) * u
        return filtered, float(mu_f)

    def manifest_fields(self) -> dict[str, object]:
        """The manifest's ``filter_mu_scale`` / ``filter_mu_range`` entries (the one not used is None)."""
        return {"filter_mu_scale": None if self.mu_range is not None else list(self.mu_scale),
                "filter_mu_range": None if self.mu_range is None else list(self.mu_range)}


@dataclass(frozen=True)
class _PatchDraws:
    """Which episodes cross a surface patch (probability ``fraction`` [-]) and the patch
    (:func:`estimators.randomisation.draw_patch` from ``ranges``), from a stream of each episode separate
    from the plant and filter draws (so those do not change with the patch settings)."""

    fraction: float = 0.0
    ranges: PatchRanges = PATCH_RANGES

    @classmethod
    def checked(cls, fraction: float, ranges: PatchRanges) -> _PatchDraws:
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"patch_fraction must be in [0, 1], got {fraction!r}")
        _positive_range("patch_start_m", ranges.start_m)
        _positive_range("patch_length_m", ranges.length_m)
        _positive_range("patch_friction", ranges.friction)
        return cls(fraction, ranges)

    def draw(self, ep_seed: int, floor_mu: float) -> SurfacePatch | None:
        if self.fraction <= 0.0:
            return None
        rng = np.random.default_rng(np.random.SeedSequence([ep_seed, 0xFA7C]))
        if rng.random() >= self.fraction:
            return None
        return draw_patch(rng, floor_mu, self.ranges)

    def manifest_fields(self) -> dict[str, object]:
        return {"patch_fraction": self.fraction, "patch_ranges": asdict(self.ranges)}


def _check_splits(counts: dict[str, int]) -> None:
    """ValueError if ``counts`` names a split other than train / val / test / shifted."""
    valid = set(_SPLITS)
    if bad := set(counts) - valid:
        raise ValueError(f"unknown split(s) {sorted(bad)}; valid splits: {sorted(valid)}")


def _split_ranges(shift_factors: tuple[str, ...], friction_range: tuple[float, float] | None
                  ) -> tuple[Ranges, Ranges, tuple[float, float] | None]:
    """(training ranges, shifted ranges, checked friction range or None): the shifted split moves
    ``shift_factors`` outside the training ranges; a ``friction_range`` (lo, hi) [-] replaces the floor
    friction range of both."""
    shifted_r = shifted_ranges(tuple(shift_factors))
    train_r = TRAIN_RANGES
    if friction_range is not None:
        friction_range = _positive_range("friction_range", friction_range)
        train_r = replace(TRAIN_RANGES, friction=friction_range)
        shifted_r = replace(shifted_r, friction=friction_range)
    return train_r, shifted_r, friction_range


Job = tuple[str, EpisodeParams, bool, float, "SurfacePatch | None"]  # split, plant, filtered, filter mu, patch


def _draw_jobs(seed: int, counts: dict[str, int], train_r: Ranges, shifted_r: Ranges, plant_beta: float,
               filters: _FilterDraws, patches: _PatchDraws = _PatchDraws()) -> list[Job]:
    """The episodes of every split, in split order: (split, plant draw, filtered, filter mu [-], patch or
    None). Each split and episode has its own spawned seed stream, so a split's draws do not depend on the
    other counts."""
    root = np.random.SeedSequence(seed)
    jobs: list[Job] = []
    for split_ss, split in zip(root.spawn(len(_SPLITS)), _SPLITS, strict=True):
        n = counts.get(split, 0)
        for ep_ss in split_ss.spawn(n):
            rng = np.random.default_rng(ep_ss)
            ep_seed = int(ep_ss.generate_state(1)[0])
            shifted = split == "shifted"
            p = draw(rng, shifted_r if shifted else train_r, ep_seed, symmetric_com=not shifted,
                     plant_beta=1.0 if shifted else plant_beta)
            filtered, mu_f = filters.draw(ep_seed, p.friction)
            jobs.append((split, p, filtered, mu_f, patches.draw(ep_seed, p.friction)))
    return jobs


def _run_jobs(jobs: list[Job], cfg: EpisodeConfig, workers: int,
              batch: int = 0) -> tuple[list[EpisodeResult], float]:
    """Run every job (in ``workers`` forked processes if > 1; with ``batch`` > 0 the nominal ones ``batch`` at a
    time on ``workers`` threads, :mod:`estimators.collect_batch`), printing the progress about every 5 % of the
    episodes; returns the results in job order and the wall time [s]."""
    t0 = time.perf_counter()
    every = max(1, len(jobs) // 20)
    shown = [0]

    def progress(n_done: int) -> None:
        if n_done // every > shown[0] // every or n_done == len(jobs):
            el = time.perf_counter() - t0
            print(f"  {n_done}/{len(jobs)} episodes, {el:.0f} s, "
                  f"eta {el / max(n_done, 1) * (len(jobs) - n_done):.0f} s", flush=True)
        shown[0] = n_done

    if batch:
        from estimators.collect_batch import run_jobs_batched  # it imports this module

        def loop(rest: list[Job]) -> list[EpisodeResult]:
            return _run_loop(rest, cfg, workers, lambda n: progress(len(jobs) - len(rest) + n))

        results = run_jobs_batched(jobs, cfg, batch, workers, loop, progress)
    else:
        results = _run_loop(jobs, cfg, workers, progress)
    return results, time.perf_counter() - t0


def _run_loop(jobs: list[Job], cfg: EpisodeConfig, workers: int,
              progress: Callable[[int], None]) -> list[EpisodeResult]:
    """The jobs in the episode loop (in ``workers`` forked processes if > 1), in job order; ``progress(n)`` after
    each with the number done."""
    args = [(p, cfg, f, s, patch) for _, p, f, s, patch in jobs]
    results: list[EpisodeResult] = []
    if workers <= 1:
        for a in args:
            results.append(_run(a))
            progress(len(results))
        return results
    ctx = mp.get_context("fork")
    with ctx.Pool(workers) as pool:
        for r in pool.imap(_run, args, chunksize=2):  # imap keeps the job order
            results.append(r)
            progress(len(results))
    return results


def _cost_by_kind(results: list[EpisodeResult]) -> dict[str, object]:
    """The manifest's per-kind (nominal / filtered episodes) cost: mean wall time [s] of one episode and
    env-steps/s of one worker (per-episode wall time summed over workers; None: no episode of that kind)."""
    filt = [r for r in results if r.filtered]
    nom = [r for r in results if not r.filtered]
    return {
        # per-episode wall time summed over workers (CPU-side cost of one episode of each kind)
        "episode_wall_s_mean": {
            "nominal": float(np.mean([r.wall_s for r in nom])) if nom else None,
            "filtered": float(np.mean([r.wall_s for r in filt])) if filt else None,
        },
        "env_steps_per_s_per_worker": {
            "nominal": sum(r.steps for r in nom) / sum(r.wall_s for r in nom) if nom else None,
            "filtered": sum(r.steps for r in filt) / sum(r.wall_s for r in filt) if filt else None,
        },
    }


def _build_manifest(seed: int, workers: int, cfg: EpisodeConfig, ranges: tuple[Ranges, Ranges],
                    shift_factors: tuple[str, ...], results: list[EpisodeResult], wall: float,
                    filters: _FilterDraws, friction_range: tuple[float, float] | None,
                    plant_beta: float) -> dict[str, object]:
    """The manifest of a collection (``ranges``: training and shifted; ``wall`` [s]: its wall time), with an
    empty ``splits`` entry for :func:`_write_split` to fill."""
    train_r, shifted_r = ranges
    total_steps = sum(r.steps for r in results)
    return {
        "seed": seed,
        "workers": workers,
        "episode_config": asdict(cfg),
        "window": {"steps": WINDOW_STEPS, "dt_s": WINDOW_DT_S, "features": N_FEATURES,
                   "layout": "q[12] rad, qdot[12] rad/s, tau_cmd[12] N·m; legs FL,FR,RL,RR x hip,thigh,calf"},
        "train_ranges": ranges_dict(train_r),
        "shifted_ranges": ranges_dict(shifted_r),
        "shift_factors": list(shift_factors),
        "shifted_note": "com_shift_xy_m is a magnitude range with random sign in the shifted set",
        "versions": _versions(),
        "wall_time_s": wall,
        "env_steps": total_steps,
        "env_steps_per_s": total_steps / wall,
        "paper_env_steps_per_s": PAPER_STEPS_PER_S,
        "filter_fraction": filters.fraction,
        "filter_overrides": list(cfg.filter_overrides),
        **filters.manifest_fields(),
        # None: the training range
        "friction_range": None if friction_range is None else list(friction_range),
        "plant_beta": plant_beta,  # plant factors ~ lo + (hi - lo) Beta(a, a) in train/val/test (1 = uniform)
        "filter_note": "filtered episodes: ID-CBF-QP safety filter in the loop (taslel_bench.api), mu = true "
                       "floor friction x U(filter_mu_scale), or U(filter_mu_range) independent of the true "
                       "friction; tau features = filtered torque; the filter's mu per episode: filter_mu",
        **_cost_by_kind(results),
        "splits": {},
    }


def _patch_row(patch: SurfacePatch | None) -> list[float]:
    return [math.nan] * 3 if patch is None else [patch.start_m, patch.length_m, patch.friction]


def _write_split(out_dir: Path, split: str, rs: list[EpisodeResult]) -> int:
    """Write ``<split>.npz`` of the episodes ``rs`` (whole, then renamed into place); returns its window
    count. Per window: X (n, WINDOW_STEPS, N_FEATURES) float32, y = friction under the trunk at the window's
    last sample [-] (the floor's without a patch), y_foot (n, 4) under each foot [-], foot_loaded (n, 4),
    episode index, window_filtered; per episode: params (``EpisodeParams.columns()``), fell, filtered,
    filter_mu [-], patch (``PATCH_COLUMNS``, nan without one)."""
    X = np.concatenate([r.windows for r in rs]).astype(np.float32)
    y = np.concatenate([r.y for r in rs]).astype(np.float32)
    ep = np.concatenate([np.full(len(r.windows), i, np.int32) for i, r in enumerate(rs)])
    params = np.array([r.params.as_row() for r in rs], np.float64)
    tmp = out_dir / f"{split}.tmp.npz"  # written whole, then renamed: never a half-written split
    np.savez_compressed(
        tmp, X=X, y=y, episode=ep, params=params,
        param_columns=np.array(EpisodeParams.columns()), fell=np.array([r.fell for r in rs]),
        filtered=np.array([r.filtered for r in rs]), filter_mu=np.array([r.filter_mu for r in rs]),
        window_filtered=np.concatenate([np.full(len(r.windows), r.filtered) for r in rs]),
        y_foot=np.concatenate([r.y_foot for r in rs]).astype(np.float32),
        foot_loaded=np.concatenate([r.foot_loaded for r in rs]).astype(bool),
        patch=np.array([_patch_row(r.patch) for r in rs], np.float64), patch_columns=np.array(PATCH_COLUMNS),
    )
    tmp.replace(out_dir / f"{split}.npz")
    return len(X)


def _split_summary(rs: list[EpisodeResult], n_windows: int) -> dict[str, object]:
    """The manifest entry of one split: episode / window counts, falls (and their floor friction [-]),
    physics steps, filtered episodes and the filter's fallback ticks."""
    fell = [r for r in rs if r.fell]
    return {
        "episodes": len(rs),
        "windows": n_windows,
        "episodes_fallen": len(fell),
        "episodes_fallen_without_windows": sum(1 for r in fell if len(r.windows) == 0),
        "fallen_friction": sorted(round(r.params.friction, 3) for r in fell),
        "env_steps": sum(r.steps for r in rs),
        "episodes_filtered": sum(r.filtered for r in rs),
        "episodes_with_patch": sum(r.patch is not None for r in rs),
        "windows_filtered": sum(len(r.windows) for r in rs if r.filtered),
        "episodes_fallen_filtered": sum(1 for r in fell if r.filtered),
        "filter_fallback_ticks": sum(r.filter_failures for r in rs),
    }


def _write_manifest(out_dir: Path, manifest: dict[str, object]) -> None:
    """Write ``manifest.json`` (whole, then renamed into place)."""
    tmp_man = out_dir / "manifest.json.tmp"
    tmp_man.write_text(json.dumps(manifest, indent=2))
    tmp_man.replace(out_dir / "manifest.json")


def collect(
    out_dir: Path,
    counts: dict[str, int],
    seed: int = 0,
    workers: int = 2,
    cfg: EpisodeConfig = EpisodeConfig(),
    filter_fraction: float = 0.0,
    filter_mu_scale: tuple[float, float] = (1.0, 1.0),
    filter_mu_range: tuple[float, float] | None = None,
    plant_beta: float = 1.0,
    shift_factors: tuple[str, ...] = PLANT_FACTORS,
    friction_range: tuple[float, float] | None = None,
    patch_fraction: float = 0.0,
    patch_ranges: PatchRanges = PATCH_RANGES,
    batch: int = 0,
) -> dict[str, object]:
    """Run all splits, write ``<split>.npz`` (X, y, episode, params, filtered, window_filtered) and
    ``manifest.json`` into ``out_dir``. ``filter_fraction`` [-]: probability that an episode runs with the
    safety filter in the loop (drawn per episode from a stream independent of the plant draws);
    ``filter_mu_scale`` (lo, hi) [-]: the filter's friction is the true one times U(lo, hi), same stream;
    ``filter_mu_range`` (lo, hi) [-]: instead, the filter's friction ~ U(lo, hi) *independent* of the true
    one (so the filter's mu, given to a model as an input, carries no information on the label by itself);
    ``plant_beta``: shape of the plant-factor draws of the train / val / test splits
    (:func:`estimators.randomisation.draw`; the shifted split is always uniform); ``shift_factors``: the
    plant factors the shifted split moves outside the training ranges (default all,
    :func:`estimators.randomisation.shifted_ranges`); ``friction_range`` (lo, hi) [-]: draw the floor friction
    of every split from U(lo, hi) instead of the training range (e.g. low-friction evaluation sets; the same
    random stream, so only the friction values change); ``patch_fraction`` [-]: probability that an episode's
    floor has a strip of other friction across the path (drawn from ``patch_ranges``, a stream of its own:
    drops and rises; labels per window under the trunk and under each foot); ``batch`` > 0: the nominal episodes
    run ``batch`` at a time through the core's batched rollout on ``workers`` threads
    (:mod:`estimators.collect_batch`; the same arrays as the episode loop's), the filtered ones in the loop."""
    if batch < 0:
        raise ValueError(f"batch must be >= 0 (0: the episode loop; N: N nominal episodes stepped together), "
                         f"got {batch!r}")
    filters = _FilterDraws.checked(filter_fraction, filter_mu_scale, filter_mu_range)
    patches = _PatchDraws.checked(patch_fraction, patch_ranges)
    _check_splits(counts)
    train_r, shifted_r, friction_range = _split_ranges(shift_factors, friction_range)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = _draw_jobs(seed, counts, train_r, shifted_r, plant_beta, filters, patches)
    results, wall = _run_jobs(jobs, cfg, workers, batch)
    manifest = _build_manifest(seed, workers, cfg, (train_r, shifted_r), shift_factors, results, wall,
                               filters, friction_range, plant_beta)
    manifest.update(patches.manifest_fields())
    manifest["batch"] = batch  # nominal episodes stepped together (0: the episode loop in worker processes)
    for split in _SPLITS:
        rs = [r for job, r in zip(jobs, results, strict=True) if job[0] == split]
        if not rs:
            continue
        n_windows = _write_split(out_dir, split, rs)
        manifest["splits"][split] = _split_summary(rs, n_windows)  # type: ignore[index]
    _write_manifest(out_dir, manifest)
    return manifest


def _parser() -> argparse.ArgumentParser:
    """The command line of ``python -m estimators.collect``."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("/work/data/estimators"), help="output folder")
    ap.add_argument("--train", type=int, default=700, help="training episodes")
    ap.add_argument("--val", type=int, default=100, help="validation episodes")
    ap.add_argument("--test", type=int, default=150, help="in-distribution test episodes")
    ap.add_argument("--shifted", type=int, default=150, help="shifted test episodes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--duration", type=float, default=EpisodeConfig.duration_s, help="episode length [s]")
    ap.add_argument("--stride", type=int, default=EpisodeConfig.stride, help="window stride [samples]")
    ap.add_argument("--filter-fraction", type=float, default=0.0,
                    help="fraction of episodes run with the safety filter in the loop (mu = true friction)")
    ap.add_argument("--filter-mu-scale", type=float, nargs=2, default=[1.0, 1.0], metavar=("LO", "HI"),
                    help="filter's mu = true friction x U(LO, HI), per filtered episode")
    ap.add_argument("--filter-mu-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="instead of --filter-mu-scale: filter's mu ~ U(LO, HI) independent of the true friction")
    ap.add_argument("--plant-beta", type=float, default=1.0,
                    help="plant factors ~ lo + (hi - lo) Beta(a, a) in train/val/test (1 = uniform; < 1 favours "
                         "the edges and corners of the training ranges)")
    ap.add_argument("--shift-factors", nargs="+", default=list(PLANT_FACTORS), choices=PLANT_FACTORS,
                    metavar="FACTOR", help="plant factors the shifted split moves outside the training ranges "
                    f"(default all: {' '.join(PLANT_FACTORS)})")
    ap.add_argument("--friction-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="floor friction ~ U(LO, HI) in every split instead of the training range (evaluation sets)")
    ap.add_argument("--patch-fraction", type=float, default=0.0,
                    help="fraction of episodes whose floor has a strip of other friction across the path")
    ap.add_argument("--patch-start", type=float, nargs=2, default=list(PATCH_RANGES.start_m), metavar=("LO", "HI"),
                    help="patch near edge ~ U(LO, HI) [m] (world x; the trunk starts at 0)")
    ap.add_argument("--patch-length", type=float, nargs=2, default=list(PATCH_RANGES.length_m), metavar=("LO", "HI"),
                    help="patch length log-uniform in [LO, HI] [m]")
    ap.add_argument("--patch-friction", type=float, nargs=2, default=list(PATCH_RANGES.friction),
                    metavar=("LO", "HI"), help="patch friction ~ U(LO, HI), at least 0.15 away from the floor's")
    ap.add_argument("--batch", type=int, default=0, metavar="N",
                    help="step N nominal episodes together (mujoco.batch on --workers threads; filtered episodes "
                         "still run one by one); 0: every episode in the episode loop")
    ap.add_argument("--filter-overrides", nargs="*", default=[],
                    help="Hydra overrides of the project config for the filter, e.g. solver=daqp")
    return ap


def _print_summary(man: dict[str, object], out: Path, workers: int) -> None:
    """Print the throughput (env-steps/s, against the paper's), the per-kind cost and the split counts."""
    rate = man["env_steps_per_s"]
    how = f"{workers} workers" if not man.get("batch") else f"batches of {man['batch']} on {workers} threads"
    print(f"collected {man['env_steps']:,} env steps in {man['wall_time_s']:.1f} s with {how}")
    print(f"throughput {rate:,.0f} env-steps/s  vs paper {PAPER_STEPS_PER_S:,} (RTX 3080, 4096 robots): "
          f"{rate / PAPER_STEPS_PER_S:.2f}x")
    per = man["env_steps_per_s_per_worker"]  # type: ignore[index]
    for kind in ("nominal", "filtered"):
        if per[kind]:
            print(f"  {kind:8s} episodes: {per[kind]:,.0f} env-steps/s per worker, "
                  f"{man['episode_wall_s_mean'][kind]:.2f} s per episode")  # type: ignore[index]
    for split, info in man["splits"].items():  # type: ignore[union-attr]
        print(f"  {split:8s} {info['episodes']:5d} episodes ({info['episodes_filtered']} filtered) "
              f"{info['windows']:7d} windows fallen {info['episodes_fallen']} "
              f"(filtered {info['episodes_fallen_filtered']}), filter fallback ticks {info['filter_fallback_ticks']}")
    print(f"wrote {out}/{{train,val,test,shifted}}.npz and manifest.json")


def main(argv: list[str] | None = None) -> None:
    a = _parser().parse_args(argv)
    cfg = EpisodeConfig(duration_s=a.duration, stride=a.stride, filter_overrides=tuple(a.filter_overrides))
    counts = {"train": a.train, "val": a.val, "test": a.test, "shifted": a.shifted}
    man = collect(a.out, counts, seed=a.seed, workers=a.workers, cfg=cfg, filter_fraction=a.filter_fraction,
                  filter_mu_scale=tuple(a.filter_mu_scale),
                  filter_mu_range=None if a.filter_mu_range is None else tuple(a.filter_mu_range),
                  plant_beta=a.plant_beta,
                  shift_factors=tuple(a.shift_factors),
                  friction_range=None if a.friction_range is None else tuple(a.friction_range),
                  patch_fraction=a.patch_fraction,
                  patch_ranges=PatchRanges(tuple(a.patch_start), tuple(a.patch_length), tuple(a.patch_friction)),
                  batch=a.batch)
    _print_summary(man, a.out, a.workers)


if __name__ == "__main__":
    main()
