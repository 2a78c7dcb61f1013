"""Checks of single config values that name the field: ``number("scenario.height_m", -1, lo=0, hi=0.2)``
raises :class:`ConfigError` ``scenario.height_m=-1: must be a finite number in [0, 0.2] [m]``.

A small helper module with no imports from the rest of the project: the core's :mod:`taslel_bench.config.validate`
uses it for the core groups, and the axis packages (``scenarios``, ``solvers``, ``estimators``) use it to
check their own constructor arguments, naming them by their dotted config path (``scenario.<key>``,
``solver.<key>``, ``estimator.<key>``).
"""

from __future__ import annotations

import math
import numbers as _numbers
from collections.abc import Iterable, Sequence
from typing import Any, cast


class ConfigError(ValueError):
    """A config value is invalid; the message names the field (dotted config path), the value and what is
    allowed."""


def _show(value: Any) -> str:
    """The value as the user wrote it (lists and dicts of OmegaConf containers as plain Python)."""
    if hasattr(value, "_content") or isinstance(value, (list, tuple, dict)):
        try:
            from omegaconf import OmegaConf

            return repr(OmegaConf.to_container(value) if hasattr(value, "_content") else value)
        except Exception:  # only for the message
            return repr(value)
    return repr(value)


def fail(path: str, value: Any, rule: str) -> ConfigError:
    """The error for ``path=value`` breaking ``rule`` (raise it)."""
    return ConfigError(f"{path}={_show(value)}: {rule}")


def plain_dict(node: Any, path: str) -> dict[str, Any]:
    """An OmegaConf mapping node as a plain dict, interpolations resolved (``OmegaConf.to_container``);
    :class:`ConfigError` naming ``path`` when the node is not a mapping."""
    from omegaconf import OmegaConf

    plain = OmegaConf.to_container(node, resolve=True)
    if not isinstance(plain, dict):
        raise fail(path, node, "must be a mapping")
    return cast(dict[str, Any], plain)  # config keys are strings (YAML and Hydra's overrides)


def interval(lo: float | None, hi: float | None, lo_open: bool = False, hi_open: bool = False) -> str:
    """``[0, 5)``-style text of a range (``-inf``/``inf`` for a missing end)."""
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    return f"{left}{'-inf' if lo is None else _fmt(lo)}, {'inf' if hi is None else _fmt(hi)}{right}"


def _fmt(x: float) -> str:
    """Integers in full, floats with 6 significant digits."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def is_number(value: Any) -> bool:
    """A real number (numpy scalars included), not a bool (YAML ``true`` is not 1 here) and not a string."""
    return isinstance(value, _numbers.Real) and not isinstance(value, bool)


def number(
    path: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
    why: str = "",
) -> float:
    """``value`` as a float; raises unless it is a finite number in the range (``lo``/``hi`` None: open).
    ``why`` (appended in parentheses) says where a range comes from when it is not obvious."""
    rng = interval(lo, hi, lo_open, hi_open)
    rule = f"must be a finite number in {rng}" + (f" [{unit}]" if unit else "") + (f" ({why})" if why else "")
    if not is_number(value) or not math.isfinite(value):
        raise fail(path, value, rule)
    x = float(value)
    below = lo is not None and (x <= lo if lo_open else x < lo)
    above = hi is not None and (x >= hi if hi_open else x > hi)
    if below or above:
        raise fail(path, value, rule)
    return x


def integer(path: str, value: Any, lo: int | None = None, hi: int | None = None, *, unit: str = "") -> int:
    """``value`` as an int; raises unless it is a whole number (``3`` or ``3.0``) in ``[lo, hi]``."""
    rule = f"must be an integer in {interval(lo, hi)}" + (f" [{unit}]" if unit else "")
    if not is_number(value) or not math.isfinite(value) or float(value) != int(value):
        raise fail(path, value, rule)
    n = int(value)
    if (lo is not None and n < lo) or (hi is not None and n > hi):
        raise fail(path, value, rule)
    return n


def flag(path: str, value: Any) -> bool:
    """``value`` if it is a bool (``true``/``false``); raises otherwise (``"maybe"`` would be truthy)."""
    if not isinstance(value, bool):
        raise fail(path, value, "must be true or false")
    return value


def choice(path: str, value: Any, choices: Iterable[str]) -> str:
    """``value`` if it is one of ``choices``; raises listing them otherwise."""
    valid = tuple(choices)
    if value not in valid:
        raise fail(path, value, f"valid: {', '.join(valid)}")
    return str(value)


def numbers(
    path: str,
    values: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    length: int | None = None,
    min_length: int = 0,
    unit: str = "",
    why: str = "",
) -> tuple[float, ...]:
    """A list of finite numbers in a range, of exactly ``length`` (or at least ``min_length``) entries;
    an entry out of range is named ``path[i]``."""
    count = f"{length}" if length is not None else f"at least {min_length}"
    rule = (
        f"must be a list of {count} numbers" + (f" [{unit}]" if unit else "") + (f" ({why})" if why else "")
    )
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):  # ListConfig is a Sequence
        raise fail(path, values, rule)
    items = list(values)
    if (length is not None and len(items) != length) or len(items) < min_length:
        raise fail(path, values, rule)
    return tuple(number(f"{path}[{i}]", v, lo, hi, unit=unit) for i, v in enumerate(items))


def number_or_list(
    path: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    length: int,
    unit: str = "",
    why: str = "",
) -> tuple[float, ...]:
    """One number (repeated ``length`` times) or a list of exactly ``length`` numbers, each in the range
    (e.g. a joint property given for all 12 joints at once or per joint)."""
    if is_number(value):
        return (number(path, value, lo, hi, unit=unit, why=why),) * length
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        rng = interval(lo, hi) + (f" [{unit}]" if unit else "")
        raise fail(path, value, f"must be one number or a list of {length} numbers in {rng}"
                                + (f" ({why})" if why else ""))  # fmt: skip
    return numbers(path, value, lo, hi, length=length, unit=unit, why=why)


__all__ = ["ConfigError", "choice", "fail", "flag", "integer", "interval", "is_number", "number",
           "number_or_list", "numbers"]
