"""``model.from``: a model file whose values set the ``model`` group's keys (``model=identified model.from=<file>``,
the file ``python -m taslel_bench.identify`` writes).

The file is YAML with one top-level key, ``model``, a mapping of ``model.*`` keys (not ``urdf`` or ``from``); its
values are checked by the rules of ``model.*`` (the plant perturbation's shared fields, the schema's ranges), each
error naming ``model.from=<file>`` and the key. A key the file sets and the command line sets to another value is
refused (one place per value). :func:`model_values` is the group with the file applied, what the controller's
model is built from (:func:`taslel_bench.config.settings.model_options`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from omegaconf import DictConfig

from taslel_bench.config.schema import ModelConfig
from taslel_bench.plant.perturbation import check_trunk_and_joints
from taslel_bench.util.fields import ConfigError, fail, plain_dict
from taslel_bench.util.params import check_value, schema_fields, spec_of

KEY = "from"
PLACEHOLDER = "<model file>"  # conf/model/identified.yaml's value (a ``???`` would not override the schema's null)
NOT_IN_FILE = ("urdf", KEY)  # the file sets values of the model, not which model file or URDF to read


def file_keys() -> list[str]:
    """The ``model.*`` keys a model file may set."""
    return [f.name for f in dataclasses.fields(ModelConfig) if f.name not in NOT_IN_FILE]


def load_model_file(path: Any) -> dict[str, Any]:
    """The checked values of the model file at ``path`` ({key: value}, joint fields and vectors as the
    config writes them); :class:`ConfigError` naming ``model.from`` and the file for a missing, unreadable or
    malformed file, an unknown key or a value out of its range."""
    where = f"model.from={str(path)!r}"
    if str(path) == PLACEHOLDER:
        raise ConfigError(f"{where}: model=identified reads the model from a file: add model.from=<file> (a YAML "
                          "model file, e.g. written by python -m taslel_bench.identify)")
    file = Path(str(path))
    if not file.is_file():
        raise ConfigError(f"{where}: no such file (a YAML model file, e.g. written by python -m "
                          "taslel_bench.identify)")
    try:
        data = yaml.safe_load(file.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f"{where}: not readable as YAML: {' '.join(str(exc).split())}") from exc
    if not isinstance(data, dict) or set(data) != {"model"} or not isinstance(data["model"], dict):
        raise ConfigError(f"{where}: must hold one mapping, `model:` with model.* keys; got "
                          f"{type(data).__name__ if not isinstance(data, dict) else sorted(map(str, data))}")
    values: dict[str, Any] = data["model"]
    check_file_values(where, values)
    return values


def check_file_values(where: str, values: dict[str, Any]) -> None:
    """The rules of ``model.*`` on a file's values; errors read ``model.from='<file>': model.<key>=<value>: ...``."""
    valid = file_keys()
    if unknown := [k for k in values if k not in valid]:
        raise ConfigError(f"{where}: model.{unknown[0]}: unknown key of a model file; valid: {', '.join(valid)}")
    prefix = f"{where}: model"
    check_trunk_and_joints(prefix, values)
    for f, tp, optional in schema_fields(ModelConfig):
        if f.name in values and tp in (int, float, bool) and not (values[f.name] is None and optional):
            check_value(f"{prefix}.{f.name}", values[f.name], tp, spec_of(f), lambda key: None)


def model_values(cfg: DictConfig) -> dict[str, Any]:
    """The ``model`` group as {key: value} with ``model.from``'s file applied (``from`` itself left out)."""
    values = plain_dict(cfg.model, "model")
    path = values.pop(KEY, None)
    if path is None:
        return values
    loaded = load_model_file(path)
    defaults = ModelConfig()
    for key, value in loaded.items():
        if not _same(values[key], getattr(defaults, key)) and not _same(values[key], value):
            raise fail(f"model.{key}", values[key], f"is set by model.from={str(path)!r} too (to {value!r}); set it "
                                                    "in one place")
    return {**values, **loaded}


def _same(a: Any, b: Any) -> bool:
    """Equal values, a joint field's one number equal to 12 equal numbers."""
    try:
        x, y = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
        return bool(np.array_equal(x, y))
    except (TypeError, ValueError):
        return a == b
