"""The machine, package versions and code version (git commit) a result was produced on (one place; reports of every package and
axis use it: it is a leaf module with no dependency on the rest of the core)."""

from __future__ import annotations

import importlib.metadata
import os
import platform
from pathlib import Path

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
