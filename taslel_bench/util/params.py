"""Config fields that carry their meaning: ``param(0.4, "gait period", unit="s", lo=0, lo_open=True, hi=5)`` is a
dataclass field whose default, one-line meaning, unit and valid range live together. The run config's schema
(:mod:`taslel_bench.config.schema`) is made of such dataclasses; :func:`check_fields` checks a config node against
them (the messages of :mod:`taslel_bench.util.fields`), and the documentation's config reference is written from
them. Like :mod:`taslel_bench.util.fields`, no imports from the rest of the project.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from taslel_bench.util.fields import choice, fail, flag, integer, number

SPEC = "spec"  # the metadata key of a field's :class:`Spec`


@dataclass(frozen=True)
class Spec:
    """What a config field means and which values are valid. ``hi_key``: the upper bound is the value of another
    key of the run config (a dotted path from the root, e.g. ``control_rate_hz``), checked with its name."""

    doc: str  # one line: the key's meaning
    unit: str = ""  # e.g. "s", "N·m", "1/s"; "" for dimensionless or not a number
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    hi_key: str | None = None
    choices: tuple[str, ...] | None = None
    why: str = ""  # where a range comes from, when it is not obvious


def param(default: Any = dataclasses.MISSING, doc: str = "", *, factory: Callable[[], Any] | None = None,
          unit: str = "", lo: float | None = None, hi: float | None = None, lo_open: bool = False,
          hi_open: bool = False, hi_key: str | None = None, choices: tuple[str, ...] | None = None,
          why: str = "") -> Any:
    """A dataclass field with its :class:`Spec` (``factory`` instead of ``default`` for lists and nodes)."""
    spec = Spec(doc, unit, lo, hi, lo_open, hi_open, hi_key, tuple(choices) if choices else None, why)
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata={SPEC: spec})
    return dataclasses.field(default=default, metadata={SPEC: spec})


def spec_of(field: dataclasses.Field) -> Spec | None:
    return field.metadata.get(SPEC)


def default_of(cls: type, name: str) -> Any:
    """The default of field ``name`` of dataclass ``cls`` (a factory is called): a schema that mirrors a core
    dataclass reads the core's default instead of writing it again."""
    field = next(f for f in dataclasses.fields(cls) if f.name == name)
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def config_copy(cls: type, name: str) -> type:
    """A mutable dataclass ``name`` with the fields (types, defaults, specs) of the dataclass ``cls``: the config
    node of a frozen core value (OmegaConf makes a frozen dataclass's node read-only, so no override could set it);
    the core value is built from the node with ``cls(**values)``."""
    hints = typing.get_type_hints(cls)
    specs = [(f.name, hints[f.name], dataclasses.field(default=f.default, default_factory=f.default_factory,
                                                       metadata=f.metadata))
             for f in dataclasses.fields(cls)]
    copy = dataclasses.make_dataclass(name, specs)
    copy.__doc__ = cls.__doc__
    copy.__module__ = cls.__module__
    return copy


def _base(tp: Any) -> tuple[Any, bool]:
    """(the type without ``None``, whether ``None`` is allowed) of an annotation."""
    args = typing.get_args(tp)
    if args and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return (rest[0] if len(rest) == 1 else Any), True
    return tp, False


def schema_fields(cls: type) -> Iterator[tuple[dataclasses.Field, Any, bool]]:
    """(field, type without None, optional) of each field of the dataclass ``cls``."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp, optional = _base(hints[f.name])
        yield f, tp, optional


def check_value(path: str, value: Any, tp: Any, spec: Spec | None, bound: Callable[[str], Any]) -> None:
    """Raise a ConfigError naming ``path`` unless ``value`` is of type ``tp`` and within ``spec``'s range
    (``bound(key)``: the value of another config key, for ``hi_key``)."""
    if spec is not None and spec.choices:
        choice(path, value, spec.choices)
    elif tp is bool:
        flag(path, value)
    elif tp in (int, float) and spec is not None:
        hi, why = spec.hi, spec.why
        if spec.hi_key is not None:
            hi = float(bound(spec.hi_key))
            why = f"{why} at {spec.hi_key}={hi:g}" if why else f"at most {spec.hi_key}={hi:g}"
        if tp is int:
            integer(path, value, None if spec.lo is None else int(spec.lo), None if hi is None else int(hi),
                    unit=spec.unit)
        else:
            number(path, value, spec.lo, hi, lo_open=spec.lo_open, hi_open=spec.hi_open, unit=spec.unit, why=why)


def check_fields(path: str, node: Any, cls: type, bound: Callable[[str], Any]) -> None:
    """Check every field of the config ``node`` (a mapping at ``path``) against the dataclass ``cls``, nested
    dataclasses included; ``None`` passes where the field is optional; a key the dataclass has no field for (added
    with Hydra's ``+key=value``, which opens the node) is refused."""
    names = [f.name for f in dataclasses.fields(cls)]
    for key in node:
        if key not in names:
            where = f"{path}.{key}" if path else str(key)
            raise fail(where, node[key], f"unknown key; valid: {', '.join(names)}")
    for f, tp, optional in schema_fields(cls):
        value, where = node[f.name], f"{path}.{f.name}" if path else f.name
        if value is None and optional:
            continue
        if dataclasses.is_dataclass(tp) and isinstance(tp, type):
            check_fields(where, value, tp, bound)
            continue
        check_value(where, value, tp, spec_of(f), bound)


__all__ = ["SPEC", "Spec", "check_fields", "check_value", "config_copy", "default_of", "param", "schema_fields",
           "spec_of"]
