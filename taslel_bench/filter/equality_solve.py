"""Solve the filter's equality rows for (vdot, lambda): A_free Y = R, compiled.

The equality rows of the ID-CBF-QP (:mod:`taslel_bench.filter.constraints`: 18 equations of motion, then 3
contact-or-swing rows per foot) determine (vdot, lambda) from u. ``A_free`` is their (vdot, lambda)
block (30 x 30, columns ordered vdot then lambda); the filter solves A_free Y = R for one right-hand side
(the nominal target) or 13 (the condensed formulation's [z0, Z]).

The robot is a floating base with four 3-joint legs, so A_free has a fixed block structure: the rows of leg
i (its 3 joint rows of the equations of motion and its foot's 3 contact rows) touch only the base
accelerations and that leg's 6 unknowns y_i = (vdot of its joints, lambda_i) -- M has no leg-to-leg
entries, foot i's Jacobian no other leg's columns. :func:`solve_tree` eliminates each y_i with a 6x6 LU
and solves the 6x6 Schur complement for the base (about 8k flops instead of ~20k for a dense LU). Each
6x6 leg block is singular only when a stance leg's own 3x3 Jacobian is (a fully stretched leg); then
the dense LU with partial pivoting of the whole block is used instead. Both give the same Y to rounding
(tested).
"""

from __future__ import annotations

import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.jit import kernel

NV, NU, NL = quad.NV, quad.N_JOINTS, 3 * quad.N_LEGS
N_BASE = 6  # floating-base velocity coordinates (first in vdot)
LAM0 = NV + NU  # first lambda column of X = (vdot, u, lambda)


class FreeBlockSolver:
    """Workspace for :func:`solve_free` with ``n_rhs`` right-hand sides (no allocation per call).

    ``eom_row0`` / ``contact_row0``: first rows of the equations of motion (18 rows, base first) and of the
    contact-or-swing rows (3 per foot, LEGS order) in A."""

    def __init__(self, n_rhs: int, eom_row0: int, contact_row0: int) -> None:
        n_legs, m_eq = quad.N_LEGS, NV + NL
        self.rows = np.array([eom_row0, contact_row0], np.int64)
        self.workspace = (
            np.zeros((n_legs, 6, 6)),  # K: leg blocks, LU-factorised
            np.zeros((n_legs, 6), np.int64),  # their pivots
            np.zeros((n_legs, 6, N_BASE)),  # W = K^-1 C (coupling to the base accelerations)
            np.zeros((n_legs, 6, n_rhs)),  # V = K^-1 R_i
            np.zeros((N_BASE, N_BASE)),  # S: Schur complement of the base
            np.zeros((N_BASE, n_rhs)),  # T: its right-hand sides -> base accelerations
            np.zeros(N_BASE, np.int64),  # its pivots
            np.zeros((m_eq, m_eq)),  # dense fallback: A_free, LU-factorised
            np.zeros(m_eq, np.int64),  # its pivots
        )


@kernel
def lu_factor(a, piv):
    """LU factorisation with partial pivoting of the square ``a`` in place (LAPACK dgetrf's layout:
    unit-lower L below the diagonal, U on and above, row k swapped with piv[k]). False if singular."""
    n = a.shape[0]
    for k in range(n):
        p, best = k, abs(a[k, k])
        for i in range(k + 1, n):
            if abs(a[i, k]) > best:
                p, best = i, abs(a[i, k])
        piv[k] = p
        if best == 0.0:
            return False
        if p != k:
            for j in range(n):
                a[k, j], a[p, j] = a[p, j], a[k, j]
        inv = 1.0 / a[k, k]
        for i in range(k + 1, n):
            f = a[i, k] * inv
            a[i, k] = f
            if f != 0.0:
                for j in range(k + 1, n):
                    a[i, j] -= f * a[k, j]
    return True


@kernel
def lu_solve(a, piv, rhs):
    """Solve (LU) X = rhs in place for every column of ``rhs`` (``a``, ``piv`` from :func:`lu_factor`)."""
    n, m = rhs.shape
    for k in range(n):
        p = piv[k]
        if p != k:
            for j in range(m):
                rhs[k, j], rhs[p, j] = rhs[p, j], rhs[k, j]
    for i in range(n):  # forward: unit lower
        for k in range(i):
            f = a[i, k]
            if f != 0.0:
                for j in range(m):
                    rhs[i, j] -= f * rhs[k, j]
    for i in range(n - 1, -1, -1):  # backward: upper
        for k in range(i + 1, n):
            f = a[i, k]
            if f != 0.0:
                for j in range(m):
                    rhs[i, j] -= f * rhs[k, j]
        inv = 1.0 / a[i, i]
        for j in range(m):
            rhs[i, j] *= inv


