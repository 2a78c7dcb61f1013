"""The batched rollout (``mujoco.batch`` physics, the trot's PD over all environments in one call) is the episode
loop bit for bit: per tick qpos, qvel and torques, the falls and their times, at one and two threads; batched data
collection writes the loop's arrays; what it cannot run is refused by name."""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import numpy as np
import pytest

from estimators.collect import EpisodeConfig, collect, run_episode
from estimators.collect_batch import run_batch
from estimators.randomisation import TRAIN_RANGES, SurfacePatch, draw
from estimators.simple import FixedEstimator
from taslel_bench import api
from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.control.terrain_following import TerrainFollowingController
from taslel_bench.interfaces import FrictionStrips, Plane, PlantPerturbation, Terrain

# per environment: floor friction [-] and trunk mass scale [-]; the first falls (a thigh touches the floor at 1.292 s)
WORLDS = ((0.02, 1.0), (0.8, 1.3), (0.3, 1.0), (1.0, 1.6))
SEEDS = (100, 101, 102, 103)  # each environment's initial-state noise


class _PlantRecorder:
    """An episode observer keeping MuJoCo qpos, qvel and the applied torque (core order) after every tick."""

    def start(self, episode) -> None:
        self.episode, self.qpos, self.qvel, self.u = episode, [], [], []

    def after_tick(self, k: int, t: float, fres) -> None:
        d, act = self.episode.d, self.episode.bridge.actuator_ids
        self.qpos.append(d.qpos.copy())
        self.qvel.append(d.qvel.copy())
        self.u.append(d.ctrl[act].copy())


@pytest.fixture(scope="module")
def paper_parts():
    """The project's nominal episode (the paper's trot, filter off) for 1 s of walking, and one plant per world."""
    cfg = api.compose(["filter.enabled=false"])
    settings = dataclasses.replace(api.episode_settings(cfg), duration_s=1.0, analyse=False)
    worlds = [api.StaticWorld(Terrain((Plane(mu),)), perturbation=PlantPerturbation(trunk_mass_scale=m))
              for mu, m in WORLDS]
    return cfg, settings, worlds, [api.build_plant(w, api.PlantOptions()) for w in worlds]


@pytest.fixture(scope="module")
def loop_runs(paper_parts):
    cfg, settings, worlds, plants = paper_parts
    runs = []
    for world, plant, seed in zip(worlds, plants, SEEDS, strict=True):
        rec = _PlantRecorder()
        res = api.Episode(settings, world, plant, api.build_controller(cfg), None, FixedEstimator(1.0),
                          np.random.default_rng(seed), observers=[rec], trace=False).run()
        runs.append((res, rec))
    return runs


@pytest.mark.parametrize("nthread", [1, 2])
def test_batched_rollout_is_the_episode_loop_bit_for_bit(paper_parts, loop_runs, nthread: int) -> None:
    cfg, settings, worlds, plants = paper_parts
    envs = [api.BatchEnv(w, p, api.build_controller(cfg), np.random.default_rng(s))
            for w, p, s in zip(worlds, plants, SEEDS, strict=True)]
    batch = api.BatchRollout(settings, envs, nthread=nthread, record="states").run()
    assert batch.nthread == nthread and batch.trace is not None
    assert [r.fell for r, _ in loop_runs] == [True, False, False, False]
    for i, (res, rec) in enumerate(loop_runs):
        out, n = batch.outcomes[i], res.n_ticks
        assert (out.status, out.fell, out.n_ticks, out.fall_term) == (res.status, res.fell, n,
                                                                      res.extras.get("fall_term", ""))
        assert np.array_equal(out.time_to_fall_s, res.time_to_fall_s, equal_nan=True)
        assert np.array_equal(batch.trace.qpos[:n, i], np.array(rec.qpos))
        assert np.array_equal(batch.trace.qvel[:n, i], np.array(rec.qvel))
        assert np.array_equal(batch.trace.u[:n, i], np.array(rec.u))
    assert batch.outcomes[0].time_to_fall_s == pytest.approx(1.292) and batch.outcomes[0].fall_term == "body_contact"
    assert batch.physics_steps == sum(r.n_ticks for r, _ in loop_runs)


def test_one_controller_shared_by_every_environment_gives_the_same_bits(paper_parts, loop_runs) -> None:
    cfg, settings, worlds, plants = paper_parts
    shared = api.build_controller(cfg)
    envs = [api.BatchEnv(w, p, shared, np.random.default_rng(s)) for w, p, s in zip(worlds, plants, SEEDS, strict=True)]
    batch = api.BatchRollout(settings, envs, nthread=2, record="states").run()
    assert batch.trace is not None
    for i, (res, rec) in enumerate(loop_runs):
        assert np.array_equal(batch.trace.u[: res.n_ticks, i], np.array(rec.u))


@pytest.mark.parametrize("period_s", [0.4, 0.437])
def test_reference_timeline_is_the_references_of_every_tick(period_s: float) -> None:
    """The timeline indexes the per-period table after its first period; the values are those the controller
    gives tick by tick, bit for bit, for a fresh controller and for one that ran an episode before."""
    gait = GaitParams(period_s=period_s)
    stepped, timed = NominalController(gait, PDGains()), NominalController(gait, PDGains())
    ticks = 3000
    expected = []
    for k in range(ticks):
        stepped.update_references(k * 1e-3)
        expected.append(stepped._references.copy())
    for _ in range(2):
        rows, index = timed.reference_timeline(ticks, 1e-3)
        assert rows[index].tobytes() == np.array(expected).tobytes()
        assert len(rows) == round(period_s * 1000) + 2  # the stand, walking's first tick, one period
        timed = pickle.loads(pickle.dumps(timed))  # a copy (another process's) writes the same references


