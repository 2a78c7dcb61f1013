"""The run lock's race (``python -m studies.lock_race FOLDER TRIALS``): in each trial a stale lock (left by a
dead process) is met by 4 processes released at once; every holder logs when it enters and leaves. Prints the
number of trials in which more than one process held the lock at the same time (0: the lock is exclusive).
Run by ``tests/test_reliability_lock.py`` and the fault matrix (``studies/fault_matrix.py``)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import socket
import sys
import time
from pathlib import Path

from taslel_bench.record.run_lock import RunFolderLocked, RunLock

CONTENDERS = 4
HOLD_S = 0.2  # [s] each holder keeps the lock this long


def contender(folder: Path, barrier, log: Path) -> None:
    """Wait for the others, try the lock once, log the time held."""
    barrier.wait()
    try:
        lock = RunLock(folder).acquire()
    except RunFolderLocked:
        return
    with open(log, "a") as f:
        f.write(f"{os.getpid()} in {time.monotonic()}\n")
    time.sleep(HOLD_S)
    with open(log, "a") as f:
        f.write(f"{os.getpid()} out {time.monotonic()}\n")
    lock.release()


def most_holders(log: Path) -> int:
    """The largest number of processes that held the lock at once, from the log's in/out lines."""
    held = most = 0
    for line in log.read_text().split("\n"):
        if line:
            held += 1 if line.split()[1] == "in" else -1
            most = max(most, held)
    return most


def trial(folder: Path) -> int:
    """One race in ``folder`` (made here) on the stale lock of a process that has exited; its most holders."""
    folder.mkdir()
    dead = mp.Process(target=time.sleep, args=(0,))  # a killed run's pid
    dead.start()
    dead.join()
    (folder / "run.lock").write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(), "started": "x"}))
    log = folder / "log"
    log.write_text("")
    barrier = mp.Barrier(CONTENDERS)
    procs = [mp.Process(target=contender, args=(folder, barrier, log)) for _ in range(CONTENDERS)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
    return most_holders(log)


def main(argv: list[str] | None = None) -> None:
    args = argv if argv is not None else sys.argv[1:]
    folder, trials = Path(args[0]), int(args[1])
    print(sum(trial(folder / f"t{k}") > 1 for k in range(trials)))


if __name__ == "__main__":
    main()
