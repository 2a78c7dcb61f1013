"""Timing that says when it cannot be trusted: every run records its share of a CPU and the machine's load,
each solve is timed by the wall clock and by the thread's CPU time, the solver verdict judges deadlines on
the undisturbed measurement and says the machine was busy, and the bench tool refuses to write a report
from a disturbed run unless told to. Each test failed on the main of before (nothing of it existed)."""

from __future__ import annotations

import threading

import numpy as np
import pandas as pd
import pytest

from taslel_bench.sim.run import run
from taslel_bench.sweep.solver_verdict import solver_verdict
from tests.conftest import compose_cfg


def test_cpu_watch_sees_a_thread_that_waited_for_the_cpu():
    """A second thread spinning in this process takes the GIL half the time: the measured thread ran about
    half of the wall time, and the watch says the timing is disturbed."""
    from taslel_bench.util.machine import CpuWatch

    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            pass

    hog = threading.Thread(target=spin)
    hog.start()
    try:
        with CpuWatch() as watch:
            total = 0
            for i in range(3_000_000):
                total += i
    finally:
        stop.set()
        hog.join()
    share = watch.result
    assert share.thread_share < 0.8 and share.busy_reason.startswith(f"CPU share {share.thread_share:.2f}")
    assert share.record()["machine_busy"] is True


def test_a_run_records_its_cpu_share_and_each_solves_thread_cpu_time(tmp_path):
    summary = run(compose_cfg(["duration=0.3", "progress=false", "record.mcap=false", "solver=osqp"]), tmp_path / "r")
    for key in ("machine_cpu_share", "machine_process_cpu_share", "machine_load_1min_start", "machine_load_1min_end",
                "machine_steal_share", "machine_involuntary_switches_per_s", "machine_busy", "machine_busy_reason"):
        assert key in summary
    assert 0 < summary["machine_cpu_share"] <= 1.05
    steps = pd.read_parquet(tmp_path / "r" / "steps.parquet",
                            columns=["qp_status", "qp_solve_us", "qp_solve_cpu_us", "qp_setup"])  # fmt: skip
    solved = steps[steps["qp_status"] >= 0]
    assert len(solved) > 100 and np.isfinite(solved["qp_solve_cpu_us"]).all() and (solved["qp_solve_cpu_us"] > 0).all()
    # the thread's CPU time covers the backend call, its wall timer the solve inside it: the CPU time stays within
    # the wall time + 5 µs but for rare solves (cause not identified; work between the two clocks' readings is one
    # candidate): measured on a quiet machine, 1 of 9,600 solves (12 runs) was 64 µs above
    above = solved["qp_solve_cpu_us"] > solved["qp_solve_us"] + 5.0
    assert above.mean() <= 0.01, solved[above]
    assert solved["qp_setup"].iloc[0] and 1 <= solved["qp_setup"].sum() <= 3  # the persistent solver's builds


def _sweep(folder, busy: bool, share: float):
    """Two backends on one world; on the busy machine 3 % of the solves waited 8-9 ms for a CPU (wall clock),
    their thread CPU time stayed 90 / 330 µs."""
    rows = []
    for solver, cpu_us, waited_us in (("osqp", 90.0, 8000.0), ("clarabel", 330.0, 9000.0)):
        (folder / solver).mkdir(parents=True)
        n = 1000
        wall, cpu = np.full(n, cpu_us * 1.05), np.full(n, cpu_us)
        cpu[0] = wall[0] = 820.0 if not busy else 1320.0  # the solver's build: slower on a busy machine
        if busy:
            wall[1::33] = waited_us
        pd.DataFrame({"qp_solve_us": wall, "qp_solve_cpu_us": cpu, "qp_iterations": np.full(n, 10),
                      "qp_setup": np.arange(n) == 0,
                      "qp_u_error_nm": np.where(np.arange(n) % 10 == 0, 1e-6, np.nan),
                      "qp_status": np.zeros(n, int)}).to_parquet(folder / solver / "steps.parquet")  # fmt: skip
        rows.append({"scenario": "flat", "solver": solver, "status": "ok", "run_dir": solver, "control_rate_hz": 1000.0,
                     "qp_reference_tol_nm": 1e-3, "real_time_factor": 1.0, "machine_busy": busy,
                     "machine_cpu_share": share})  # fmt: skip
    return pd.DataFrame(rows)


def test_verdict_on_a_busy_machine_is_the_quiet_ones_and_says_it_was_busy(tmp_path):
    quiet, _ = solver_verdict(tmp_path / "q", _sweep(tmp_path / "q", False, 0.97), ["scenario", "solver"])
    busy, rows = solver_verdict(tmp_path / "b", _sweep(tmp_path / "b", True, 0.41), ["scenario", "solver"])
    sentence = next(line for line in busy.splitlines() if line.startswith("**flat**"))
    assert "machine busy: CPU share 0.41 -- deadline figures from thread CPU time" in sentence
    assert "ship **osqp**" in sentence and "ship **osqp**" in quiet and "machine busy" not in quiet
    assert "its 1 first build(s) of a QP layout judged apart: up to 1320 µs" in sentence
    assert set(rows["timing"]) == {"thread CPU"}


def test_bench_refuses_to_write_a_report_from_a_disturbed_run(tmp_path, monkeypatch):
    from taslel_bench.qp import tick_bench
    from taslel_bench.util.machine import CpuShare, CpuWatch

    class Busy(CpuWatch):
        def __exit__(self, *exc: object) -> None:
            self.result = CpuShare(1.0, 0.41, 0.45, 3.0, 3.5, 0.0, 900.0)

    monkeypatch.setattr(tick_bench, "CpuWatch", Busy)
    monkeypatch.setattr(tick_bench, "part_costs", lambda built, trace=None: {})
    out = tmp_path / "tick.md"
    argv = ["--duration", "0.1", "--solvers", "daqp", "--formulations", "condensed", "--out", str(out)]
    monkeypatch.setattr(tick_bench, "_print_table", lambda rows, args: None)
    with pytest.raises(SystemExit, match="machine busy during the measurement .*CPU share 0.41"):
        tick_bench.main(argv)
    assert not out.exists()


def test_only_the_first_build_of_a_layout_is_flagged_a_setup():
    """A backend that keeps one solver and switches between two layouts rebuilds at every switch: only the
    first build of each layout is judged apart, the rebuilds are the loop's cost."""
    from types import SimpleNamespace

    from taslel_bench.sim.solve_clock import ThreadTimedBackend

    class Switching:
        setups, layout = 0, None

        def solve(self, problem):
            if problem != self.layout:
                self.setups, self.layout = self.setups + 1, problem
            return SimpleNamespace(solve_cpu_time_s=float("nan"))

    timed = ThreadTimedBackend(Switching())
    flags = [timed.solve(layout).setup for layout in ("stand", "stand", "walk", "stand", "walk", "walk")]
    assert flags == [True, False, True, False, False, False]
