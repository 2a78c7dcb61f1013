"""Backends by name: every solver installed behind qpsolvers, plus the persistent native ones.

``make_backend("osqp", eps_abs=1e-6)`` -> :class:`QpsolversBackend` with those native settings;
``make_backend("osqp_persistent", eps_abs=1e-6)`` -> the persistent OSQP backend. Keyword arguments that
are constructor parameters of the backend class (``matrices``, ``bounds``, ``presolve``, ``check``, ...)
go to the constructor, the rest are native solver settings. Names this module does not know, or whose
package is not installed, raise :class:`ValueError` listing what is available.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
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
    if name == "reference":
        from solvers.reference import reference_backend

        return reference_backend(**settings)
    if name in PERSISTENT:
        module, cls_name, _ = PERSISTENT[name]
        cls = getattr(importlib.import_module(module), cls_name)
        ctor, native = _split(cls, settings)
        return cls(settings=native, **ctor)
    from solvers.qpsolvers_backend import QpsolversBackend

    ctor, native = _split(QpsolversBackend, settings)
    return QpsolversBackend(name, settings=native, **ctor)
