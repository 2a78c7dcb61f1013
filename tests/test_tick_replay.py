"""taslel_bench.qp.tick_replay: the replay of the loop's ticks redoes the loop's work (same QP answers, same
plant states), says so when it does not, and covers the nominal-only loop's parts."""

import numpy as np
import pytest

from taslel_bench.api import compose
from taslel_bench.qp.tick_replay import PARTS, record_ticks, replay
from taslel_bench.sim.build import Built

N = 30


def _recorded(*overrides):
    built = Built(compose(["duration=1.0", "progress=false", "record.reference_every=0", *overrides]))
    return built, record_ticks(built, N)


@pytest.fixture(scope="module")
def filtered():
    return _recorded("scenario=obstacle")


def test_replay_redoes_the_loops_ticks(filtered):
    built, rec = filtered
    alone, back, worst = replay(built, rec)  # raises if an answer or a state differs from the loop's
    assert worst["qpos"] == 0.0 and worst["u_nm"] < 1e-12  # DAQP: the loop's answers to rounding
    assert list(alone) == list(back) == list(PARTS)
    assert all(x.shape == (N,) and np.all(x > 0) for x in (*alone.values(), *back.values()))
    assert len(rec.solutions) == N and all(x is not None for x in rec.solutions)


def test_replay_fails_on_a_changed_answer_or_state(filtered):
    built, rec = filtered
    kept = rec.solutions[7]
    rec.solutions[7] = kept + 1e-6
    try:
        with pytest.raises(RuntimeError, match="does not redo the loop's work: max \\|u - u_loop\\| 1e-06"):
            replay(built, rec, answer_tol_nm=1e-9)
        assert replay(built, rec)[2]["u_nm"] == pytest.approx(1e-6)  # within the run's 1e-3 N·m
    finally:
        rec.solutions[7] = kept
    qpos = rec.rows["mj_step"][5][0]
    qpos[2] += 1e-6  # the trunk height before tick 5's step: tick 4's replayed step no longer ends there
    try:
        with pytest.raises(RuntimeError, match="max \\|qpos - qpos_loop\\| 1e-06"):
            replay(built, rec)
    finally:
        qpos[2] -= 1e-6


def test_an_iterative_solver_replays_within_the_wrong_answer_tolerance():
    built, rec = _recorded("scenario=obstacle", "solver=osqp")
    worst = replay(built, rec)[2]  # the first replayed solve starts cold: the answers move within tolerance
    assert worst["qpos"] == 0.0 and worst["u_nm"] < 1e-3


def test_nominal_only_replays_its_three_parts():
    built, rec = _recorded("filter.enabled=false")
    alone, back, worst = replay(built, rec)
    assert list(alone) == list(back) == ["controller", "mj_step", "contact_check"]
    assert worst == {"u_nm": 0.0, "qpos": 0.0}


def test_a_run_shorter_than_the_record_is_an_error():
    built = Built(compose(["duration=0.05", "progress=false", "filter.enabled=false"]))
    with pytest.raises(RuntimeError, match="recorded 0 of 30 walking ticks"):
        record_ticks(built, N)


def test_bench_back_to_back_sums_the_parts_and_restores_the_episode():
    import mujoco

    from taslel_bench.qp.tick_bench import _back_to_back_text, back_to_back

    step = mujoco.mj_step
    built = Built(compose(["duration=0.3", "progress=false", "record.mcap=false"]))
    built.episode.run()
    out = back_to_back(built, wall_per_tick_us=500.0)
    assert out["ticks"] == 199  # 0.3 s walk = 300 ticks, less the 100 after the stand and one
    assert out["alone"] > 0 and out["back to back"] > 0
    assert out["share back to back"] == pytest.approx(out["alone"] / out["back to back"])
    assert out["share loop"] == pytest.approx(out["alone"] / 500.0)
    assert "compute" not in vars(built.episode.controller) and "filter" not in vars(built.filter)
    assert mujoco.mj_step is step  # the episode's physics is MuJoCo's again
    steady = {"ticks": 199, "alone": 70.0, "back to back": 80.0, "share back to back": 0.875, "wall": 120.0,
              "share loop": 0.58, "u error": 1e-15}  # fmt: skip
    row = ("filter + daqp", *([None] * 9), steady)
    text = _back_to_back_text([row, ("short", *([None] * 9), {})])
    assert "| filter + daqp | 70.0 | 80.0 | 0.88 | 120.0 | 0.58 | 1e-15 |  |" in text and "short" not in text
    assert back_to_back(Built(compose(["duration=0.05", "progress=false"])), 500.0) == {}
    fast_loop = {**steady, "share loop": 1.5}  # the parts alone timed slower than the whole loop: a disturbed run
    assert "share loop > 1.05: the machine's speed changed" in _back_to_back_text([("x", *([None] * 9), fast_loop)])
    assert "speed changed" not in _back_to_back_text([row])
    failed = {"ticks": 0, "error": "not replayed: the episode recorded 12 of 30 walking ticks"}
    assert "| fell | - | - | - | - | - | - | not replayed: the episode recorded 12" in _back_to_back_text(
        [("fell", *([None] * 9), failed)])


def test_bench_back_to_back_reports_a_failed_replay(monkeypatch):
    from taslel_bench.qp import tick_bench

    def ended_early(built, n):
        raise RuntimeError("the episode recorded 12 of 199 walking ticks")

    monkeypatch.setattr(tick_bench, "record_ticks", ended_early)
    built = Built(compose(["duration=0.3", "progress=false", "filter.enabled=false"]))
    assert tick_bench.back_to_back(built, 500.0) == {"ticks": 0, "error": "not replayed: the episode recorded 12 of "
                                                                          "199 walking ticks"}


def test_an_answer_missing_on_one_side_is_a_difference():
    from taslel_bench.qp.tick_replay import _u_difference

    x = np.arange(4.0)
    assert _u_difference(None, None, slice(0, 2)) == 0.0
    assert _u_difference(x, None, slice(0, 2)) == np.inf and _u_difference(None, x, slice(0, 2)) == np.inf
    assert _u_difference(x + 1e-3, x, slice(0, 2)) == pytest.approx(1e-3)
