"""A run stopped by Ctrl-C (SIGINT) or SIGTERM ends with one line, a summary marked ``interrupted`` with the
time reached, its files closed and readable, exit 130/143; a rerun names what it left; a refused value
leaves no folder. Each test failed on the main of before (a traceback, an empty partial MCAP, exit 1)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent
LONG = ["duration=30", "progress=false", "record.mcap=true", "record.chunk_ticks=500"]


def start(run_dir: Path, *extra: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "taslel_bench", *LONG, *extra, f"hydra.run.dir={run_dir}"]
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def interrupt_when_running(proc: subprocess.Popen, run_dir: Path, signum: int) -> tuple[str, str]:
    """Send ``signum`` once the episode has streamed its first chunk; (stdout, stderr) at exit."""
    deadline = time.monotonic() + 240
    while not list(run_dir.glob(".steps.parquet.tmp-*")) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    proc.send_signal(signum)
    return proc.communicate(timeout=240)


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_ends_the_run_with_one_line_and_readable_files(tmp_path, signum, code):
    run_dir = tmp_path / "run"
    proc = start(run_dir)
    _, err = interrupt_when_running(proc, run_dir, signum)
    assert proc.returncode == code, err[-3000:]
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and f"interrupted by {signal.Signals(signum).name} at t = " in lines[0], err[-3000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "interrupted" and 0 < summary["interrupted_at_s"] < 30
    steps = pd.read_parquet(run_dir / "steps.parquet")  # closed, readable: the ticks simulated
    assert len(steps) > 0 and steps["t_s"].max() <= summary["interrupted_at_s"]
    assert (run_dir / "episode.mcap").stat().st_size > 1000 and not (run_dir / "episode.partial.mcap").exists()
    json.loads((run_dir / "events.json").read_text())
    assert not list(run_dir.glob(".*.tmp-*")) and not (run_dir / "run.lock").exists()


def test_a_rerun_names_what_an_interrupted_run_left_and_never_reuses_it(tmp_path):
    first = tmp_path / "runs" / "2026-01-01_00-00-00_flat_daqp_s0"
    proc = start(first)
    interrupt_when_running(proc, first, signal.SIGINT)
    assert proc.returncode == 130
    # the same command again, into a new timestamped folder beside it: it names the interrupted one
    later = tmp_path / "runs" / "2026-01-01_00-05-00_flat_daqp_s0"
    proc = start(later)
    _, err = interrupt_when_running(proc, later, signal.SIGINT)
    assert f"note: {first}: an earlier run of this config, interrupted by SIGINT at t = " in err, err[-3000:]
    # into the same folder: the interrupted result is put aside and named, not skipped as complete
    from taslel_bench.sim.run import earlier_unfinished, prepare_folder
    from tests.conftest import compose_cfg

    cfg = compose_cfg(LONG)
    assert any(str(first) in line for line in earlier_unfinished(tmp_path / "runs" / "new", cfg))
    summary = json.loads((first / "summary.json").read_text())
    skipped, notes = prepare_folder(cfg, first, summary["config_sha256"])
    assert skipped is None and notes["superseded"].endswith("_interrupted")
    assert "interrupted by SIGINT" in notes["superseded_why"]


def test_a_refused_value_creates_no_folder(tmp_path):
    run_dir = tmp_path / "refused"
    out = subprocess.run([sys.executable, "-m", "taslel_bench", "controller.kp=-1", f"hydra.run.dir={run_dir}"],
                         cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    assert out.returncode == 2 and "controller.kp=-1" in out.stderr
    assert not run_dir.exists()


def test_a_report_rebuilt_during_a_live_sweep_marks_live_jobs_running(tmp_path):
    from taslel_bench.sweep.aggregate import collect

    live, dead = tmp_path / "seed=0", tmp_path / "seed=1"
    for folder in (live, dead):
        (folder / ".hydra").mkdir(parents=True)
        (folder / ".hydra" / "overrides.yaml").write_text(f"- seed={folder.name[-1]}\n")
        (folder / ".hydra" / "config.yaml").write_text(f"seed: {folder.name[-1]}\n")
    (dead / "run.lock").write_text('{"pid": 1, "host": "x", "started": "y"}')  # left, held by nobody
    holder = subprocess.Popen(
        [sys.executable, "-c", ("import sys; from taslel_bench.record.run_lock import RunLock; "
         f"l = RunLock(r'{live}').acquire(); print('held', flush=True); sys.stdin.read()")],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        rows = {int(r["seed"]): r for r in collect(tmp_path).to_dict("records")}
    finally:
        holder.kill()
        holder.wait()
    assert rows[0]["status"] == "running" and f"pid {holder.pid}" in rows[0]["message"]
    assert rows[1]["status"] == "error" and "crashed or killed" in rows[1]["message"]


def test_ctrl_c_of_a_sweep_stops_its_runs_starts_no_more_and_writes_the_table(tmp_path):
    """The terminal's SIGINT reaches the sweep and its workers: the running jobs end as interrupted runs, the
    queued ones are not started, the table says so for each, exit 130."""
    folder = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "taslel_bench", "-m", "seed=0,1,2,3", *LONG, f"hydra.sweep.dir={folder}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + 300
    while len(list(folder.glob("*/.steps.parquet.tmp-*"))) < 2 and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)  # as a Ctrl-C in its terminal: the whole process group
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err[-3000:]
    table = pd.read_parquet(folder / "summary.parquet")
    rows = {int(s): r for s, r in zip(table["seed"], table.to_dict("records"), strict=True)}
    assert sorted(rows) == [0, 1, 2, 3] and {r["status"] for r in rows.values()} == {"interrupted"}
    assert sum("not run: the sweep was interrupted by SIGINT" in r["message"] for r in rows.values()) == 2
    assert "Traceback" not in err and not (folder / ".sweep_interrupted").exists()
