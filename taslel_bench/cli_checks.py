"""Checks of the command line before Hydra composes or runs anything (``python -m taslel_bench``).

* ``group=option`` with an option that does not exist: refused with the closest options ("did you mean").
* ``key=value`` with a key the config does not have: refused with the closest keys.
* ``key=value`` with a value the schema's type or range refuses (``controller.period=abc``): refused with the
  key's valid range and unit (:mod:`taslel_bench.config.schema`), before Hydra's own type error.
* ``+key=value`` (Hydra's "append"): refused when no part of the run reads the key. A key is read when its
  value is an object with a ``_target_``, when it is an entry of a node the run reads whole
  (:data:`WHOLE_NODES`, e.g. ``filter.barriers``), when the config node holding it is built by a ``_target_``
  whose constructor takes that argument (or ``**kwargs``),
  or when the harness reads it by name as an optional key (``node.get("key")``, ``_get(cfg, "a.b.key")``,
  ``OmegaConf.select(cfg, "a.b.key")``) in the source of ``taslel_bench`` or of the axis packages.

Every refusal is a :class:`CliError`; ``python -m taslel_bench`` prints it and exits 2 (bad input), before
any folder is created.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import inspect
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

from taslel_bench.config.compose import CONF_DIR

REPO = CONF_DIR.parent
SOURCE_DIRS = ("taslel_bench", "scenarios", "solvers", "estimators")
# nodes whose every entry the run reads (built as a list, or handed on whole): a key added under them is read
WHOLE_NODES = ("filter.barriers", "robot.plant_names", "robot.plant_overrides")
RENAMED_TARGET = "solvers.registry.renamed"  # conf/solver/<name>_persistent.yaml: old names, refused when used


class CliError(ValueError):
    """A command-line mistake found before anything runs; the message names the override and what is valid."""


def _yaml_target(path: Path) -> str | None:
    for line in path.read_text().splitlines():
        m = re.match(r"_target_:\s*(\S+)", line)
        if m:
            return m.group(1)
    return None


@functools.cache
def group_options(conf_dir: Path = CONF_DIR, include_renamed: bool = True) -> dict[str, tuple[str, ...]]:
    """Config group -> its options (the YAML files of ``conf/<group>/``); ``include_renamed=False`` leaves out
    the old names that are refused when used (kept so that the refusal can name the new name)."""
    groups: dict[str, tuple[str, ...]] = {}
    for sub in sorted(p for p in conf_dir.rglob("*") if p.is_dir()):
        files = sorted(sub.glob("*.yaml"))
        if not include_renamed:
            files = [f for f in files if _yaml_target(f) != RENAMED_TARGET]
        if files:
            groups[sub.relative_to(conf_dir).as_posix()] = tuple(f.stem for f in files)
    return groups


def suggest(word: str, candidates: Iterable[str], n: int = 2) -> list[str]:
    """The closest candidates to ``word`` (difflib ratio >= 0.75), best first."""
    return difflib.get_close_matches(word, list(candidates), n=n, cutoff=0.75)


def _did_you_mean(word: str, candidates: Iterable[str]) -> str:
    close = suggest(word, [c for c in candidates if not word.startswith(c + ".")])  # not the key's own parents
    return f"; did you mean {' or '.join(close)}?" if close else ""


def _is_cli_flag(arg: str) -> bool:
    return arg.startswith("-")


def task_overrides(argv: Sequence[str]) -> list[str]:
    """The override arguments of a command line (Hydra's flags and their values removed)."""
    out, skip = [], False
    for arg in argv:
        if skip:
            skip = False
            continue
        if arg in ("--config-name", "-cn", "--config-path", "-cp", "--config-dir", "-cd", "--experimental-rerun",
                   "--info", "-i"):
            skip = arg not in ("--info", "-i")
            continue
        if _is_cli_flag(arg):
            continue
        out.append(arg)
    return out


@functools.cache
def _optional_keys_read() -> frozenset[str]:
    """Dotted paths and leaf names the harness reads as optional keys (``.get("name")``, ``select(cfg, "a.b")``,
    ``_get(cfg, "a.b")``) anywhere in its source and the axis packages."""
    names: set[str] = set()
    pattern = re.compile(r"""(?:\.get|_get\(\w+,|select\(\w+,)\(?\s*["']([A-Za-z_][\w.]*)["']""")
    for d in SOURCE_DIRS:
        for path in (REPO / d).rglob("*.py"):
            for m in pattern.finditer(path.read_text(errors="replace")):
                names.add(m.group(1))
                names.add(m.group(1).rsplit(".", 1)[-1])
    return frozenset(names)


def _target_accepts(target: str, name: str) -> bool:
    """Whether the ``_target_`` class or function takes ``name`` as an argument (or any keyword)."""
    module, _, attr = target.rpartition(".")
    try:
        obj = getattr(importlib.import_module(module), attr)
        params = inspect.signature(obj).parameters
    except (ImportError, AttributeError, TypeError, ValueError):
        return True  # cannot tell: let the run's own checks decide
    return name in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())


def _keys(node, prefix: str = "") -> list[str]:
    from omegaconf import DictConfig

    out = []
    if isinstance(node, DictConfig):
        for k in node:
            path = f"{prefix}{k}"
            out.append(path)
            out.extend(_keys(node._get_node(k), path + "."))
    return out


