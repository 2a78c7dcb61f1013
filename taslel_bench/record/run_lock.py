"""One writer per run folder: ``run.lock`` holds the writer's pid, host and start time.

The lock is created with ``O_CREAT | O_EXCL`` (atomic on POSIX, also on NFS v3+). A lock left by a process
that is gone (same host, pid no longer alive: a SIGKILLed run, a dead worker) is stale and taken over, and
the takeover is reported. A lock of a live process, or of a process on another host (whose liveness cannot
be checked from here), is refused with :class:`RunFolderLocked` naming the holder.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import socket
from pathlib import Path
from typing import Self

LOCK_NAME = "run.lock"


class RunFolderLocked(RuntimeError):
    """Another live process writes this run folder."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        return True
    return True


def _holder(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None  # unreadable: a writer died between create and write
    return data if isinstance(data, dict) else None


def is_stale(holder: dict | None) -> bool:
    """A lock whose process is gone: same host and pid not alive (or an unreadable lock file)."""
    if holder is None:
        return True
    if holder.get("host") != socket.gethostname():
        return False
    pid = holder.get("pid")
    return not (isinstance(pid, int) and _alive(pid))


class RunLock:
    """``with RunLock(run_dir):`` holds ``run_dir/run.lock`` for the block. ``stale_taken_over`` names a
    dead holder whose lock was taken over (None if the folder was free)."""

    def __init__(self, run_dir: Path) -> None:
        self.path = Path(run_dir) / LOCK_NAME
        self.stale_taken_over: str | None = None
        self._held = False

    def acquire(self) -> Self:
        me = {"pid": os.getpid(), "host": socket.gethostname(),
              "started": dt.datetime.now(dt.UTC).isoformat(timespec="seconds")}  # fmt: skip
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = _holder(self.path)
                if not is_stale(holder):
                    raise RunFolderLocked(
                        f"{self.path.parent}: run folder is being written by pid {holder.get('pid')} on "
                        f"{holder.get('host')} since {holder.get('started')} ({self.path}); two writers would "
                        f"corrupt each other's files. Wait for it, or stop it; a lock of a dead process on this "
                        f"host is taken over automatically, one of another host must be deleted by hand"
                    ) from None
                self.stale_taken_over = (f"pid {holder.get('pid')} on {holder.get('host')} since "
                                         f"{holder.get('started')}" if holder else "unreadable lock")
                self.path.unlink(missing_ok=True)
                continue
            with os.fdopen(fd, "w") as f:
                f.write(json.dumps(me))
            self._held = True
            return self
        raise RunFolderLocked(f"{self.path}: could not take the lock (another process keeps recreating it)")

    def release(self) -> None:
        if self._held:
            self._held = False
            holder = _holder(self.path)
            if holder is not None and holder.get("pid") == os.getpid():
                self.path.unlink(missing_ok=True)

    def __enter__(self) -> Self:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


__all__ = ["LOCK_NAME", "RunFolderLocked", "RunLock", "is_stale"]
