"""Batched rollout speed (``python -m studies.batch_rollout_speed [--envs 256] [--threads 2] [--duration 5]
[--loop-episodes 40] [--filtered-episodes 2]``).

Printed bench lines on the data collection's nominal training draws (seed 0: each environment's floor friction,
plant perturbation, gait and PD gains as ``estimators.collect`` draws them; 1 kHz control and physics):

* **batched nominal**: ``api.BatchRollout`` (``mujoco.batch`` physics on ``--threads`` threads, the trot's PD of all
  environments in one compiled call per tick, fall terms after every step, window sampling): physics steps per
  second of its ticks' loop, and with the environments' setup (plants, reference timelines, initial states);
* **physics only**: the same batch (same models, initial states, and environments ending on the same ticks)
  replaying the recorded torques with no controller: the batched loop's limit, and the ratio of the two (the two
  measured ``--repeat`` times in turns; the best and the median of each are printed);
* **loop today**: ``estimators.collect`` on the first ``--loop-episodes`` draws (the episode loop, ``--threads``
  worker processes);
* **filtered**: episodes with the safety filter (``filter=id_cbf_qp``, the project's solver) in the episode loop,
  per worker; not batched (see :mod:`taslel_bench.sim.batch`);
* threads, load average before and after, machine and commit, and the paper's figure.

A printed benchmark, not a test: the numbers depend on the machine and on what else runs on it.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from estimators.collect import (
    PAPER_STEPS_PER_S,
    TRAIN_RANGES,
    EpisodeConfig,
    _draw_jobs,
    _FilterDraws,
    collect,
    episode_parts,
    run_episode,
)
from estimators.features import WINDOW_DT_S
from estimators.randomisation import EpisodeParams, shifted_ranges
from taslel_bench import api

PAPER_CLAIM = ('paper, "Data Collection" (Nvidia Isaac): "A simulation with 4096 parallel Unitree A1 quadrupeds '
               'reaches 100,000 steps per second on an Nvidia RTX 3080 12GB GPU"')


def _draws(n: int) -> list[EpisodeParams]:
    """The first ``n`` training draws of ``estimators.collect`` with seed 0 (its episode order)."""
    jobs = _draw_jobs(0, {"train": n}, TRAIN_RANGES, shifted_ranges(), 1.0, _FilterDraws.checked(0.0, (1.0, 1.0), None))
    return [p for _, p, _, _, _ in jobs]


def batched(draws: list[EpisodeParams], cfg: EpisodeConfig, threads: int) -> tuple[api.BatchRollout, float]:
    """(the rollout of ``draws`` with window sampling and the torques recorded, the plants' build time [s])."""
    t0 = time.perf_counter()
    parts = [episode_parts(p, cfg) for p in draws]
    build_s = time.perf_counter() - t0
    envs = [api.BatchEnv(x.world, x.plant, x.controller, x.rng) for x in parts]
    rollout = api.BatchRollout(parts[0].settings, envs, nthread=threads, record="torques",
                               sample_every_ticks=round(WINDOW_DT_S / cfg.timestep_s))
    return rollout, build_s


def physics_only(rollout: api.BatchRollout, res: api.BatchResult) -> tuple[float, bool]:
    """(physics steps per second, the replay ended in the rollout's final states): the rollout's batch from its
    initial states, each tick's recorded torques written and every environment stepped while it ran."""
    b, act = rollout.batch, rollout.bridge.actuator_ids
    final = b.bind("qpos").copy()
    assert res.trace is not None  # recorded
    u, ends = res.trace.u, np.array([o.n_ticks for o in res.outcomes])
    rollout.reset()
    ctrl, n, steps = b.bind("ctrl"), len(ends), 0
    t0 = time.perf_counter()
    for k in range(int(ends.max())):
        ids = np.flatnonzero(ends > k)
        ctrl[:, act] = u[k]
        b.step(None if ids.size == n else ids)
        steps += ids.size
    wall = time.perf_counter() - t0
    return steps / wall, bool(np.array_equal(b.bind("qpos"), final))


def interleaved(rollout: api.BatchRollout, repeat: int) -> tuple[api.BatchResult, dict[str, list[float]], bool]:
    """(the last batched result; per kind, "batched" and "physics", ``repeat`` rates [env-steps/s] measured in
    turns and the process's CPU time per env-step [µs] (all threads: how busy the cores were, not the wall);
    every replay reached the rollout's final states)."""
    out: dict[str, list[float]] = {"batched": [], "physics": [], "batched_cpu_us": [], "physics_cpu_us": []}
    same = True
    for _ in range(repeat):
        cpu0 = time.process_time()
        res = rollout.run()
        cpu1 = time.process_time()
        rate, ok = physics_only(rollout, res)
        cpu2 = time.process_time()
        out["batched"].append(res.env_steps_per_s)
        out["physics"].append(rate)
        out["batched_cpu_us"].append((cpu1 - cpu0) / res.physics_steps * 1e6)  # the replay steps as many
        out["physics_cpu_us"].append((cpu2 - cpu1) / res.physics_steps * 1e6)
        same &= ok
    return res, out, same


def loop_today(n: int, cfg: EpisodeConfig, workers: int) -> float:
    """env-steps/s of ``estimators.collect`` (the episode loop, ``workers`` processes) on ``n`` training episodes."""
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        man = collect(Path(tmp), {"train": n}, seed=0, workers=workers, cfg=cfg)
    return float(man["env_steps_per_s"])  # type: ignore[arg-type]


def filtered(draws: list[EpisodeParams], cfg: EpisodeConfig) -> float:
    """env-steps/s of one worker running ``draws`` with the safety filter in the episode loop."""
    results = [run_episode(p, cfg, filtered=True) for p in draws]
    return sum(r.steps for r in results) / sum(r.wall_s for r in results)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--envs", type=int, default=256, help="environments stepped together")
    ap.add_argument("--threads", type=int, default=2, help="batch threads (and the loop's worker processes)")
    ap.add_argument("--duration", type=float, default=EpisodeConfig.duration_s,
                    help="episode length with the stand [s]")
    ap.add_argument("--repeat", type=int, default=3, help="batched and physics-only runs, in turns")
    ap.add_argument("--loop-episodes", type=int, default=40, help="episodes of the loop's figure (0: skip)")
    ap.add_argument("--filtered-episodes", type=int, default=2, help="episodes of the filtered figure (0: skip)")
    a = ap.parse_args(argv)
    cfg = EpisodeConfig(duration_s=a.duration)
    info = api.machine_info()
    print(f"machine {info['cpu']} ({info['cores']} cores), {info['code']}; load before {_load()}", flush=True)
    draws = _draws(a.envs)
    rollout, build_s = batched(draws, cfg, a.threads)
    res, m, same = interleaved(rollout, a.repeat)
    rates, limits = m["batched"], m["physics"]
    rate, limit = max(rates), max(limits)
    setup_s = build_s + res.setup_time_s
    print(f"batched nominal: {rate:,.0f} env-steps/s, best of {a.repeat} (median {np.median(rates):,.0f}; {a.envs} "
          f"envs x {a.duration:g} s, {res.nthread} threads, {res.physics_steps:,} steps, "
          f"{sum(o.fell for o in res.outcomes)} falls; CPU {min(m['batched_cpu_us']):.1f} µs per env-step); with the "
          f"setup ({build_s:.1f} s plants + {res.setup_time_s:.1f} s timelines and initial states, once): "
          f"{res.physics_steps / (setup_s + res.physics_steps / rate):,.0f} env-steps/s", flush=True)
    print(f"physics only (same batch, recorded torques replayed, no controller): {limit:,.0f} env-steps/s, best of "
          f"{a.repeat} (median {np.median(limits):,.0f}; CPU {min(m['physics_cpu_us']):.1f} µs per env-step); "
          f"batched / physics only = {rate / limit:.2f} (medians {np.median(rates) / np.median(limits):.2f}); "
          f"replays reached the same final states: {same}; load {_load()}", flush=True)
    if a.loop_episodes:
        print(f"loop today (estimators.collect, {a.threads} workers, {a.loop_episodes} episodes): "
              f"{loop_today(a.loop_episodes, cfg, a.threads):,.0f} env-steps/s; load {_load()}", flush=True)
    if a.filtered_episodes:
        print(f"filtered (filter=id_cbf_qp, episode loop, not batched): "
              f"{filtered(draws[: a.filtered_episodes], cfg):,.0f} env-steps/s per worker; load {_load()}", flush=True)
    print(f"{PAPER_CLAIM}: batched nominal = {rate / PAPER_STEPS_PER_S:.2f}x that figure")


def _load() -> str:
    """The 1, 5 and 15 minute load averages."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


if __name__ == "__main__":
    main()