@kernel
def _leg_row(i, a, eom0, contact0):
    """Row of A for local row ``a`` (0-2: leg i's joint rows of the EoM, 3-5: foot i's contact rows)."""
    return eom0 + N_BASE + 3 * i + a if a < 3 else contact0 + 3 * i + a - 3


@kernel
def _leg_col(i, c):
    """Column of X for leg i's local unknown ``c`` (0-2: its joint accelerations, 3-5: lambda_i)."""
    return N_BASE + 3 * i + c if c < 3 else LAM0 + 3 * i + c - 3


@kernel
def _free_row(i, c):
    """Row of Y (order: vdot, then lambda) for leg i's local unknown ``c``."""
    return N_BASE + 3 * i + c if c < 3 else NV + 3 * i + c - 3


@kernel
def solve_tree(A, rhs, eom0, contact0, K, piv, W, V, S, T, pivS):
    """Overwrite ``rhs`` (rows ordered as A's equality rows) with Y = A_free^-1 rhs (rows ordered vdot,
    lambda) by eliminating each leg's 6 unknowns, then the base (module doc). False if a leg block or the
    base Schur complement is singular (``rhs`` is then unchanged)."""
    m = rhs.shape[1]
    n_legs = K.shape[0]
    for i in range(n_legs):
        for a in range(6):
            r = _leg_row(i, a, eom0, contact0)
            for c in range(6):
                K[i, a, c] = A[r, _leg_col(i, c)]
            for c in range(N_BASE):
                W[i, a, c] = A[r, c]
            for j in range(m):
                V[i, a, j] = rhs[r, j]
        if not lu_factor(K[i], piv[i]):
            return False
        d_min, d_max = np.inf, 0.0  # a nearly singular leg block: leave it to the pivoted dense LU
        for k in range(6):
            d_min, d_max = min(d_min, abs(K[i, k, k])), max(d_max, abs(K[i, k, k]))
        if d_min < 1e-10 * d_max:
            return False
        lu_solve(K[i], piv[i], W[i])
        lu_solve(K[i], piv[i], V[i])
    for a in range(N_BASE):  # base rows of the EoM: S = B0 - sum_i D_i W_i, T = R_b - sum_i D_i V_i
        r = eom0 + a
        for c in range(N_BASE):
            S[a, c] = A[r, c]
        for j in range(m):
            T[a, j] = rhs[r, j]
        for i in range(n_legs):
            for k in range(6):
                d = A[r, _leg_col(i, k)]
                if d != 0.0:
                    for c in range(N_BASE):
                        S[a, c] -= d * W[i, k, c]
                    for j in range(m):
                        T[a, j] -= d * V[i, k, j]
    if not lu_factor(S, pivS):
        return False
    lu_solve(S, pivS, T)  # base accelerations
    for a in range(N_BASE):
        for j in range(m):
            rhs[a, j] = T[a, j]
    for i in range(n_legs):  # y_i = V_i - W_i vdot_base
        for k in range(6):
            out = _free_row(i, k)
            for j in range(m):
                acc = V[i, k, j]
                for c in range(N_BASE):
                    acc -= W[i, k, c] * T[c, j]
                rhs[out, j] = acc
    return True


@kernel
def solve_dense(A, rhs, A_free, piv):
    """Y = A_free^-1 rhs in place by a dense LU with partial pivoting of the (vdot, lambda) columns of A.
    False if singular."""
    for r in range(A.shape[0]):
        for c in range(NV):
            A_free[r, c] = A[r, c]
        for c in range(NL):
            A_free[r, NV + c] = A[r, LAM0 + c]
    if not lu_factor(A_free, piv):
        return False
    lu_solve(A_free, piv, rhs)
    return True


@kernel
def solve_free(A, rhs, rows, ws):
    """Y = A_free^-1 rhs in place (rows of Y: vdot, then lambda): :func:`solve_tree`, else
    :func:`solve_dense`; ``rows``, ``ws`` from :class:`FreeBlockSolver`. False if A_free is singular."""
    K, piv, W, V, S, T, pivS, A_free, piv_dense = ws
    if solve_tree(A, rhs, rows[0], rows[1], K, piv, W, V, S, T, pivS):
        return True
    return solve_dense(A, rhs, A_free, piv_dense)
