"""QP test sets (record -> load -> merge) and the replay benchmark (correctness verdicts, unavailable backends,
determinism). Test set: tests/data/qps_runs.npz, 120 QPs (every 20th tick) of three 0.3 s runs (flat,
low_friction, obstacle) with references; regenerate with record.qps=true runs + ``python -m taslel_bench.qpset
merge <folders> --reference -o tests/data/qps_runs.npz``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import qpsolvers

from taslel_bench.interfaces import QPSolution
from taslel_bench.qp import replay, replay_report
from taslel_bench.qp.replay_report import compare, summarize, write_report
from taslel_bench.record import qpset
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
RUNS_SET = ROOT / "tests" / "data" / "qps_runs.npz"
TOL = replay.Tolerances()
HIGH = {"high_accuracy": {}}


@pytest.fixture(scope="module")
def runs_set() -> qpset.QPSet:
    return qpset.load(RUNS_SET)


def test_record_in_a_run_and_load_round_trip(tmp_path):
    cfg = compose_cfg(["scenario=obstacle", "duration=0.1", "progress=false", "record.mcap=false",
                       "record.qps=true", "record.qps_every=50", "filter.formulation=full"])  # fmt: skip
    summary = run(cfg, tmp_path, {"scenario": "obstacle", "solver": "daqp"})
    qs = qpset.load(tmp_path / qpset.FILENAME)
    n_ticks = 600  # 0.5 s stand + 0.1 s at 1 kHz
    assert summary["qps_recorded"] == len(qs) == n_ticks // 50
    assert list(qs.tick) == list(range(0, n_ticks, 50))
    np.testing.assert_allclose(qs.t_s, qs.tick * 1e-3)
    assert qs.runs[0]["scenario"] == "obstacle" and qs.runs[0]["solver"] == "daqp"
    assert np.all(qs.build_time_s > 0) and np.all(qs.solve_time_s > 0) and set(qs.status) == {"solved"}
    for i in range(len(qs)):  # the stored solution used solves the stored QP
        p, x = qs.problem(i), qs.x_used_of(i)
        assert p.G.shape == (24, 42)  # obstacle: ECBF rows present
        assert np.abs(p.A @ x - p.b).max() < 1e-6 and (p.G @ x - p.h).max() < 1e-6
        rows, _bounds = qpset.active_sets(p, x)
        assert np.array_equal(rows, qs.groups[0].active_rows[i])


def test_recorder_save_load_is_exact(tmp_path, runs_set):
    rec = qpset.QPRecorder({"scenario": "s"})
    originals = [runs_set.problem(i, copy=True) for i in (0, 50, 100)]  # two layouts
    for k, p in enumerate(originals):
        rec.add(p, runs_set.x_ref_of([0, 50, 100][k]), tick=k, t_s=k * 1e-3, build_time_s=1e-5)
    qpset.save(tmp_path / "s.npz", rec.to_set({"note": "x"}))
    back = qpset.load(tmp_path / "s.npz")
    assert len(back) == 3 and len(back.groups) == 2 and back.meta["note"] == "x"
    for i, p in enumerate(originals):
        q = back.problem(i)
        for k in ("P", "q", "A", "b", "G", "h", "lb", "ub", "A_pattern", "G_pattern"):
            assert np.array_equal(getattr(p, k), getattr(q, k)), k
        assert q.row_labels == p.row_labels and q.layout == p.layout


def test_merge_keeps_runs_and_layouts(runs_set):
    m = qpset.merge([runs_set, runs_set])
    assert len(m) == 2 * len(runs_set) and len(m.groups) == 2 and len(m.runs) == 6
    assert sorted(set(m.scenario())) == ["flat", "low_friction", "obstacle"]
    for i in (0, len(runs_set) + 7):
        j = i % len(runs_set)
        assert np.array_equal(m.problem(i).G, runs_set.problem(j).G)
        assert np.array_equal(m.x_ref_of(i), runs_set.x_ref_of(j))
    assert sum(len(s) for s in m.sequences()) == len(m)


class WrongU:
    """Says "solved" but returns the exact answer with u shifted by 0.01 N·m (and no duals)."""

    name = "wrong_u"

    def __init__(self) -> None:
        self.inner = replay.make_backend(replay.solver_conf("daqp"))

    def reset(self) -> None:
        self.inner.reset()

    def describe(self) -> dict:
        return {"name": self.name}

    def solve(self, problem):
        sol = self.inner.solve(problem)
        x = sol.x.copy()
        x[problem.layout["u"]] += 0.01
        return QPSolution(x, "solved", sol.solve_time_s)


def test_wrong_answer_counted_as_incorrect(runs_set):
    seqs = replay.select(runs_set, max_qps=5)
    labels = {"solver": "wrong_u", "profile": "x", "mode": "cold", "backend": "wrong_u"}
    frame = replay.replay_backend(runs_set, WrongU, "cold", seqs, 1, TOL, labels)
    assert len(frame) == 15
    assert frame["success"].all() and not frame["correct"].any()
    np.testing.assert_allclose(frame["du_nm"], 0.01, rtol=1e-6)
    s = summarize(frame)
    assert s.loc[0, "success_pct"] == 100.0 and s.loc[0, "correct_pct"] == 0.0 and s.loc[0, "wrong_but_solved"] == 15


def test_judge_checks_residuals_and_duals(runs_set):
    p, x_ref = runs_set.problem(60), runs_set.x_ref_of(60)
    good = QPSolution(x_ref.copy(), "solved", 1e-5)
    assert replay.judge(p, good, x_ref, TOL)["correct"]
    infeasible = x_ref.copy()
    infeasible[0] += 1e-3  # vdot off: equations of motion violated, u untouched
    v = replay.judge(p, QPSolution(infeasible, "solved", 1e-5), x_ref, TOL)
    assert v["success"] and not v["correct"] and v["du_nm"] == 0.0 and v["primal"] > 1e-4
    bad_duals = QPSolution(x_ref.copy(), "solved", 1e-5)
    bad_duals.y, bad_duals.z, bad_duals.z_box = np.zeros(30), np.zeros(p.G.shape[0]), np.zeros(42)
    v = replay.judge(p, bad_duals, x_ref, TOL)  # zero multipliers: stationarity fails
    assert v["dual"] > TOL.dual and not v["correct"]
    assert not replay.judge(p, QPSolution(None, "max_iter", 1e-5), x_ref, TOL)["success"]


def test_uninstalled_backend_is_unavailable_not_a_failure(runs_set):
    with pytest.raises(replay.Unavailable, match="not installed"):
        replay.make_backend({"_target_": "solvers.qpsolvers_backend.QpsolversBackend", "solver": "gurobi_x"})
    with pytest.raises(replay.Unavailable, match="ModuleNotFoundError|ImportError"):
        replay.make_backend({"_target_": "no_such_package.Backend"})
    frame = replay.replay(runs_set, ["no_such_solver", "daqp"], ["cold", "persistent", "warm"], HIGH, 1, TOL,
                          max_qps=4)  # fmt: skip
    s = summarize(frame).set_index(["solver", "mode"])
    assert s.loc[("no_such_solver", "cold"), "status"].startswith("unavailable: no conf/solver/no_such_solver")
    for mode in ("cold", "persistent", "warm"):
        assert s.loc[("daqp", mode), "status"] == "ran"
        assert s.loc[("daqp", mode), "correct_pct"] == 100.0


def test_report_tables_of_a_rate_not_measured(runs_set):
    """deadlines_hz without 500: the report's 500 Hz table has '-' cells (it raised a TypeError)."""
    s = summarize(replay.replay(runs_set, ["daqp"], ["cold"], HIGH, 1, TOL, max_qps=4), (1000.0,))
    assert "miss_500hz_minpass_pct" not in s
    assert (replay_report._pivot(s, "miss_500hz_pct", "{:.2f}", "miss_500hz_minpass_pct") == "-").all().all()
    assert any("at 500 Hz" in line for line in replay_report._rate_lines(s))


