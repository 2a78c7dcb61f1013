"""The fast nominal loop (estimators.fastloop) against the core episode loop: bit-identical samples, the same
fall tick and time, the same collected windows; filtered episodes are refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators.collect import EpisodeConfig, WindowSampler, build_episode, run_episode
from estimators.fastloop import run_nominal
from estimators.randomisation import TRAIN_RANGES, draw

EVERY = 30  # ticks between samples (WINDOW_DT_S at 1 kHz)


def _core_and_fast(p, cfg: EpisodeConfig):
    sampler = WindowSampler(EVERY, p.friction)
    core = build_episode(p, cfg, sampler).run()
    fast = run_nominal(build_episode(p, cfg, WindowSampler(EVERY, p.friction)), EVERY)
    return core, np.stack(sampler.samples), fast


@pytest.mark.parametrize("seed", [1, 7])
def test_fast_loop_samples_are_the_core_loops_bit_for_bit(seed: int) -> None:
    p = draw(np.random.default_rng(seed), TRAIN_RANGES, seed=seed)
    core, core_samples, fast = _core_and_fast(p, EpisodeConfig(duration_s=1.6))
    assert core.status == fast.status == "ok" and not core.fell and not fast.fell
    assert fast.n_ticks == core.n_ticks == 1600
    assert fast.samples.shape == core_samples.shape == (54, 36)
    assert np.array_equal(fast.samples, core_samples)  # same physics, operation for operation


def test_fast_loop_falls_on_the_same_tick() -> None:
    p = dataclasses.replace(draw(np.random.default_rng(1), TRAIN_RANGES, seed=1), motor_strength_scale=0.4,
                            trunk_mass_scale=1.5)  # weak motors, heavy trunk: falls within a second
    core, core_samples, fast = _core_and_fast(p, EpisodeConfig(duration_s=2.0))
    assert core.fell and fast.fell
    assert fast.time_to_fall_s == core.time_to_fall_s and fast.n_ticks == core.n_ticks
    assert np.array_equal(fast.samples, core_samples)


def test_collect_loops_give_the_same_windows_and_filtered_runs_refuse_the_fast_loop() -> None:
    p = draw(np.random.default_rng(3), TRAIN_RANGES, seed=3)
    a = run_episode(p, EpisodeConfig(duration_s=1.6, stride=2, loop="fast"))
    b = run_episode(p, EpisodeConfig(duration_s=1.6, stride=2, loop="core"))
    assert a.windows.shape == (3, 40, 36) and np.array_equal(a.windows, b.windows) and a.steps == b.steps
    with pytest.raises(ValueError, match="loop"):
        run_episode(p, EpisodeConfig(duration_s=1.6, loop="gpu"))
    ep = build_episode(p, EpisodeConfig(duration_s=0.6), WindowSampler(EVERY, p.friction), filtered=True)
    with pytest.raises(ValueError, match="unfiltered"):
        run_nominal(ep, EVERY)


def test_references_equal_the_controllers_tick_by_tick() -> None:
    """The per-period shortcut of fastloop.references gives what update_references gives on every tick."""
    from estimators.fastloop import references
    from taslel_bench import api

    gait = api.GaitParams(period_s=0.437, speed_mps=0.5)
    make = lambda: api.NominalController(gait, api.PDGains(), stand_duration_s=0.5, fd_dt_s=1e-3)
    refs = references(make(), 3000, 1e-3)
    ctl = make()
    for k in range(3000):
        ctl.update_references(k * 1e-3)
        assert np.array_equal(refs[k, 0], ctl.q_des) and np.array_equal(refs[k, 1], ctl.qd_des), k


def test_patch_episode_labels_per_foot_in_both_loops() -> None:
    """A drop patch across the path: the per-foot labels change foot by foot (front feet first), the trunk
    label follows the trunk, the two loops give the same windows and labels; a flat floor labels every
    window with its friction."""
    from estimators.randomisation import SurfacePatch

    p = dataclasses.replace(draw(np.random.default_rng(3), TRAIN_RANGES, seed=3), friction=0.9, speed_mps=0.5)
    patch = SurfacePatch(start_m=0.45, length_m=3.0, friction=0.3)
    cfg = EpisodeConfig(duration_s=4.0, stride=1)
    a = run_episode(p, cfg, patch=patch)
    b = run_episode(p, dataclasses.replace(cfg, loop="core"), patch=patch)
    assert np.array_equal(a.windows, b.windows)
    assert np.array_equal(a.y, b.y) and np.array_equal(a.y_foot, b.y_foot)
    assert np.array_equal(a.foot_loaded, b.foot_loaded)
    assert set(np.unique(a.y_foot)) == {np.float32(0.9), np.float32(0.3)}
    mixed = a.y_foot.min(axis=1) != a.y_foot.max(axis=1)  # some feet on the patch, some not
    assert mixed.any()
    first_on = [int(np.argmax(a.y_foot[:, leg] < 0.5)) for leg in range(4)]  # FL, FR, RL, RR
    assert max(first_on[:2]) < min(first_on[2:])  # the front feet reach the patch first
    trunk_on = int(np.argmax(a.y < 0.5))
    assert max(first_on[:2]) <= trunk_on <= min(first_on[2:])  # the trunk is between front and rear feet
    flat = run_episode(p, EpisodeConfig(duration_s=1.6, stride=2))
    assert np.all(flat.y == np.float32(0.9)) and np.all(flat.y_foot == np.float32(0.9))