def _check_group(line: str, key: str, values: list[str], groups: dict[str, tuple[str, ...]]) -> None:
    options = groups[key]
    for v in values:
        path = CONF_DIR / key / f"{v}.yaml"
        if v in options and _yaml_target(path) == RENAMED_TARGET:
            note = " ".join(ln.lstrip("# ").strip() for ln in path.read_text().splitlines() if ln.startswith("#"))
            raise CliError(f"{line}: '{v}' is an old name, refused. {note}")
        if v not in options:
            shown = group_options(include_renamed=False).get(key, options)
            raise CliError(f"{line}: '{v}' is not an option of the config group '{key}'"
                           f"{_did_you_mean(v, shown)} (options: {', '.join(shown)})")


def _values(override) -> list:
    """The value of an override, or each value of a sweep over a list of choices (a range or a glob: none)."""
    if not override.is_sweep_override():
        return [override.value()]
    try:
        return list(override.sweep_iterator())
    except Exception:  # a sweep kind without a finite list of values: the run's validation judges each job
        return []


def _check_typed_value(cfg, key: str, value) -> None:
    """Refuse ``key=value`` where the schema's field type refuses the value, with the field's range and unit (the
    text of :func:`taslel_bench.util.params.check_value`), else OmegaConf's own reason."""
    import copy
    import dataclasses

    from omegaconf import DictConfig, OmegaConf
    from omegaconf.errors import ValidationError

    from taslel_bench.util.fields import ConfigError
    from taslel_bench.util.params import check_value, schema_fields, spec_of

    parent_key, _, leaf = key.rpartition(".")
    parent = OmegaConf.select(cfg, parent_key) if parent_key else cfg
    schema = OmegaConf.get_type(parent) if parent is not None else None
    if not (isinstance(parent, DictConfig) and isinstance(schema, type) and dataclasses.is_dataclass(schema)):
        return  # a node without a schema (an axis, a free-form mapping): its own checks judge the value
    try:
        OmegaConf.update(copy.deepcopy(parent), leaf, value, merge=True)  # a copy of the typed node, on trial
        return
    except ValidationError as exc:
        reason = str(exc).splitlines()[0]
    for field, tp, _optional in schema_fields(schema):
        if field.name == leaf:
            try:
                check_value(key, value, tp, spec_of(field), lambda other: OmegaConf.select(cfg, other))
            except ConfigError as exc:
                raise CliError(str(exc)) from None
    raise CliError(f"{key}={value!r}: {reason}")


def check_overrides(argv: Sequence[str]) -> None:
    """Refuse unknown group options, unknown keys and unread ``+key=value`` overrides (see the module doc)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf import OmegaConf

    args = task_overrides(argv)
    if not args:
        return
    try:
        parsed = OverridesParser.create().parse_overrides(args)
    except HydraException:
        return  # a syntax error: Hydra's own message says where
    groups = group_options()
    group_args, key_overrides = [], []
    for o in parsed:
        key = o.key_or_group
        if o.is_delete():
            continue
        if key.startswith(("hydra.", "hydra/")):
            # Hydra's own groups also hold its plugins' options (submitit_local, joblib ...): Hydra checks them
            continue
        if key in groups:
            values = list(o.sweep_string_iterator()) if o.is_sweep_override() else [str(o.value())]
            assert o.input_line is not None  # parse_overrides keeps each override's text
            _check_group(o.input_line, key, values, groups)
            group_args.append(f"{'+' if o.is_add() else ''}{key}={values[0]}")
        else:
            key_overrides.append(o)
    if not key_overrides:
        return
    from taslel_bench.config.compose import compose

    try:
        cfg = compose(group_args)
    except Exception:  # a composition error is reported by Hydra itself, with its own message
        return
    known = _keys(cfg)
    optional = _optional_keys_read()
    for o in key_overrides:
        key = o.key_or_group
        exists = OmegaConf.select(cfg, key, default="__absent__", throw_on_missing=False) != "__absent__"
        if not (o.is_add() or o.is_force_add()):
            if not exists:
                raise CliError(f"{o.input_line}: the config has no key '{key}'{_did_you_mean(key, known)} "
                               f"(the keys: python -m taslel_bench --cfg job)")
            for value in _values(o):
                _check_typed_value(cfg, key, value)
            continue
        if exists:
            continue  # Hydra refuses to append an existing key itself; ++ sets it
        parent, _, leaf = key.rpartition(".")
        value = o.value()
        if parent in WHOLE_NODES or (isinstance(value, dict) and "_target_" in value):
            continue  # an entry of a node read whole, or an object built from its _target_
        node = OmegaConf.select(cfg, parent) if parent else cfg
        target = node.get("_target_") if node is not None and OmegaConf.is_dict(node) else None
        if target is not None and _target_accepts(str(target), leaf):
            continue
        if key in optional or (leaf in optional and node is not None):
            continue
        raise CliError(f"{o.input_line}: no part of the run reads '{key}', so it would change nothing"
                       f"{_did_you_mean(key, known)} (an existing key is set without '+': key=value)")
