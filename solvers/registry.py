"""Backends by name: every solver installed behind qpsolvers, plus the persistent native ones.

``make_backend("osqp")`` -> :class:`QpsolversBackend` with the accurate settings of ``conf/solver/osqp.yaml``
(the YAML files are the one place where tolerances are chosen; a name without a YAML file gets the
solver's own defaults); ``make_backend("osqp_persistent", eps_abs=1e-7)`` -> the persistent OSQP backend
with that setting changed. Keyword arguments that are constructor parameters of the backend class
(``matrices``, ``bounds``, ``presolve``, ``check``, ``warm_start`` ...) go to the constructor, the rest are
native solver settings. Names this module does not know, or whose package is not installed, raise
:class:`ValueError` listing what is available.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
from pathlib import Path
from typing import Any

from taslel_bench.interfaces import QPBackend

# name -> (module, class, Python module the backend needs)
PERSISTENT: dict[str, tuple[str, str, str]] = {
    "osqp_persistent": ("solvers.osqp_persistent", "OsqpPersistent", "osqp"),
    "piqp_persistent": ("solvers.piqp_persistent", "PiqpPersistent", "piqp"),
    "proxqp_persistent": ("solvers.proxqp_persistent", "ProxqpPersistent", "proxsuite"),
    "daqp_persistent": ("solvers.daqp_persistent", "DaqpPersistent", "daqp"),
}
SPECIAL = ("reference",)
CONF_DIR = Path(__file__).resolve().parent.parent / "conf" / "solver"


def conf_defaults(name: str) -> dict[str, Any]:
    """Constructor arguments from ``conf/solver/<name>.yaml`` (empty when there is no such file)."""
    path = CONF_DIR / f"{name}.yaml"
    if not path.is_file():
        return {}
    from omegaconf import OmegaConf

    cfg = OmegaConf.to_container(OmegaConf.load(path), resolve=True)
    return {k: v for k, v in cfg.items() if not k.startswith("_") and k != "solver"}


def available_backends() -> list[str]:
    """Names :func:`make_backend` accepts on this machine."""
    from solvers.qpsolvers_backend import installed_solvers

    names = installed_solvers()
    names += [n for n, (_, _, dep) in PERSISTENT.items() if importlib.util.find_spec(dep) is not None]
    names += list(SPECIAL)
    return names


def _split(cls: type, settings: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    params: set[str] = set()
    for klass in cls.__mro__:  # constructor keywords of the class and of its bases (**kwargs pass-through)
        if "__init__" in vars(klass):
            params |= set(inspect.signature(klass.__init__).parameters)
    params -= {"self", "settings", "solver", "kwargs", "args"}
    ctor = {k: v for k, v in settings.items() if k in params}
    native = {k: v for k, v in settings.items() if k not in params and k != "settings"}
    native.update(dict(settings.get("settings") or {}))
    return ctor, native


def make_backend(name: str, **settings: Any) -> QPBackend:
    """Build the backend called ``name`` (see module doc)."""
    available = available_backends()
    if name not in available:
        raise ValueError(f"unknown or uninstalled QP backend {name!r}; available: {', '.join(available)}")
    defaults = conf_defaults(name)
    native_defaults = dict(defaults.pop("settings", None) or {})
    settings = {**defaults, **settings}
    if name == "reference":
        from solvers.reference import reference_backend

        return reference_backend(**settings)
    if name in PERSISTENT:
        module, cls_name, _ = PERSISTENT[name]
        cls = getattr(importlib.import_module(module), cls_name)
        ctor, native = _split(cls, settings)
        return cls(settings={**native_defaults, **native}, **ctor)
    from solvers.qpsolvers_backend import QpsolversBackend

    ctor, native = _split(QpsolversBackend, settings)
    return QpsolversBackend(name, settings={**native_defaults, **native}, **ctor)