def _collection_draws() -> list[tuple]:
    """Four training draws, one with weak motors and a heavy trunk (falls within a second), one with a patch."""
    draws = [draw(np.random.default_rng(s), TRAIN_RANGES, seed=s) for s in (1, 2, 3, 4)]
    draws[1] = dataclasses.replace(draws[1], motor_strength_scale=0.4, trunk_mass_scale=1.5)
    return [(p, None) for p in draws[:3]] + [(draws[3], SurfacePatch(0.1, 0.2, 0.2))]


def test_batched_collection_episodes_are_the_loops() -> None:
    cfg = EpisodeConfig(duration_s=2.0, stride=2)
    jobs = _collection_draws()
    batched = run_batch(jobs[:3], cfg, nthread=2) + run_batch(jobs[3:], cfg, nthread=2)
    assert [r.fell for r in batched] == [False, True, False, False]
    for (p, patch), got in zip(jobs, batched, strict=True):
        want = run_episode(p, cfg, patch=patch)
        assert (got.fell, got.steps) == (want.fell, want.steps)
        assert np.array_equal(got.fall_time_s, want.fall_time_s, equal_nan=True)
        for name in ("windows", "y", "y_foot", "foot_loaded"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert len(batched[0].windows) > 0 and len({float(v) for v in batched[3].y}) == 2  # the patch's label changes


def test_collect_with_batch_writes_the_loops_arrays(tmp_path: Path) -> None:
    cfg = EpisodeConfig(duration_s=1.6, stride=4)
    counts = {"train": 3, "shifted": 2}
    kw = {"seed": 4, "cfg": cfg, "patch_fraction": 0.5, "filter_fraction": 0.3}
    loop = collect(tmp_path / "loop", counts, workers=1, **kw)
    batched = collect(tmp_path / "batch", counts, workers=2, batch=2, **kw)
    assert batched["batch"] == 2 and loop["splits"] == batched["splits"]
    for split in counts:
        a, b = np.load(tmp_path / "loop" / f"{split}.npz"), np.load(tmp_path / "batch" / f"{split}.npz")
        assert a.files == b.files
        for key in a.files:
            assert np.array_equal(a[key], b[key], equal_nan=a[key].dtype.kind == "f"), (split, key)


def test_what_a_batch_cannot_run_is_refused_by_name(paper_parts) -> None:
    cfg, settings, worlds, plants = paper_parts
    env = api.BatchEnv(worlds[0], plants[0], api.build_controller(cfg), np.random.default_rng(0))
    with pytest.raises(ValueError, match="envs is empty"):
        api.BatchRollout(settings, [])
    strips = api.StaticWorld(Terrain((FrictionStrips((1.0,), (0.5, 0.9)),)))
    other = dataclasses.replace(env, scenario=strips, mj_model=api.build_plant(strips, api.PlantOptions()))
    with pytest.raises(ValueError, match=r"envs\[1\]\.mj_model: its layout"):
        api.BatchRollout(settings, [env, other])
    follower = TerrainFollowingController(GaitParams(), PDGains(), terrain=Terrain())
    with pytest.raises(ValueError, match=r"envs\[0\]\.controller: .*open-loop trot.*TerrainFollowingController"):
        api.BatchRollout(settings, [dataclasses.replace(env, controller=follower)])
    with pytest.raises(ValueError, match="sample_every_ticks must be >= 0"):
        api.BatchRollout(settings, [env], sample_every_ticks=-1)
    with pytest.raises(ValueError, match="record must be one of none, torques, states, got 'qpos'"):
        api.BatchRollout(settings, [env], record="qpos")
    with pytest.raises(ValueError, match="batch must be >= 0"):
        collect(Path("/nonexistent"), {"train": 1}, batch=-1)


def test_a_diverging_environment_ends_in_error_as_in_the_loop_and_the_others_run_on(paper_parts, loop_runs) -> None:
    """Negative joint damping (kd < 0) makes the legs' motion grow until the episode's state guard ends it."""
    cfg, settings, worlds, plants = paper_parts

    def unstable() -> NominalController:
        return NominalController(GaitParams(), PDGains(kp=100.0, kd=-5.0))

    controllers = [api.build_controller(cfg), unstable(), api.build_controller(cfg), api.build_controller(cfg)]
    envs = [api.BatchEnv(w, p, c, np.random.default_rng(s))
            for w, p, c, s in zip(worlds, plants, controllers, SEEDS, strict=True)]
    batch = api.BatchRollout(settings, envs, nthread=2, record="states").run()
    rec = _PlantRecorder()
    res = api.Episode(settings, worlds[1], plants[1], unstable(), None, FixedEstimator(1.0),
                      np.random.default_rng(SEEDS[1]), observers=[rec], trace=False).run()
    got = batch.outcomes[1]
    assert (got.status, got.message, got.n_ticks) == (res.status, res.message, res.n_ticks)
    assert res.status == "error" and res.message.startswith("non-finite or exploding plant state") and res.n_ticks < 50
    assert batch.trace is not None
    assert np.array_equal(batch.trace.qpos[: res.n_ticks, 1], np.array(rec.qpos))
    n = loop_runs[2][0].n_ticks
    assert np.array_equal(batch.trace.qpos[:n, 2], np.array(loop_runs[2][1].qpos))  # the others run on untouched
