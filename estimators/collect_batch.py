"""Batched collection (``python -m estimators.collect --batch N``): nominal episodes stepped N at a time through the
core's batched rollout (``api.BatchRollout``: ``mujoco.batch`` physics on a thread pool, the trot's joint PD of all
of them in one compiled call per tick), with the same windows and labels as :func:`estimators.collect.run_episode`
of each, bit for bit (``tests/test_batch_rollout.py``). Filtered episodes are not batched (the filter's model
update and QP run per episode and per tick): they run in the episode loop as before.

Episodes with a surface patch have another plant layout (floor strips instead of one plane) than those without,
so the two kinds are batched apart. A batch's parts (plants, controllers and their references: the serial part of its
cost) are built in worker processes, one per thread, then stepped together. An episode's ``wall_s`` is its share
of its batch's CPU time (batch wall time x threads / episodes), so the manifest's per-worker rate is per thread.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import time
from collections.abc import Callable
from multiprocessing.pool import Pool

import numpy as np

from estimators.collect import (
    EpisodeConfig,
    EpisodeParts,
    EpisodeResult,
    Job,
    _episode_result,
    _Samples,
    episode_parts,
)
from estimators.features import WINDOW_DT_S
from estimators.randomisation import EpisodeParams, SurfacePatch
from taslel_bench import api


def ready_parts(args: tuple[EpisodeParams, EpisodeConfig, SurfacePatch | None]) -> EpisodeParts:
    """One episode's parts (draw, config, patch) with its controller's references made for the whole episode (its
    per-period table filled: the batch then only looks them up); run in a worker process, the parts pickled back."""
    p, cfg, patch = args
    parts = episode_parts(p, cfg, patch)
    parts.controller.reference_timeline(round(cfg.duration_s / cfg.timestep_s), cfg.timestep_s)
    return parts


def run_batch(jobs: list[tuple[EpisodeParams, SurfacePatch | None]], cfg: EpisodeConfig, nthread: int,
              pool: Pool | None = None) -> list[EpisodeResult]:
    """The nominal episodes of ``jobs`` (draw, patch or None; all with a patch or all without) stepped together on
    ``nthread`` threads, their parts built in ``pool``'s processes (None: here); their results in job order, equal
    to :func:`estimators.collect.run_episode`'s."""
    if not jobs:
        return []
    if len({patch is None for _, patch in jobs}) > 1:
        raise ValueError("run_batch: jobs mix episodes with and without a patch (two plant layouts); batch them apart")
    wall0 = time.perf_counter()
    args = [(p, cfg, patch) for p, patch in jobs]
    parts = [ready_parts(a) for a in args] if pool is None else pool.map(ready_parts, args)
    envs = [api.BatchEnv(x.world, x.plant, x.controller, x.rng) for x in parts]
    rollout = api.BatchRollout(parts[0].settings, envs, nthread=nthread,
                               sample_every_ticks=round(WINDOW_DT_S / cfg.timestep_s))
    res = rollout.run()
    smp = res.samples
    assert smp is not None  # sample_every_ticks > 0
    cpu_share = (time.perf_counter() - wall0) * res.nthread / len(jobs)  # [s] per episode
    out = []
    for i, ((p, patch), o) in enumerate(zip(jobs, res.outcomes, strict=True)):
        if o.status == "error":
            raise RuntimeError(f"collection episode (seed {p.seed}) failed: {o.message}")
        n = int(np.searchsorted(smp.ticks, o.n_ticks))  # the samples of the ticks it ran
        features = np.concatenate([smp.q_joints[:n, i], smp.qd_joints[:n, i], smp.tau_prev[:n, i]], axis=-1)
        samples = _Samples(features.astype(np.float32), smp.friction_under_trunk[:n, i], smp.sensordata[:n, i])
        fall_t = o.time_to_fall_s if o.fell else math.nan
        out.append(_episode_result(samples, fall_t, o.n_ticks * rollout.physics_per_tick, p, cfg, rollout.contacts,
                                   parts[i].world.terrain, patch, wall_s=cpu_share))
    return out


def run_jobs_batched(jobs: list[Job], cfg: EpisodeConfig, batch: int, nthread: int,
                     run_loop: Callable[[list[Job]], list[EpisodeResult]],
                     progress: Callable[[int], None]) -> list[EpisodeResult]:
    """Every job, in job order: the nominal ones ``batch`` at a time on ``nthread`` threads (with and without a
    patch apart; each batch's parts built in ``nthread`` worker processes first), the filtered ones through
    ``run_loop`` (the episode loop); ``progress(n)`` after each batch with the episodes done so far."""
    if batch < 1:
        raise ValueError(f"batch must be >= 1 (episodes stepped together), got {batch!r}")
    results: dict[int, EpisodeResult] = {}
    nominal = [i for i, job in enumerate(jobs) if not job[2]]
    with mp.get_context("fork").Pool(max(1, nthread)) as pool:
        for with_patch in (False, True):
            kind = [i for i in nominal if (jobs[i][4] is not None) == with_patch]
            for start in range(0, len(kind), batch):
                chunk = kind[start : start + batch]
                done = run_batch([(jobs[i][1], jobs[i][4]) for i in chunk], cfg, nthread, pool)
                results.update(zip(chunk, done, strict=True))
                progress(len(results))
    filtered = [i for i, job in enumerate(jobs) if job[2]]
    results.update(zip(filtered, run_loop([jobs[i] for i in filtered]), strict=True))
    return [results[i] for i in range(len(jobs))]