def test_replaying_twice_gives_the_same_tables(runs_set, tmp_path):
    tables = []
    for k in range(2):
        frame = replay.replay(runs_set, ["osqp", "proxqp"], ["cold", "persistent"],
                              {"default": {"all": {"settings": {}, "check": {"level": "none"}},
                                           "osqp": {"settings": {"eps_abs": 1e-3, "eps_rel": 1e-3},
                                                               "settings_with_equalities": {}},
                                           "proxqp": {"settings": {"eps_abs": 1e-5,
                                                                              "check_duality_gap": False}}},
                               **HIGH}, 2, TOL, max_qps=15)  # fmt: skip
        s = summarize(frame)
        assert s["passes_agree"].all()
        tables.append(s[["solver", "profile", "mode", "success_pct", "correct_pct", "wrong_but_solved"]])
        out = tmp_path / f"r{k}"
        out.mkdir()
        frame.to_parquet(out / replay.QP_TABLE)
    pd.testing.assert_frame_equal(tables[0], tables[1])
    t = tables[0].set_index(["solver", "profile", "mode"])
    assert t.loc[("osqp", "high_accuracy", "persistent"), "correct_pct"] == 100.0
    assert t.loc[("osqp", "default", "persistent"), "wrong_but_solved"] > 0  # default OSQP: "solved", u off
    report = write_report(tmp_path / "r0")
    write_report(tmp_path / "r1")
    same, _ = compare(tmp_path / "r0" / "results.csv", tmp_path / "r1" / "results.csv")
    assert same
    text = report.read_text()
    assert "Correctness rate" in text and "Deadline-miss rate" in text and "osqp" in text
    assert (tmp_path / "r0" / "results.csv").is_file() and (tmp_path / "r0" / "overhead.csv").is_file()


