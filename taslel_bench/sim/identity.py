"""A run's identity: the content of everything that decides its results, hashed into ``config_sha256``.

* the resolved config (without the keys that only change what is printed or the sweep's own settings);
* ``plant``: every file MuJoCo reads for the plant, as MuJoCo resolves it: ``robot.plant_mjcf`` (or
  example-robot-data's URDF), every ``<include>``d file (MuJoCo looks in the main file's folder first, also for
  an include inside an included file) and every mesh, heightfield, texture and skin they name
  (:func:`taslel_bench.plant.mjcf_files.mjcf_files`);
* ``model``: the controller model's URDF (``model.urdf`` or the default) and its ``model.from`` file;
* ``checkpoint``: every file the estimator loads (its optional ``input_files()``: model and drop detector);
* ``code``: the source of every module of the project's packages (:data:`PROJECT_PACKAGES`) that the run
  imports, found statically from :data:`ENTRY_MODULES` and every ``_target_`` of the config (imports inside
  functions included, so a module imported late in the episode counts too), and the ``_target_`` modules
  themselves wherever they live; a new, untracked ``scenarios/*.py`` is hashed like any other;
* ``config``: the config files Hydra composed (``conf/config.yaml`` and the file of each group's choice);
* the versions of the packages that compute the results (:data:`taslel_bench.util.machine.PACKAGES`).

Nothing of it comes from git: a copy without ``.git`` (a tarball, a non-editable install) has the same
identity as the checkout it was made from. ``git_commit`` / ``git_dirty`` stay in the summary as information.
:meth:`RunIdentity.record` says which files were hashed (kept in ``summary.json`` under ``identity``).
"""

from __future__ import annotations

import ast
import hashlib
import importlib.metadata
import importlib.util
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from functools import lru_cache
from pathlib import Path

from taslel_bench.plant.mjcf_files import mjcf_files

PROJECT_PACKAGES = ("taslel_bench", "scenarios", "solvers", "estimators", "hydra_plugins.taslel_bench_launchers")
ENTRY_MODULES = ("taslel_bench.sim.run",)  # runs an episode and writes its folder (the CLI around it only prints)
MISSING = "<missing>"


class FileRole(StrEnum):
    """Why a file is part of a run's identity."""

    PLANT = "plant"
    MODEL = "model"
    CHECKPOINT = "checkpoint"
    CODE = "code"
    CONFIG = "config"


@dataclass(frozen=True)
class IdentityFile:
    """One hashed file: ``name`` is how the identity knows it (a module name for code, a path relative to
    ``conf/`` for config files, the absolute path otherwise), ``sha256`` its content's hash or ``<missing>``."""

    role: FileRole
    name: str
    path: Path
    sha256: str


@dataclass(frozen=True)
class RunIdentity:
    """``config_sha256`` and what it was computed from."""

    config_sha256: str
    files: tuple[IdentityFile, ...]
    packages: tuple[tuple[str, str], ...]

    def record(self) -> dict[str, object]:
        """``{role: {name: sha256[:16]}, "packages": {name: version}}`` for ``summary.json``."""
        out: dict[str, object] = {role.value: {} for role in FileRole}
        for f in self.files:
            out[f.role.value][f.name] = f.sha256[:16]  # type: ignore[index]
        out["packages"] = dict(self.packages)
        return out


def file_sha256(path: Path) -> str:
    """[hex] sha256 of the file's bytes, :data:`MISSING` if it is not a file."""
    path = Path(path)
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else MISSING


# --------------------------------------------------------------------------------------------------- code


def is_project_module(name: str) -> bool:
    """``name`` is a module of one of :data:`PROJECT_PACKAGES` (or the package itself)."""
    return any(name == p or name.startswith(p + ".") for p in PROJECT_PACKAGES)


def _module_file(name: str) -> Path | None:
    """The source file of module ``name`` (a package's ``__init__.py``), None if it is not a module. A project
    module is looked up by path under its top-level package's folder(s), never imported (``from a.b import C``
    must not import ``a.b`` and what it needs, e.g. torch); another module through its finder."""
    if is_project_module(name):
        top, _, rest = name.partition(".")
        parts = rest.split(".") if rest else []
        for folder in _package_folders(top):
            base = folder.joinpath(*parts)
            for candidate in (base / "__init__.py", base.with_suffix(".py")) if parts else (base / "__init__.py",):
                if candidate.is_file():
                    return candidate.resolve()
        return None
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError, AttributeError):
        return None
    origin = spec.origin if spec is not None else None
    return Path(origin).resolve() if origin and origin.endswith(".py") else None


@lru_cache(maxsize=16)
def _package_folders(top: str) -> tuple[Path, ...]:
    """The folders of top-level package ``top`` (several for a namespace package such as hydra_plugins)."""
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return ()
    locations = list(spec.submodule_search_locations or []) if spec is not None else []
    return tuple(Path(p) for p in locations)


@lru_cache(maxsize=4096)
def _imported_names(path: Path, mtime_ns: int, size: int, module: str, is_package: bool) -> tuple[str, ...]:
    """Every module name an ``import`` statement of the file names (anywhere in it, relative imports made
    absolute; ``from a import b`` gives ``a`` and ``a.b``, which may be a module). Cached per file version."""
    tree = ast.parse(path.read_bytes(), filename=str(path))
    package = module if is_package else module.rpartition(".")[0]
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parent = ".".join(parts[: len(parts) - node.level + 1])
                base = f"{parent}.{base}" if base else parent
            names.append(base)
            names += [f"{base}.{alias.name}" for alias in node.names if alias.name != "*"]
    return tuple(names)


