"""The tight reference: two unrelated algorithms that must agree.

quadprog (Goldfarb-Idnani dual active set, with the presolve it needs) is checked against DAQP (a primal
active-set method on the dual LDP, separate code base); both are exact up to round-off on this QP and agree
to ~1e-13 N·m. Both answers must also pass tight KKT checks (primal 1e-8, dual 1e-8, gap 1e-8, so
|u - u*| <= sqrt(2e-8) ~ 1.4e-4 N·m is *certified*, and far smaller in practice). The reference returns
quadprog's answer, and a non-solved status when the two disagree on u by more than ``agree_u_nm`` -- so
a wrong reference cannot silently pass as the truth every other backend is measured against.

(Clarabel was tried as the second opinion: even at 1e-12 tolerances it stays ~3e-7 N·m off on some
QPs, the 1e-5 regularisation makes the KKT system ill-conditioned for an interior-point method.)
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from solvers.base import BackendSolution
from solvers.qpsolvers_backend import QpsolversBackend
from taslel_bench.interfaces import QPBackend, QPProblem, number

TIGHT_CHECK = {"primal": 1e-8, "dual": 1e-8, "gap": 1e-8}


class CrossChecked:
    """Solve with ``primary`` and ``secondary``; return ``primary``'s answer only if both agree on u."""

    def __init__(self, primary: QPBackend, secondary: QPBackend, agree_u_nm: float = 1e-8) -> None:
        self.primary, self.secondary = primary, secondary
        self.agree_u_nm = number("solver.agree_u_nm", agree_u_nm, 0.0, lo_open=True, unit="N·m")
        self.name = f"reference({primary.name}+{secondary.name})"

    def reset(self) -> None:
        self.primary.reset()
        self.secondary.reset()

    def describe(self) -> dict[str, object]:
        return {
            "name": self.name,
            "kind": "cross-checked reference",
            "agree_u_nm": self.agree_u_nm,
            "primary": self.primary.describe(),
            "secondary": self.secondary.describe(),
        }

    def solve(self, problem: QPProblem) -> BackendSolution:
        t0 = time.perf_counter()
        a = self.primary.solve(problem)
        b = self.secondary.solve(problem)
        elapsed = time.perf_counter() - t0
        out = a if isinstance(a, BackendSolution) else BackendSolution(a.x, a.status, a.solve_time_s)
        out.overhead_s = elapsed - out.solve_time_s
        if not a.ok:
            return out
        if not b.ok:
            out.status = f"reference unconfirmed: {self.secondary.name} {b.status}"
            return out
        u = problem.layout.get("u", slice(None))
        du = float(np.max(np.abs(a.x[u] - b.x[u])))
        if du > self.agree_u_nm:
            out.status = f"reference disagreement: |du| = {du:.1e} N·m"
        return out


def reference_backend(agree_u_nm: float = 1e-8, **_: Any) -> CrossChecked:
    """quadprog checked by DAQP (see module doc)."""
    return CrossChecked(
        QpsolversBackend("quadprog", check=TIGHT_CHECK),
        QpsolversBackend("daqp", check=TIGHT_CHECK),
        agree_u_nm,
    )
