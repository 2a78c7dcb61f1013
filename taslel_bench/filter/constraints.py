"""The ID-CBF-QP's fixed constraint families: equations of motion, stance contact (or zero swing force) and
the friction pyramid. Each is a small object owning a block of rows that it (re)writes every tick in place,
through a compiled kernel (bottom of this module); none allocates per tick. The barrier families (one
exponential CBF each) are in :mod:`taslel_bench.filter.barriers`. Variables: :mod:`taslel_bench.filter.layout`.
"""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.layout import INACTIVE_RHS, LAM, NL, NU, NV, VDOT, TickInputs, U
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import quadruped as quad
from taslel_bench.util.jit import kernel


class EqualityFamily:
    name = "eq"
    n_rows = 0
    start = 0

    def pattern(self, mask: np.ndarray) -> None: ...

    def init(self, qp: QPProblem) -> None:
        """Write the rows' constant entries once (the QP arrays are reused every tick)."""

    def write(self, qp: QPProblem, x: TickInputs) -> None: ...


class EquationsOfMotion(EqualityFamily):
    """M vdot - B u - Jc' lambda = -h  (18 rows); B selects the 12 actuated joints."""

    name, n_rows = "eom", NV

    def pattern(self, mask: np.ndarray) -> None:
        rows = slice(self.start, self.start + NV)
        mask[rows, VDOT] = True
        mask[rows, U] = np.vstack([np.zeros((6, NU), bool), np.eye(NU, dtype=bool)])
        mask[rows, LAM] = True

    def init(self, qp: QPProblem) -> None:
        qp.A[self.start + 6 : self.start + NV, U] = -np.eye(NU)

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        _eom_rows(qp.A, qp.b, self.start, m.M, m.foot_jac_in_world, m.h)


class ContactOrSwing(EqualityFamily):
    """Per foot, 3 rows: stance -> J_i vdot = -J̇_i v - k_v J_i v (the paper's eq. 3 for k_v = 0: the foot
    centre does not accelerate; k_v > 0 [1/s] also brakes a foot that touched down sliding);
    swing -> lambda_i = 0."""

    name, n_rows = "contact", NL

    def __init__(self, velocity_gain: float = 0.0) -> None:
        self.velocity_gain = velocity_gain  # [1/s]

    def pattern(self, mask: np.ndarray) -> None:
        for i in range(quad.N_LEGS):
            rows = slice(self.start + 3 * i, self.start + 3 * i + 3)
            mask[rows, VDOT] = True
            mask[rows, NV + NU + 3 * i : NV + NU + 3 * i + 3] = np.eye(3, dtype=bool)

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        _contact_rows(qp.A, qp.b, self.start, m.foot_jac_in_world, m.foot_jdotv_in_world, m.foot_vel_in_world,
                      x.in_stance, self.velocity_gain)  # fmt: skip


class FrictionCone:
    """Per foot, 5 rows of G x <= h: unilateral -lambda_z <= -lambda_min and the square pyramid
    |lambda_x|, |lambda_y| <= mu_tilde lambda_z with mu_tilde = mu / sqrt(2) (inscribed in the Coulomb
    cone, as in the paper). A swing foot's rows are inactive zero rows (0 <= INACTIVE_RHS): its lambda is
    already fixed to 0 by the equality rows, and duplicating that as inequalities makes some solvers
    (quadprog, interior-point methods) see dependent constraints."""

    name, n_rows = "friction", 5 * quad.N_LEGS

    def __init__(self, lambda_min_n: float) -> None:
        self.lambda_min_n = lambda_min_n  # [N]
        self.start = 0

    def pattern(self, mask: np.ndarray) -> None:
        for i in range(quad.N_LEGS):
            mask[self.start + 5 * i : self.start + 5 * i + 5, NV + NU + 3 * i : NV + NU + 3 * i + 3] = True

    def labels(self) -> list[str]:
        return [f"{leg}_{k}" for leg in quad.LEGS for k in ("unilateral", "fx+", "fx-", "fy+", "fy-")]

    def init(self, qp: QPProblem) -> None:
        self._stance = np.zeros(quad.N_LEGS, bool)
        self._mu = np.full(quad.N_LEGS, np.nan)
        self._key: tuple[bytes, float] | None = None
        for i in range(quad.N_LEGS):
            self._write_foot(qp, i, False, np.nan)

    def _write_foot(self, qp: QPProblem, i: int, stance: bool, mu: float) -> None:
        r, c = self.start + 5 * i, NV + NU + 3 * i
        block = qp.G[r : r + 5, c : c + 3]
        if stance:
            mu_t = mu / np.sqrt(2.0)
            block[:] = [[0.0, 0.0, -1.0], [1.0, 0.0, -mu_t], [-1.0, 0.0, -mu_t], [0.0, 1.0, -mu_t], [0.0, -1.0, -mu_t]]
            qp.h[r : r + 5] = (-self.lambda_min_n, 0.0, 0.0, 0.0, 0.0)
        else:
            block[:] = 0.0
            qp.h[r : r + 5] = INACTIVE_RHS
        self._stance[i], self._mu[i] = stance, mu

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        key = (x.in_stance.tobytes(), x.mu)
        if key == self._key:
            return
        self._key = key
        for i in range(quad.N_LEGS):  # rewrite a foot's rows only when its contact mode or mu changed
            stance = bool(x.in_stance[i])
            if stance != self._stance[i] or (stance and x.mu != self._mu[i]):
                self._write_foot(qp, i, stance, x.mu)


# --------------------------------------------------------------------------------- compiled row writers
# Column blocks of X are fixed (VDOT, U, LAM above); each kernel writes one family's rows in place.


@kernel
def _eom_rows(A, b, r0, M, foot_jac, h):
    """Rows r0 .. r0 + NV of ``M vdot - B u - sum_i J_i' lambda_i = -h`` (the constant -B block is
    written once by :meth:`EquationsOfMotion.init`)."""
    nv, lam0 = M.shape[0], NV + NU
    for r in range(nv):
        for c in range(nv):
            A[r0 + r, c] = M[r, c]
        for i in range(foot_jac.shape[0]):
            for k in range(3):
                A[r0 + r, lam0 + 3 * i + k] = -foot_jac[i, k, r]
        b[r0 + r] = -h[r]


@kernel
def _contact_rows(A, b, r0, foot_jac, foot_jdotv, foot_vel, in_stance, velocity_gain):
    """Per foot i, rows r0 + 3i .. r0 + 3i + 3: stance -> J_i vdot = -(J̇_i v + k_v J_i v);
    swing -> lambda_i = 0."""
    nv, lam0 = foot_jac.shape[2], NV + NU
    for i in range(foot_jac.shape[0]):
        stance = in_stance[i]
        for k in range(3):
            r = r0 + 3 * i + k
            for c in range(nv):
                A[r, c] = foot_jac[i, k, c] if stance else 0.0
            A[r, lam0 + 3 * i + k] = 0.0 if stance else 1.0
            b[r] = -(foot_jdotv[i, k] + velocity_gain * foot_vel[i, k]) if stance else 0.0
