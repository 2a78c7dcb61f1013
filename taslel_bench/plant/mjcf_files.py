"""The files MuJoCo reads for an MJCF: the file, its ``<include>``s (recursively) and every mesh, skin,
heightfield and texture they name, found as MuJoCo finds them (includes relative to the main file's folder,
then the including file's; assets under ``<compiler meshdir / texturedir / assetdir>`` relative to the main
file's folder). Used for the run's identity (:mod:`taslel_bench.sim.identity`) and to name missing
files in a compile error (:func:`taslel_bench.plant.build.compile_plant`)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path

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
    main file's folder, then the including file's: MuJoCo's order) and the assets they name. Missing files are
    listed too (their absence is part of the identity)."""
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
                todo.append(_resolve(inc.get("file", ""), (root_dir, path.parent)).resolve())  # MuJoCo's order
    dirs: dict[str, str | None] = {"meshdir": None, "texturedir": None, "assetdir": None}
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


__all__ = ["mjcf_files"]
