"""A run's identity: everything that decides its results, hashed into ``config_sha256``.

* the resolved config (without the keys that only change what is printed or the sweep's own settings);
* the content of every file MuJoCo reads for the plant: ``robot.plant_mjcf`` (or example-robot-data's URDF),
  every ``<include>``d file, and every mesh, heightfield, texture and skin they name (found through the
  ``<compiler meshdir/texturedir/assetdir>`` of the model, relative to the main file's folder);
* the controller model's URDF (``model.urdf`` or the default);
* every checkpoint the estimator loads (its optional ``input_files()``: model and drop detector);
* the code version (package version, git commit and a hash of uncommitted changes to tracked files).

A change to any of them gives another hash, so a complete run of the old inputs is not skipped.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from taslel_bench.plant.mjcf_files import mjcf_files
from taslel_bench.util.provenance import _git, code_version


def hash_files(h: hashlib._Hash, paths: Iterable[Path]) -> list[str]:
    """Feed each file's name and content (or ``<missing>``) to ``h``; returns the names hashed."""
    names = []
    for path in paths:
        path = Path(path)
        h.update(str(path).encode() + b"\0")
        h.update(path.read_bytes() if path.is_file() else b"<missing>")
        h.update(b"\0")
        names.append(str(path))
    return names


@lru_cache(maxsize=1)
def code_identity() -> str:
    """Package version, git commit and a hash of the uncommitted changes to tracked files (results/
    excluded): the code that produced a run."""
    try:
        version = metadata.version("taslel_bench")
    except metadata.PackageNotFoundError:
        version = "unknown"
    v = code_version()
    diff = _git("diff", "HEAD", "--", ".", ":(exclude)results") if v["git_commit"] != "unknown" else None
    diff_sha = hashlib.sha256((diff or "").encode()).hexdigest()[:16]
    return f"taslel_bench {version} commit {v['git_commit']} diff {diff_sha}"


__all__ = ["code_identity", "hash_files", "mjcf_files"]
