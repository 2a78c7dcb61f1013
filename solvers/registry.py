"""Backends by name.

* ``osqp``, ``clarabel``, ``piqp``, ``proxqp``, ``daqp``: the solver as a controller deploys it -- set up
  once per QP layout, values updated every tick, warm started where the solver can (``conf/solver/<name>.yaml``
  holds the settings and the u error they give; ``make_backend("osqp", eps_abs=1e-7)`` changes one);
* ``qpsolvers:<name>``: any solver installed behind qpsolvers through ``qpsolvers.solve_problem``, set up from
  scratch on every call (Hydra: ``solver=qpsolvers solver.name=<name>``; settings:
  :mod:`solvers.qpsolvers_settings`); ``quadprog`` (no persistent interface) is this route under its own name;
* ``reference``: quadprog cross-checked by DAQP (:mod:`solvers.reference`).

Keyword arguments that are constructor parameters of the backend class (``matrices``, ``bounds``,
``presolve``, ``check``, ``warm_start`` ...) go to the constructor, the rest are native solver settings.
Unknown or uninstalled names raise :class:`ValueError` listing what is available; the old names
``<name>_persistent`` raise one saying the new name.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
from pathlib import Path
from typing import Any

from taslel_bench.interfaces import QPBackend, fail

# name -> (module, class, Python module the backend needs)
PERSISTENT: dict[str, tuple[str, str, str]] = {
    "osqp": ("solvers.osqp_persistent", "OsqpPersistent", "osqp"),
    "clarabel": ("solvers.clarabel_persistent", "ClarabelPersistent", "clarabel"),
    "piqp": ("solvers.piqp_persistent", "PiqpPersistent", "piqp"),
    "proxqp": ("solvers.proxqp_persistent", "ProxqpPersistent", "proxsuite"),
    "daqp": ("solvers.daqp_persistent", "DaqpPersistent", "daqp"),
}
QPSOLVERS = "qpsolvers:"  # prefix of the per-call route's names
RENAMED = {f"{name}_persistent": name for name in ("osqp", "piqp", "proxqp", "daqp")}
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


def renamed_message(old: str) -> str:
    new = RENAMED[old]
    return (f"was renamed: solver={new} is now the persistent {new} (set up once per episode, updated every "
            f"tick, warm started); the per-call route is solver=qpsolvers solver.name={new}")  # fmt: skip


def renamed(old: str, **_: Any) -> QPBackend:
    """Hydra target of the old ``conf/solver/<name>_persistent.yaml``: refuses, naming the new name."""
    raise fail("solver", old, renamed_message(old) if old in RENAMED else "is not a solver name")


def available_backends() -> list[str]:
    """Names :func:`make_backend` accepts on this machine."""
    from solvers.qpsolvers_backend import installed_solvers

    per_call = installed_solvers()
    names = [n for n, (_, _, dep) in PERSISTENT.items() if importlib.util.find_spec(dep) is not None]
    names += [n for n in per_call if n not in PERSISTENT]  # quadprog: no persistent interface
    names += [QPSOLVERS + n for n in per_call]
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
    if name in RENAMED:
        raise ValueError(f"QP backend {name!r} {renamed_message(name)}")
    available = available_backends()
    if name not in available:
        raise ValueError(f"unknown or uninstalled QP backend {name!r}; available: {', '.join(available)}")
    if name == "reference":
        from solvers.reference import reference_backend

        return reference_backend(**{**conf_defaults(name), **settings})
    if name in PERSISTENT:
        defaults = conf_defaults(name)
        native_defaults = dict(defaults.pop("settings", None) or {})
        module, cls_name, _ = PERSISTENT[name]
        cls = getattr(importlib.import_module(module), cls_name)
        ctor, native = _split(cls, {**defaults, **settings})
        return cls(settings={**native_defaults, **native}, **ctor)
    from solvers.qpsolvers_backend import QpsolversBackend, qpsolvers_route

    ctor, native = _split(QpsolversBackend, settings)
    return qpsolvers_route(name.removeprefix(QPSOLVERS), settings=native, **ctor)
