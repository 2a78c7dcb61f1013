"""One writer per run folder: ``run.lock``, held with ``fcntl.flock`` for as long as the run writes the folder.

The kernel holds the lock for the open file, not for a pid: it is released the moment its process ends,
however it ends (SIGKILL, the OOM killer, a container stopped), so

* a lock left by a dead run is never mistaken for a live one, also inside a PID namespace (a container where
  every run is pid 1) or when the pid has been reused: the file is there but nobody holds it; it is taken over
  and the takeover is reported (``stale_taken_over``, from the pid/host/time the dead run wrote into it);
* taking over is atomic: ``flock(LOCK_EX | LOCK_NB)`` succeeds for exactly one process; a process that
  locked a file a releasing run had just unlinked sees that the path no longer names its file and retries;
* a lock held by a live process is refused with :class:`RunFolderLocked` naming the holder.

Across hosts sharing a file system: on NFS, Linux sends ``flock`` to the server as a whole-file lock (NLM for
NFS v3, the protocol's own locks for v4), so two hosts exclude each other as two processes of one host do,
unless the file system is mounted with ``nolock`` or ``local_lock=flock``/``all`` (then the lock only
excludes processes of the same host: do not run one sweep folder from several hosts on such a mount). A lock
of a host that crashed is freed by the server when the host's lease or NLM state expires (NFS v4: the lease
time, typically 90 s); until then the folder is refused. Other network file systems: whatever their flock
gives (CephFS and Lustre with ``flock`` mount option: cluster-wide; SMB/CIFS: not guaranteed).
"""

from __future__ import annotations

import datetime as dt
import errno
import fcntl
import json
import os
import socket
import time
from pathlib import Path
from typing import Self

LOCK_NAME = "run.lock"
MAX_ATTEMPTS = 20  # the path was replaced under us this many times in a row: give up (RunFolderLocked)
CONTENTION_WAIT_S = 0.5  # [s] a lock held this long by another process is a live writer (a probe holds it µs)


class RunFolderLocked(RuntimeError):
    """Another live process writes this run folder."""


def _read_holder(fd: int) -> dict | None:
    """The holder record (pid, host, started) in the open lock file, None if empty or unreadable."""
    try:
        raw = os.pread(fd, 4096, 0)
        data = json.loads(raw.decode()) if raw.strip() else None
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _describe(holder: dict | None) -> str:
    if holder is None:
        return "an unreadable lock record"
    return f"pid {holder.get('pid')} on {holder.get('host')} since {holder.get('started')}"


def _flock_within(fd: int, wait_s: float) -> bool:
    """Take the exclusive lock of ``fd``, retrying for ``wait_s``; False if another process keeps it."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                os.close(fd)
                raise
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.02)


def _same_file(fd: int, path: Path) -> bool:
    """``path`` still names the file open as ``fd`` (a releasing holder unlinks it before it unlocks)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    mine = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (mine.st_dev, mine.st_ino)


class RunLock:
    """``with RunLock(run_dir):`` holds ``run_dir/run.lock`` for the block. ``stale_taken_over`` names the dead
    holder whose lock file was left behind (None if the folder was free)."""

    def __init__(self, run_dir: Path) -> None:
        self.path = Path(run_dir) / LOCK_NAME
        self.stale_taken_over: str | None = None
        self._fd: int | None = None

    def acquire(self) -> Self:
        for _ in range(MAX_ATTEMPTS):
            fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
            if not _flock_within(fd, CONTENTION_WAIT_S):
                holder = _read_holder(fd)
                os.close(fd)
                raise RunFolderLocked(
                    f"{self.path.parent}: run folder is being written by {_describe(holder)} ({self.path}, locked); "
                    f"two writers would corrupt each other's files. Wait for it, or stop it; the lock is released "
                    f"when that process ends, however it ends"
                ) from None
            if not _same_file(fd, self.path):  # its holder released (and unlinked) it meanwhile: take the new one
                os.close(fd)
                continue
            left = _read_holder(fd)
            if left is not None:  # a record nobody holds: its process died without releasing
                self.stale_taken_over = _describe(left)
            self._write_record(fd)
            self._fd = fd
            return self
        raise RunFolderLocked(f"{self.path}: could not take the lock (the file kept being replaced)")

    @staticmethod
    def _write_record(fd: int) -> None:
        me = {"pid": os.getpid(), "host": socket.gethostname(),
              "started": dt.datetime.now(dt.UTC).isoformat(timespec="seconds")}  # fmt: skip
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(me).encode(), 0)

    def release(self) -> None:
        """Unlink the lock file while still holding it, then unlock (a waiter that opened the old file sees
        it is gone and retries on the path)."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            if _same_file(fd, self.path):
                self.path.unlink(missing_ok=True)
        finally:
            os.close(fd)  # releases the flock

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> Self:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def live_holder(run_dir: Path) -> str | None:
    """Who holds ``run_dir/run.lock`` now (pid, host, start), None if nobody does (or there is no lock file).
    Probed with a shared lock taken and dropped at once (a run starting meanwhile retries for
    :data:`CONTENTION_WAIT_S`, so a reader, e.g. a report rebuilt during a sweep, never makes it fail)."""
    try:
        fd = os.open(Path(run_dir) / LOCK_NAME, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                return _describe(_read_holder(fd))
            raise
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


__all__ = ["LOCK_NAME", "RunFolderLocked", "RunLock", "live_holder"]
