"""Checks of native solver settings by their names, before a solver sees them.

Solvers validate their own settings only at setup, inside every tick's solve, where a bad value becomes a
failed status on every tick (``eps_abs=-1``: OSQP refuses each setup) or, worse, a silently different
method. What can be said without knowing the solver is checked here, naming ``solver.settings.<key>``:

* every number is finite;
* a tolerance (a key starting with ``eps`` or containing ``tol``: OSQP/PIQP/ProxQP ``eps_abs``,
  Clarabel ``tol_gap_abs``, DAQP ``primal_tol`` ...) is >= 0;
* an iteration cap (``max_iter``, ``iter_limit``, ``maxiter``, ``iterative_refinement_max_iter``) is an
  integer >= 1;
* a time limit (a key containing ``time_limit``) is > 0.

The rest (unknown keys, solver-specific ranges) is left to the solver; the harness refuses a backend that
fails a trivial QP before a run (:func:`taslel_bench.config.axes.build_backend`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from taslel_bench.interfaces import fail, integer, is_number, number

ITERATION_CAPS = ("max_iter", "iter_limit", "maxiter")


def is_tolerance(key: str) -> bool:
    """A convergence tolerance by its name (see module doc)."""
    return key.startswith("eps") or "tol" in key


def check_settings(settings: Mapping[str, Any] | None, path: str = "solver.settings") -> dict[str, Any]:
    """A plain dict of ``settings`` after the by-name checks of the module doc (raises naming
    ``path.key``)."""
    if settings is None:
        return {}
    if not isinstance(settings, Mapping):
        raise fail(path, settings, "must be a mapping of native solver settings")
    out = dict(settings)
    for key, value in out.items():
        _check_one(f"{path}.{key}", str(key), value)
    return out


def _check_one(path: str, key: str, value: Any) -> None:
    if not is_number(value):  # bools, strings, None: the solver's business
        return
    if any(cap in key for cap in ITERATION_CAPS):
        integer(path, value, 1)
    elif "time_limit" in key:
        number(path, value, 0.0, lo_open=True, unit="s")
    elif is_tolerance(key):
        number(path, value, 0.0, why="a tolerance")
    else:
        number(path, value)  # finite


__all__ = ["check_settings", "is_tolerance"]
