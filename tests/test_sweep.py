"""Recording, sweep aggregation, report, and a real `-m` sweep through Hydra (subprocess)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from mcap.reader import make_reader

from taslel_bench.record.mcap import EVENTS, PROTOBUF_CHANNELS, read_messages
from taslel_bench.record.signals import AFTER_EPISODE, CHANNELS
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from taslel_bench.sweep.aggregate import aggregate
from taslel_bench.sweep.report import write_report
from taslel_bench.util.stats import shifted_geometric_mean
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent


def mcap_counts(path: Path) -> dict[str, int]:
    counts: dict[str, int] = {}
    with open(path, "rb") as f:  # the mcap reader (indexed, summary section) agrees with the streamed read
        indexed = [channel.topic for _, channel, _ in make_reader(f).iter_messages()]
    for topic, _, message in read_messages(path):  # JSON and protobuf channels decoded
        assert isinstance(message, dict)
        counts[topic] = counts.get(topic, 0) + 1
    assert sorted(indexed) == sorted(t for t, n in counts.items() for _ in range(n))
    return counts


def test_mcap_reads_back_with_every_channel(tmp_path):
    run(compose_cfg(["duration=0.3", "progress=false", "scenario=obstacle"]), tmp_path, {"solver": "daqp"})
    counts = mcap_counts(tmp_path / "episode.mcap")
    assert set(counts) == set(CHANNELS) | set(AFTER_EPISODE) | set(EVENTS) | set(PROTOBUF_CHANNELS)
    assert all(n > 0 for n in counts.values())
    assert counts["/torques"] == counts["/tf"] == 80  # every 10th control tick (record.mcap_rate_hz=100) of 0.8 s


def test_run_that_raises_leaves_readable_mcap_and_error_summary(tmp_path, monkeypatch):
    cfg = compose_cfg(["duration=1", "progress=false", "filter.enabled=false"])
    original = Built.__init__

    def sabotaged(self, cfg, *args, **kwargs):
        original(self, cfg, *args, **kwargs)

        def explode(model, data, t):
            if t > 0.4:
                raise RuntimeError("mid-episode fault")

        self.scenario.on_tick = explode

    monkeypatch.setattr(Built, "__init__", sabotaged)
    summary = run(cfg, tmp_path)
    assert summary["status"] == "error" and "mid-episode fault" in summary["message"]
    assert (tmp_path / "traceback.txt").is_file()
    counts = mcap_counts(tmp_path / "episode.mcap")
    assert counts["/events"] >= 2 and counts["/base_state"] > 30  # 100 Hz up to the fault at t > 0.4 s


def test_aggregate_includes_crashed_job_and_report_renders(tmp_path):
    for seed in (0, 1):
        run(compose_cfg(["duration=0.3", "progress=false", f"seed={seed}"]), tmp_path / f"seed={seed}",
            {"scenario": "flat", "solver": "daqp", "estimator": "oracle"})
    crashed = tmp_path / "seed=2" / ".hydra"
    crashed.mkdir(parents=True)
    (crashed / "config.yaml").write_text("seed: 2\n")
    (crashed / "overrides.yaml").write_text("- seed=2\n")
    frame = aggregate(tmp_path)
    assert len(frame) == 3 and (frame["status"] == "error").sum() == 1
    assert pd.read_parquet(tmp_path / "summary.parquet").shape[0] == 3
    report = write_report(tmp_path, frame).read_text()
    assert "| flat | daqp | oracle | 2 | 0 | 0 | 0/2 |" in report  # runs, errors, degraded, falls
    # the first table: unsafe runs per group and why (the crashed job is not judged)
    assert report.index("## Unsafe runs per group (the verdict)") < report.index("## Safety and physics per group")
    # runs, unsafe, status_ok, not_judged, fell, tripped
    assert "| flat | daqp | oracle | 2 | 0/2 | 2 | 0 | 0 | 0 |" in report
    assert "left no summary.json" in report
    assert (tmp_path / "qp_solve_times.png").stat().st_size > 1000


def test_shifted_geometric_mean():
    assert shifted_geometric_mean([10.0, 10.0]) == pytest.approx(10.0)
    # one huge outlier moves it far less than it moves the arithmetic mean
    v = [20.0] * 99 + [1e6]
    assert shifted_geometric_mean(v) < 0.01 * (sum(v) / len(v))


@pytest.mark.slow
def test_real_multirun_two_solvers(tmp_path):
    """`python -m taslel_bench -m solver=osqp,clarabel` end to end (short episodes), then a resume."""
    env = {**os.environ, "HYDRA_FULL_ERROR": "1"}
    cmd = [sys.executable, "-m", "taslel_bench", "-m", "solver=osqp,clarabel", "duration=0.5", "progress=false",
           f"hydra.sweep.dir={tmp_path}"]
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    table = pd.read_parquet(tmp_path / "summary.parquet")
    assert sorted(table["solver"]) == ["clarabel", "osqp"] and (table["status"] == "ok").all()
    assert (tmp_path / "report.md").is_file()
    mcaps = sorted(tmp_path.glob("*/episode.mcap"))
    assert len(mcaps) == 2 and all(min(mcap_counts(p).values()) > 0 for p in mcaps)
    # same sweep again: both runs are complete, so they are skipped
    again = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert again.returncode == 0 and again.stdout.count("already complete, skipped") == 2


@pytest.mark.slow
def test_multirun_with_a_failing_job_records_it_and_finishes_the_others(tmp_path):
    """One job refuses its config (kp < 0) inside a sweep: an error row, the other job completes."""
    cmd = [sys.executable, "-m", "taslel_bench", "-m", "controller.kp=100,-1", "duration=0.3", "progress=false",
           "record.mcap=false", f"hydra.sweep.dir={tmp_path}"]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    assert out.returncode == 1, out.stderr[-3000:]  # a sweep with an error row exits 1 (the table is still written)
    table = pd.read_parquet(tmp_path / "summary.parquet")
    assert len(table) == 2
    assert sorted(table["status"]) == ["error", "ok"]
    assert "controller.kp" in table.loc[table["status"] == "error", "message"].iloc[0]
    assert "sweep progress: job #1 (controller.kp=-1,duration=0.3) ended error" in out.stdout
    assert "sweep progress: job #0 (controller.kp=100,duration=0.3) ended ok" in out.stdout


def test_swept_contact_gain_is_a_report_column_and_a_typed_crash_row(tmp_path):
    """A sweep over filter.contact_velocity_gain: the gain becomes a float column and a row key of the
    report (also for a crashed job, read from its overrides), and the paper table has one section per gain."""
    for gain in (0.0, 50.0):
        run(compose_cfg(["duration=0.3", "progress=false", f"filter.contact_velocity_gain={gain}"]),
            tmp_path / f"gain={gain}", {"scenario": "flat", "solver": "daqp", "estimator": "oracle"})
    crashed = tmp_path / "gain=100" / ".hydra"
    crashed.mkdir(parents=True)
    (crashed / "config.yaml").write_text("seed: 0\n")
    (crashed / "overrides.yaml").write_text("- filter.contact_velocity_gain=100\n- scenario=flat\n")
    frame = aggregate(tmp_path)
    assert sorted(frame["filter_contact_velocity_gain"]) == [0.0, 50.0, 100.0]
    report = write_report(tmp_path, frame).read_text()
    assert "| scenario | solver | filter_contact_velocity_gain | estimator |" in report
    assert "| flat | daqp | 50 | oracle | 1 | 0 |" in report
    # the paper table is split by the gain (never pooled), one section per value
    assert "Filter-on runs split by `filter_contact_velocity_gain`" in report
    assert "### Filter setting `filter_contact_velocity_gain=0.0`" in report
    assert "### Filter setting `filter_contact_velocity_gain=50.0`" in report


def test_report_rows_split_by_every_swept_override_and_list_degraded_runs(tmp_path, monkeypatch):
    """`scenario.friction=0.3,1.0` are two rows (not one "flat" row); a degraded run is listed with why."""
    import taslel_bench.sim.build as run_module
    from tests.conftest import NeverSolves

    for mu in ("0.3", "1.0"):
        over = ["duration=0.2", "progress=false", "record.mcap=false", f"scenario.friction={mu}"]
        run(compose_cfg(over), tmp_path / f"mu={mu}", {"scenario": "flat", "solver": "daqp"},
            overrides=[f"scenario.friction={mu}", "duration=0.2"])
    monkeypatch.setattr(run_module, "build_backend", lambda cfg: NeverSolves())  # every tick fails
    bad = ["duration=0.2", "progress=false", "record.mcap=false", "solver=osqp", "solver.settings.max_iter=1"]
    run(compose_cfg(bad), tmp_path / "bad", {"scenario": "flat", "solver": "osqp"},
        overrides=["solver=osqp", "solver.settings.max_iter=1", "duration=0.2"])
    frame = aggregate(tmp_path)
    assert sorted(frame["scenario.friction"]) == ["", "0.3", "1.0"]
    report = write_report(tmp_path, frame).read_text()
    header = "| scenario | solver | estimator | scenario.friction | solver.settings.max_iter | runs |"
    assert header in report
    assert "| flat | daqp | oracle |  | 0.3 |" not in report  # the override is its own column
    assert "| flat | daqp | oracle | 0.3 |  | 1 | 0 | 0 |" in report
    assert "| flat | daqp | oracle | 1.0 |  | 1 | 0 | 0 |" in report
    assert "| flat | osqp | oracle |  | 1 | 1 | 0 | 1 |" in report
    assert "## Runs that ended degraded" in report and "qp_failed_rate=1 > 0.05" in report


def test_a_swept_none_level_splits_the_report_rows_and_the_fall_figure(tmp_path):
    """``+mismatch_plant=none,lossy``: "none" (the URDF plant) is a level the sweep chose, so the summary table
    and the fall-rate bars keep the two plants apart (they were pooled as one group of 2 x the seeds); a summary
    column's "none" (filter off) still is no value of its own."""
    from taslel_bench.sweep.aggregate import OVERRIDE_SEPARATOR, expand_overrides
    from taslel_bench.sweep.report import group_columns, summary_table

    rows = []
    for plant, seed in ((p, s) for p in ("none", "lossy") for s in (0, 1)):
        rows.append({"scenario": "logs", "solver": "daqp", "estimator": "oracle", "status": "ok", "seed": seed,
                     "fell": plant == "lossy" and seed == 0, "filter_contact_velocity_gain": "none" if seed else 0.0,
                     "overrides": OVERRIDE_SEPARATOR.join([f"+mismatch_plant={plant}", f"seed={seed}"]),
                     "run_dir": f"p={plant},s={seed}"})  # fmt: skip
    frame = expand_overrides(pd.DataFrame(rows))
    assert group_columns(frame) == ["scenario", "solver", "estimator", "mismatch_plant"]
    table = summary_table(tmp_path, frame)
    assert sorted(zip(table["mismatch_plant"], table["runs"], table["fall_rate"], strict=True)) == [("lossy", 2, "1/2"),
                                                                                       ("none", 2, "0/2")]
    assert "figures skipped" not in write_report(tmp_path, frame).read_text()
    assert (tmp_path / "fall_rates.png").is_file()
    frame["filter_contact_velocity_gain"] = [0.0, 100.0, float("nan"), 100.0]  # swept, and NaN: runs without it
    assert "filter_contact_velocity_gain" in group_columns(frame)
    assert "figures skipped" not in write_report(tmp_path, frame).read_text()
