"""The machine, package versions and code version (git commit) a result was produced on (one place; reports of every
package and axis use it: it is a leaf module with no dependency on the rest of the core)."""

from __future__ import annotations

import importlib.metadata
import math
import os
import platform
import resource
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Self

from taslel_bench.util.provenance import describe as describe_code

PACKAGES = ("mujoco", "pin", "numpy", "scipy", "qpsolvers", "osqp", "clarabel", "piqp", "proxsuite", "daqp",
            "quadprog", "hydra-core", "pandas", "torch", "lightning")


def machine_info() -> dict[str, str]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {}
    for pkg in PACKAGES:
        try:
            versions[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            continue
    return {
        "code": describe_code(),
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "os": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "packages": ", ".join(f"{k} {v}" for k, v in versions.items()),
    }


# ------------------------------------------------------------------------------ how busy the machine was

BUSY_CPU_SHARE = 0.8  # below this share of the wall time on a CPU, the loop's thread waited for one: busy
BUSY_STEAL_SHARE = 0.05  # above this share of the CPU time stolen by the hypervisor: busy


@dataclass(frozen=True)
class CpuShare:
    """How much of the wall time the measured thread had a CPU, and why it may not have.

    ``thread_share``: the thread's CPU time / wall time (1: never waited; a single-threaded loop on a quiet
    core is ~0.95-1); ``process_share``: the whole process's (user + system, all threads) / wall time;
    ``load_1min_start``/``_end``: the 1-minute load average; ``steal_share``: share of all CPUs' time the
    hypervisor gave to other guests (nan where ``/proc/stat`` is missing); ``involuntary_switches_per_s``:
    the process was preempted this often."""

    wall_s: float
    thread_share: float
    process_share: float
    load_1min_start: float
    load_1min_end: float
    steal_share: float
    involuntary_switches_per_s: float

    @property
    def busy_reason(self) -> str:
        """Why the timing is disturbed ("" when it is not)."""
        reasons = []
        if self.thread_share < BUSY_CPU_SHARE:
            reasons.append(f"CPU share {self.thread_share:.2f}")
        if math.isfinite(self.steal_share) and self.steal_share > BUSY_STEAL_SHARE:
            reasons.append(f"steal {self.steal_share:.0%}")
        return ", ".join(reasons)

    def record(self, prefix: str = "machine_") -> dict[str, object]:
        """Flat summary keys (``machine_cpu_share``, ..., ``machine_busy``, ``machine_busy_reason``)."""
        return {f"{prefix}cpu_share": self.thread_share, f"{prefix}process_cpu_share": self.process_share,
                f"{prefix}load_1min_start": self.load_1min_start, f"{prefix}load_1min_end": self.load_1min_end,
                f"{prefix}steal_share": self.steal_share,
                f"{prefix}involuntary_switches_per_s": self.involuntary_switches_per_s,
                f"{prefix}busy": bool(self.busy_reason), f"{prefix}busy_reason": self.busy_reason}  # fmt: skip


def _steal_and_total() -> tuple[float, float]:
    """(steal, total) jiffies of all CPUs from /proc/stat; (nan, nan) where it is not readable."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
        values = [float(v) for v in fields[:8]]
    except (OSError, IndexError, ValueError):
        return math.nan, math.nan
    return (values[7] if len(values) > 7 else math.nan), sum(values)


class CpuWatch:
    """``with CpuWatch() as watch: ...`` then ``watch.result`` (:class:`CpuShare`) of the block, for the
    calling thread and its process."""

    def __enter__(self) -> Self:
        self._wall0, self._thread0 = time.perf_counter(), time.thread_time()
        self._usage0 = resource.getrusage(resource.RUSAGE_SELF)
        self._load0 = os.getloadavg()[0]
        self._steal0 = _steal_and_total()
        self.result: CpuShare | None = None
        return self

    def __exit__(self, *exc: object) -> None:
        wall = max(time.perf_counter() - self._wall0, 1e-9)
        usage = resource.getrusage(resource.RUSAGE_SELF)
        process = (usage.ru_utime + usage.ru_stime) - (self._usage0.ru_utime + self._usage0.ru_stime)
        steal1, total1 = _steal_and_total()
        d_total = total1 - self._steal0[1]
        steal = (steal1 - self._steal0[0]) / d_total if d_total > 0 else math.nan
        self.result = CpuShare(wall, (time.thread_time() - self._thread0) / wall, process / wall, self._load0,
                               os.getloadavg()[0], steal,
                               (usage.ru_nivcsw - self._usage0.ru_nivcsw) / wall)  # fmt: skip
