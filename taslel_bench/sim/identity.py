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
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from taslel_bench.util.provenance import _git, code_version

# MJCF elements naming a file, with the attribute(s) and the compiler directory that applies
_ASSET_ATTRS: dict[str, tuple[tuple[str, ...], str]] = {
    "mesh": (("file",), "meshdir"),
    "skin": (("file",), "meshdir"),
    "hfield": (("file",), "meshdir"),
    "texture": (("file", "fileright", "fileleft", "fileup", "filedown", "filefront", "fileback"), "texturedir"),
}


def _resolve(name: str, folders: Iterable[Path]) -> Path:
    """The first existing ``folder / name`` (an absolute ``name`` as is); the first candidate if none exists."""
    p = Path(name)
    if p.is_absolute():
        return p
    candidates = [folder / p for folder in folders]
    return next((c for c in candidates if c.is_file()), candidates[0])


def _parse(path: Path) -> ET.Element | None:
    try:
        return ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return None  # unreadable: hashed as bytes (or as missing); the plant build names the error


def mjcf_files(main: Path) -> list[Path]:
    """Every file MuJoCo reads for the MJCF ``main``: the file, its includes (recursively, relative to the
    including file's folder, then the main file's) and the assets they name. Missing files are listed too
    (their absence is part of the identity)."""
    main = Path(main).resolve()
    root_dir = main.parent
    files: list[Path] = []
    trees: list[ET.Element] = []
    todo = [main]
    while todo:
        path = todo.pop(0)
        if path in files:
            continue
        files.append(path)
        tree = _parse(path)
        if tree is None:
            continue
        trees.append(tree)
        for inc in tree.iter("include"):
            if inc.get("file"):
                todo.append(_resolve(inc.get("file", ""), (path.parent, root_dir)).resolve())
    dirs = {"meshdir": None, "texturedir": None, "assetdir": None}
    for tree in trees:
        for compiler in tree.iter("compiler"):
            for key in dirs:
                if compiler.get(key) is not None:
                    dirs[key] = compiler.get(key)
    for tree in trees:
        for tag, (attrs, dir_key) in _ASSET_ATTRS.items():
            sub = dirs[dir_key] if dirs[dir_key] is not None else dirs["assetdir"]
            folders = [root_dir / sub, root_dir] if sub else [root_dir]
            for element in tree.iter(tag):
                for attr in attrs:
                    if element.get(attr):
                        asset = _resolve(element.get(attr, ""), folders).resolve()
                        if asset not in files:
                            files.append(asset)
    return files


def hash_files(h: "hashlib._Hash", paths: Iterable[Path]) -> list[str]:
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
