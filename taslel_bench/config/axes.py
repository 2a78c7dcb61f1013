"""The sweep axes (``scenario``, ``solver``, ``estimator``) built from their config groups: each class checks
its own arguments; an error it raises comes back as a :class:`ConfigError` naming the field; a QP backend must
solve a trivial QP with its settings before a run starts."""

from __future__ import annotations

from typing import Any

import numpy as np
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from taslel_bench.interfaces import QPBackend, QPProblem
from taslel_bench.util.fields import ConfigError, fail


def _get(cfg: DictConfig, path: str, default: Any = None) -> Any:
    return OmegaConf.select(cfg, path, default=default, throw_on_missing=True)


BUILD_ERRORS = (ValueError, TypeError, OSError)  # what an axis class raises for a bad argument or file


def build_axis(cfg: DictConfig, group: str) -> Any:
    """``instantiate(cfg[group])``. Hydra wraps what the constructor raises in an
    ``InstantiationException`` whose text is the repr of the error; a bad argument or file (ValueError,
    TypeError, OSError) comes back as a :class:`ConfigError` with the axis' own message, which names the
    field (``scenario.coefficients=[]: ...``), prefixed with the group and its target when it does not."""
    try:
        return instantiate(cfg[group])
    except InstantiationException as exc:
        cause = exc.__cause__
        if isinstance(cause, ConfigError) and str(cause).startswith((f"{group}.", f"{group}=")):
            raise cause from None  # already names the field: shown once, where it was raised
        if not isinstance(cause, BUILD_ERRORS):
            raise
        message = str(cause) if str(cause) else type(cause).__name__
        if not message.startswith((f"{group}.", f"{group}=")):
            message = f"{group} ({cfg[group].get('_target_')}): {type(cause).__name__}: {message}"
        raise ConfigError(message) from cause


def build_backend(cfg: DictConfig) -> QPBackend:
    """The ``solver`` axis, checked on a trivial QP of the configured formulation's shape (with the 30
    equality rows of ``full``, without them for ``condensed``): settings that make the backend fail there
    (``solver.settings.eps_abs=-1``: OSQP rejects it at every setup) fail every tick of a run."""
    backend = build_axis(cfg, "solver")
    with_equalities = cfg.filter.formulation == "full"
    solution = backend.solve(probe_problem(with_equalities))
    backend.reset()
    if not solution.ok:
        path = "solver.settings" if "settings" in cfg.solver else "solver"
        raise fail(
            path,
            _get(cfg, path),
            f"{cfg.solver.get('_target_')} fails a trivial 3-variable QP with "
            f"these settings: status {solution.status!r}",
        )
    return backend


def probe_problem(with_equalities: bool) -> QPProblem:
    """min 0.5 |x|^2 + q'x over 3 variables, one active inequality (x0 <= 0.8), a box on x0 and, with
    ``with_equalities``, x0 + x1 + x2 = 1. Solution (with equalities): (0.8, -0.15, 0.35)."""
    n = 3
    P, q = np.eye(n), np.array([-1.0, 0.5, 0.0])
    A = np.ones((1 if with_equalities else 0, n))
    b = np.ones(A.shape[0])
    G, h = np.array([[1.0, 0.0, 0.0]]), np.array([0.8])
    lb, ub = np.array([-2.0, -np.inf, -np.inf]), np.array([2.0, np.inf, np.inf])
    return QPProblem(P, q, A, b, G, h, lb, ub, P != 0, A != 0, G != 0, {"u": slice(0, n)}, ["probe"])
