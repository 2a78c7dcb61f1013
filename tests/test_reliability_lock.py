"""Locks that hold: a lock left by a killed run inside a PID namespace is taken over, a live holder is
refused, and a stale lock released to several processes at once is taken by exactly one. Each test failed
on the main of before (a left lock naming pid 1 was never taken over; the racy take-over let several hold)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

from taslel_bench.record.run_lock import LOCK_NAME, RunFolderLocked, RunLock

ROOT = Path(__file__).resolve().parent.parent


def test_lock_left_by_pid_1_in_a_container_is_taken_over(tmp_path):
    """A run that is pid 1 in its PID namespace (a container) and was killed: pid 1 is alive here (another
    namespace's init), but nobody holds the lock."""
    (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": 1, "host": socket.gethostname(), "started": "x"}))
    with RunLock(tmp_path) as lock:
        assert lock.stale_taken_over is not None and "pid 1 " in lock.stale_taken_over
    assert not (tmp_path / LOCK_NAME).exists()


def test_live_holder_in_another_process_is_refused_and_named(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", ("import sys; from taslel_bench.record.run_lock import RunLock; "
         f"l = RunLock(r'{tmp_path}').acquire(); print('held', flush=True); sys.stdin.read()")],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        try:
            RunLock(tmp_path).acquire()
            raise AssertionError("a second writer got the lock of a live holder")
        except RunFolderLocked as exc:
            assert f"pid {holder.pid} on {socket.gethostname()}" in str(exc)
    finally:
        holder.kill()
        holder.wait()
    with RunLock(tmp_path) as lock:  # its process is gone (SIGKILL): the kernel freed the lock
        assert f"pid {holder.pid}" in str(lock.stale_taken_over)


def test_a_stale_lock_released_to_four_processes_at_once_is_held_by_one(tmp_path):
    race = [sys.executable, "-m", "studies.lock_race", str(tmp_path), "15"]  # 15 trials (studies/lock_race.py)
    out = subprocess.run(race, cwd=ROOT, capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.strip() == "0", f"{out.stdout.strip()} of 15 trials had more than one holder"
