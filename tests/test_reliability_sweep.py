"""The fault sweep: one worker killed (SIGKILL, as the OOM killer does), one run folder corrupted, the
disk full for one run (ENOSPC injected at its steps.parquet writer, tests/fault_injection/sitecustomize.py;
and, where this machine lets the test mount one, a real tiny tmpfs that fills up): the table is complete
with error rows, nothing is lost, the exit code says so."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import uuid
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent
FAULTS = Path(__file__).resolve().parent / "fault_injection"
TINY = ["duration=0.3", "progress=false", "record.mcap=false"]


def sweep(folder: Path, seeds: str, faults: str = "") -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(FAULTS), str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "TASLEL_FAULTS": faults}  # fmt: skip
    cmd = [sys.executable, "-m", "taslel_bench", "-m", f"seed={seeds}", *TINY, f"hydra.sweep.dir={folder}"]
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False)


@pytest.mark.slow
def test_killed_worker_corrupt_folder_and_full_disk_leave_a_complete_table(tmp_path):
    folder = tmp_path / "sweep"
    first = sweep(folder, "1")
    assert first.returncode == 0, first.stderr[-2000:]
    corrupt = folder / "duration=0.3,seed=1"
    old_summary = corrupt / "summary.json"
    old_summary.write_text(old_summary.read_text()[:300])  # truncated
    # Hydra's log stays
    old_files = {p.name: p.read_bytes() for p in corrupt.iterdir() if p.is_file() and p.suffix != ".log"}

    out = sweep(folder, "0,1,2,3", "kill=seed=2;enospc=seed=3")
    assert out.returncode == 1, out.stdout[-3000:] + out.stderr[-3000:]
    table = pd.read_parquet(folder / "summary.parquet")
    rows = {int(s): r for s, r in zip(table["seed"], table.to_dict("records"), strict=True)}
    assert sorted(rows) == [0, 1, 2, 3]  # every job has its row
    assert rows[0]["status"] == "ok" and rows[1]["status"] == "ok"
    assert rows[2]["status"] == "error" and "died twice" in rows[2]["message"] and "SIGKILL" in rows[2]["message"]
    assert rows[3]["status"] == "error" and "No space left on device" in rows[3]["message"]
    assert "steps.parquet" in rows[3]["message"]
    # nothing lost: the corrupted run's files are kept as they were, under superseded/
    moved = [d for d in (corrupt / "superseded").iterdir() if d.name.endswith("incomplete-summary-unreadable")]
    assert len(moved) == 1 and {p.name: p.read_bytes() for p in moved[0].iterdir()} == old_files
    assert "2 with errors" in out.stdout and "error: duration=0.3,seed=2" in out.stdout


@pytest.mark.slow
def test_sweep_on_a_real_full_disk_exits_1_with_one_line(tmp_path):
    """A tmpfs of 1.5 MB: the runs' files and the table do not fit. The sweep still ends, says "disk full"
    and exits 1 (skipped where mounting is not allowed)."""
    mount = tmp_path / f"tiny-{uuid.uuid4().hex[:6]}"
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1500k", "tmpfs", str(mount)], capture_output=True,
                      check=False).returncode != 0:  # fmt: skip
        pytest.skip("cannot mount a tmpfs here")
    try:
        out = sweep(mount / "sweep", "0,1,2")
        assert out.returncode == 1, out.stdout[-2000:] + out.stderr[-2000:]
        assert "disk full" in out.stderr or "No space left on device" in out.stdout
        assert "3 runs" in out.stdout  # the table, printed when it cannot be written
    finally:
        subprocess.run(["umount", str(mount)], check=False)


@pytest.mark.slow
def test_ray_launcher_turns_a_dead_worker_into_an_error_row(tmp_path):
    """hydra/launcher=ray: the worker of seed=1 is SIGKILLed (and again on Ray's one retry): that job is an
    error row naming it, the other jobs run on, the table is complete, exit 1."""
    folder = tmp_path / "sweep"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(FAULTS), str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "TASLEL_FAULTS": "kill=seed=1", "RAY_ADDRESS": "127.0.0.1:1"}  # fmt: skip
    cmd = [sys.executable, "-m", "taslel_bench", "-m", "hydra/launcher=ray", "hydra.launcher.num_cpus=2",
           "seed=0,1,2", *TINY, f"hydra.sweep.dir={folder}"]  # fmt: skip
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False)
    assert out.returncode == 1, out.stdout[-3000:] + out.stderr[-3000:]
    table = pd.read_parquet(folder / "summary.parquet")
    rows = {int(s): r for s, r in zip(table["seed"], table.to_dict("records"), strict=True)}
    assert sorted(rows) == [0, 1, 2]
    assert rows[0]["status"] == "ok" and rows[2]["status"] == "ok"
    assert rows[1]["status"] == "error" and "died twice" in rows[1]["message"]


@pytest.mark.slow
def test_workers_exit_when_the_sweep_process_is_killed(tmp_path):
    """SIGKILL of the sweep's main process only: its loky workers stop within a second or two instead of
    running their jobs on (a rerun would race them)."""
    import json
    import signal
    import time

    folder = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "taslel_bench", "-m", "seed=0,1", "duration=120", "progress=false",
           "record.mcap=false", "hydra.launcher.n_jobs=2", f"hydra.sweep.dir={folder}"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline, pids = time.monotonic() + 300, []
    while time.monotonic() < deadline and len(pids) < 2:
        pids = []
        for lock in folder.glob("*/run.lock"):
            with contextlib.suppress(OSError, ValueError, KeyError):
                pids.append(int(json.loads(lock.read_text())["pid"]))
        time.sleep(0.5)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert len(pids) == 2 and proc.pid not in pids  # the jobs run in workers
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.2)
    alive = [p for p in pids if _alive(p)]
    for p in alive:  # do not leave them behind if the test fails
        os.kill(p, signal.SIGKILL)
    assert alive == []


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"  # a zombie has exited
