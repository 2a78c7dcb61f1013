"""Accurate native settings of every solver on the qpsolvers route (``solver=qpsolvers solver.name=<name>``),
with the u error they give on the filter's QPs (``tests/test_solvers.py`` checks them against the reference).

The route sets the solver up from scratch on every call (``qpsolvers.solve_problem``): what it measures is a
solver as a one-shot QP call, not as a controller deploys it (``solver=<name>`` is that: set up once per
episode, updated per tick). A name without an entry here gets the solver's own defaults.
"""

from __future__ import annotations

from typing import Any

# name -> constructor arguments of QpsolversBackend (settings = native solver settings)
QPSOLVERS_DEFAULTS: dict[str, dict[str, Any]] = {
    # OSQP (ADMM). Default tolerances are off by ~0.05-0.26 N·m in u here (docs/concepts.md, measured facts); eps_abs
    # 1e-6 with eps_rel 0 and solution polishing gives |u - u_ref| ~ 3e-7 N·m on the fixture (5e-7 max).
    "osqp": {"settings": {"eps_abs": 1e-6, "eps_rel": 0.0, "polishing": True, "max_iter": 20000},
             "check": {"primal": 1e-6, "dual": 1e-5, "gap": 1e-5}},
    # Clarabel (interior point). The 1e-5 regularisation makes its KKT system ill-conditioned: at 1e-9
    # tolerances alone |u - u_ref| reaches ~9e-4 N·m (1.2e-3 at 1e-10). Tight iterative refinement plus the
    # exact presolve (drops the swing-foot friction rows that break LICQ) gives ~4e-6 N·m.
    "clarabel": {"presolve": True,
                 "settings": {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-9, "tol_feas": 1e-9,
                              "iterative_refinement_reltol": 1e-14, "iterative_refinement_abstol": 1e-14,
                              "iterative_refinement_max_iter": 50},
                 "check": {"primal": 1e-6, "dual": 1e-5, "gap": 1e-5}},
    # PIQP (proximal interior point, dense interface): 2e-7 N·m.
    "piqp": {"settings": {"eps_abs": 1e-9, "eps_rel": 0.0}, "check": {"primal": 1e-6, "dual": 1e-5, "gap": 1e-5}},
    # ProxQP (dense), cold started. The duality-gap test is on (docs/concepts.md, measured facts: without it ProxQP can
    # stop early with u wrong by N·m): 2e-8 N·m.
    "proxqp": {"settings": {"eps_abs": 1e-9, "eps_rel": 0.0, "check_duality_gap": True,
                            "eps_duality_gap_abs": 1e-9, "eps_duality_gap_rel": 0.0},
               "check": {"primal": 1e-6, "dual": 1e-5, "gap": 1e-5}},
    # DAQP (dual active set): exact up to round-off (~1e-13 N·m) at its defaults; a primal-residual check is
    # enough to catch garbage (the KKT check costs about as much as the solve).
    "daqp": {"settings": {}, "check": {"primal": 1e-6, "level": "primal"}},
    # quadprog (Goldfarb-Idnani): exact (~1e-13 N·m); the presolve drops the swing-foot friction rows implied
    # by lambda_i = 0 (quadprog aborts with "constraints are inconsistent" on them, solvers/presolve.py).
    "quadprog": {"settings": {}, "presolve": True, "check": {"primal": 1e-6, "level": "primal"}},
}


def qpsolvers_defaults(name: str) -> dict[str, Any]:
    """A copy of the constructor arguments for ``name`` (empty for a solver without an entry)."""
    entry = QPSOLVERS_DEFAULTS.get(name, {})
    return {k: (dict(v) if isinstance(v, dict) else v) for k, v in entry.items()}


__all__ = ["QPSOLVERS_DEFAULTS", "qpsolvers_defaults"]