def _parents(name: str) -> list[str]:
    """``a.b.c`` -> ``[a, a.b]``: the packages Python imports (runs the ``__init__`` of) before ``a.b.c``."""
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def code_modules(roots: Iterable[str]) -> dict[str, Path]:
    """``{module name: source file}`` of ``roots`` and every project module they import, transitively
    (static: every import statement counts, also those inside functions). A root outside the project (a
    ``_target_`` in a test or user module) is included itself; its project imports are followed."""
    found: dict[str, Path] = {}
    todo = list(roots)
    root_names = set(todo)
    while todo:
        name = todo.pop()
        if name in found or not (is_project_module(name) or name in root_names):
            continue
        path = _module_file(name)
        if path is None:
            continue
        found[name] = path
        stat = path.stat()
        imported = _imported_names(path, stat.st_mtime_ns, stat.st_size, name, path.name == "__init__.py")
        todo += [n for n in (*imported, *_parents(name)) if n not in found]
    return found


def target_modules(config: object) -> list[str]:
    """The module of every ``_target_`` in a resolved config (nested dicts and lists)."""
    out: list[str] = []
    if isinstance(config, Mapping):
        target = config.get("_target_")
        if isinstance(target, str) and "." in target:
            out.append(_module_of(target))
        for value in config.values():
            out += target_modules(value)
    elif isinstance(config, list):
        for value in config:
            out += target_modules(value)
    return out


def _module_of(target: str) -> str:
    """The longest prefix of ``a.b.C.method`` that is a module (``a.b``)."""
    parts = target.split(".")
    for i in range(len(parts) - 1, 0, -1):
        name = ".".join(parts[:i])
        if _module_file(name) is not None:
            return name
    return parts[0]


# ------------------------------------------------------------------------------------------------- config


def config_files(conf_dir: Path, choices: Mapping[str, str]) -> dict[str, Path]:
    """``{path relative to conf/: file}`` of the files Hydra composed: ``config.yaml`` and
    ``<group>/<option>.yaml`` of each choice (``choices``: Hydra's ``runtime.choices``, or the defaults list of
    ``config.yaml`` for the groups not chosen)."""
    conf_dir = Path(conf_dir)
    chosen = {**_default_choices(conf_dir / "config.yaml"), **{k: str(v) for k, v in choices.items() if v}}
    files = {"config.yaml": conf_dir / "config.yaml"}
    for group, option in sorted(chosen.items()):
        if group.startswith("hydra") or option in ("null", "None"):
            continue
        rel = f"{group}/{option}.yaml"
        files[rel] = conf_dir / rel
    return files


def _default_choices(primary: Path) -> dict[str, str]:
    """``{group: option}`` of the primary config's defaults list (``- scenario: flat``)."""
    import yaml

    try:
        data = yaml.safe_load(primary.read_text()) or {}
    except (OSError, yaml.YAMLError):
        return {}
    out: dict[str, str] = {}
    for item in data.get("defaults", []) if isinstance(data, dict) else []:
        if isinstance(item, dict) and len(item) == 1:
            (group, option), = item.items()
            if isinstance(group, str) and not group.startswith(("override ", "hydra")) and isinstance(option, str):
                out[group.lstrip("+")] = option
    return out


# ------------------------------------------------------------------------------------------------- packages


def package_versions() -> tuple[tuple[str, str], ...]:
    """(name, version) of this package and of the packages that compute results (absent ones left out)."""
    from taslel_bench.util.machine import PACKAGES

    out = []
    for pkg in ("taslel_bench", *PACKAGES):
        try:
            out.append((pkg, importlib.metadata.version(pkg)))
        except importlib.metadata.PackageNotFoundError:
            continue
    return tuple(out)


# ----------------------------------------------------------------------------------------------- identity


def run_identity(config_text: str, plant: Iterable[Path], model: Iterable[Path], checkpoints: Iterable[Path],
                 targets: Iterable[str], config: Mapping[str, Path]) -> RunIdentity:  # fmt: skip
    """The identity of a run whose resolved config (as hashed) is ``config_text`` and which reads these files."""
    files: list[IdentityFile] = []
    for role, paths in ((FileRole.PLANT, plant), (FileRole.MODEL, model), (FileRole.CHECKPOINT, checkpoints)):
        files += [IdentityFile(role, str(p), Path(p), file_sha256(Path(p))) for p in paths]
    modules = code_modules([*ENTRY_MODULES, *targets])
    files += [IdentityFile(FileRole.CODE, name, path, file_sha256(path)) for name, path in sorted(modules.items())]
    files += [IdentityFile(FileRole.CONFIG, rel, path, file_sha256(path)) for rel, path in sorted(config.items())]
    packages = package_versions()
    h = hashlib.sha256(config_text.encode())
    for f in files:
        h.update(f"\0{f.role.value}\0{f.name}\0{f.sha256}".encode())
    for name, version in packages:
        h.update(f"\0package\0{name}\0{version}".encode())
    return RunIdentity(h.hexdigest(), tuple(files), packages)


__all__ = ["FileRole", "IdentityFile", "RunIdentity", "code_modules", "config_files", "file_sha256", "mjcf_files",
           "run_identity", "target_modules"]