@pytest.mark.slow
def test_cli_multirun_over_solvers(tmp_path):
    cmd = [sys.executable, "-m", "taslel_bench.replay", str(RUNS_SET), "-m", "solver=daqp,piqp",
           "repeats=1", "max_qps=5", "profiles=[high_accuracy]", f"hydra.sweep.dir={tmp_path}"]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(cmd, check=False, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    text = (tmp_path / "report.md").read_text()
    assert "| daqp |" in text and "| piqp |" in text
    assert "piqp / high_accuracy / warm: unavailable: the solver ignores initial guesses" in text


def test_record_condensed_formulation_stores_what_the_backend_solved(tmp_path):
    """filter.formulation=condensed: the recorded QP is the 12-variable one the backend got, with its u."""
    cfg = compose_cfg(["scenario=obstacle", "duration=0.1", "progress=false", "record.mcap=false",
                       "record.qps=true", "record.qps_every=100", "filter.formulation=condensed"])  # fmt: skip
    run(cfg, tmp_path, {"scenario": "obstacle", "solver": "daqp"})
    qs = qpset.load(tmp_path / qpset.FILENAME)
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    u_cols = [c for c in steps.columns if c.startswith("u_") and not c.startswith("u_nom")]
    assert len(qs) == 6 and len(qs.groups) == 1  # P changes every tick but is stored per QP, not per layout
    Ps = []
    for i in range(len(qs)):
        p, x = qs.problem(i), qs.x_used_of(i)
        assert p.n == 12 and p.A.shape == (0, 12) and p.G.shape == (24, 12)
        assert (p.G @ x - p.h).max() < 1e-6
        np.testing.assert_allclose(x, steps.loc[int(qs.tick[i]), u_cols].to_numpy(float), atol=1e-9)
        # the stored QP (with its own P) has the recorded u as its minimiser
        x_qp = qpsolvers.solve_qp(p.P, p.q, p.G, p.h, lb=p.lb, ub=p.ub, solver="quadprog")
        np.testing.assert_allclose(x_qp, x, atol=1e-6)
        Ps.append(p.P.copy())
    assert not np.allclose(Ps[1], Ps[-1])
