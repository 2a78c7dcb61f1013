"""Data collection runs the benchmark's episode loop with a sampling observer and no trace: the same samples,
sensors and fall as the loop that records its trace, and per-foot labels that follow the feet."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators.collect import EpisodeConfig, WindowSampler, build_episode, run_episode
from estimators.randomisation import TRAIN_RANGES, SurfacePatch, draw
from estimators.simple import FixedEstimator
from taslel_bench.sim.observers import MetricsFeed

EVERY = 30  # ticks between samples (WINDOW_DT_S at 1 kHz)


def _sampled(p, cfg: EpisodeConfig, trace: bool, filtered: bool = False):
    sampler = WindowSampler(EVERY)
    res = build_episode(p, cfg, FixedEstimator(p.friction), filtered, observers=[sampler], trace=trace).run()
    return res, sampler


@pytest.mark.parametrize("seed", [1, 7])
def test_samples_without_the_trace_are_the_traced_loops_bit_for_bit(seed: int) -> None:
    p = draw(np.random.default_rng(seed), TRAIN_RANGES, seed=seed)
    cfg = EpisodeConfig(duration_s=1.6)
    traced, a = _sampled(p, cfg, trace=True)
    bare, b = _sampled(p, cfg, trace=False)
    assert traced.status == bare.status == "ok" and not traced.fell and not bare.fell
    assert bare.trace is None and traced.n_ticks == bare.n_ticks == 1600
    assert len(b.samples) == 54 and b.ticks == list(range(0, 1600, EVERY))
    assert np.array_equal(np.stack(a.samples), np.stack(b.samples))
    assert np.array_equal(np.stack(b.sensors), traced.trace.sensordata_mj[b.ticks])  # the state after each tick
    k = b.ticks[5]  # a sample's joint angles are the plant's at the tick's start: the state after tick k - 1
    q_core = traced.trace.qpos_mj[k - 1, np.asarray(b._episode.bridge.joint_qadr)]  # [rad] core joint order
    assert np.array_equal(np.stack(b.samples)[5, :12], q_core.astype(np.float32))


def test_a_fall_ends_both_loops_on_the_same_tick() -> None:
    p = dataclasses.replace(draw(np.random.default_rng(1), TRAIN_RANGES, seed=1), motor_strength_scale=0.4,
                            trunk_mass_scale=1.5)  # weak motors, heavy trunk: falls within a second
    traced, a = _sampled(p, EpisodeConfig(duration_s=2.0), trace=True)
    bare, b = _sampled(p, EpisodeConfig(duration_s=2.0), trace=False)
    assert traced.fell and bare.fell and traced.time_to_fall_s == bare.time_to_fall_s
    assert traced.n_ticks == bare.n_ticks < 2000
    assert np.array_equal(np.stack(a.samples), np.stack(b.samples))


def test_filtered_collection_counts_the_filters_fallbacks_and_a_bare_loop_refuses_chunk_observers() -> None:
    p = draw(np.random.default_rng(3), TRAIN_RANGES, seed=3)
    traced, a = _sampled(p, EpisodeConfig(duration_s=1.0), trace=True, filtered=True)
    assert a.filter_fallbacks == int(traced.trace.qp_fallback[: traced.trace.n].sum())
    episode = build_episode(p, EpisodeConfig(duration_s=0.6), FixedEstimator(p.friction),
                            observers=[MetricsFeed(None)], trace=False)
    with pytest.raises(ValueError, match="on_chunk"):
        episode.run()


def test_patch_episode_labels_per_foot() -> None:
    """A drop patch across the path: the per-foot labels change foot by foot (front feet first), the trunk
    label follows the trunk; a flat floor labels every window with its friction."""
    p = dataclasses.replace(draw(np.random.default_rng(3), TRAIN_RANGES, seed=3), friction=0.9, speed_mps=0.5)
    patch = SurfacePatch(start_m=0.45, length_m=3.0, friction=0.3)
    a = run_episode(p, EpisodeConfig(duration_s=4.0, stride=1), patch=patch)
    assert set(np.unique(a.y_foot)) == {np.float32(0.9), np.float32(0.3)}
    mixed = a.y_foot.min(axis=1) != a.y_foot.max(axis=1)  # some feet on the patch, some not
    assert mixed.any()
    first_on = [int(np.argmax(a.y_foot[:, leg] < 0.5)) for leg in range(4)]  # FL, FR, RL, RR
    assert max(first_on[:2]) < min(first_on[2:])  # the front feet reach the patch first
    trunk_on = int(np.argmax(a.y < 0.5))
    assert max(first_on[:2]) <= trunk_on <= min(first_on[2:])  # the trunk is between front and rear feet
    flat = run_episode(p, EpisodeConfig(duration_s=1.6, stride=2))
    assert np.all(flat.y == np.float32(0.9)) and np.all(flat.y_foot == np.float32(0.9))
