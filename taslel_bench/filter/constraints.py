"""Constraint families of the ID-CBF-QP. Each is a small object owning a block of rows that it (re)writes
every tick in place, through a compiled kernel (bottom of this module); none allocates per tick.

Decision variables X = (vdot [18], u [12], lambda [12]):
  * vdot: generalised acceleration in Pinocchio's convention (trunk-frame linear/angular, joints);
  * u: joint torques [N·m], core joint order;
  * lambda: contact forces [N] of the four feet (LEGS order) **on the robot, in world axes**, applied at
    the foot-sphere centre. A swing foot's lambda is constrained to zero so the layout never changes.

The layout is fixed (42 variables, 30 equality rows, 20 + 4 inequality rows), which lets persistent
solvers keep one sparsity pattern for a whole episode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import a1
from taslel_bench.robot.model import A1Model
from taslel_bench.terrain.parts import Log
from taslel_bench.terrain.profile import ClearanceProfile
from taslel_bench.util.jit import kernel

NV, NU, NL = a1.NV, a1.N_JOINTS, 3 * a1.N_LEGS
VDOT, U, LAM = slice(0, NV), slice(NV, NV + NU), slice(NV + NU, NV + NU + NL)
N_VARS = NV + NU + NL
INACTIVE_RHS = 1e6  # right-hand side of an inactive inequality row (0 <= 1e6); finite for every solver


@dataclass
class TickInputs:
    """What the constraint families read each tick (model already updated at (q, v))."""

    model: A1Model
    v: np.ndarray  # Pinocchio velocity (18)
    in_stance: np.ndarray  # bool (4,)
    mu: float  # [-] friction coefficient the filter assumes
    swing_phase: np.ndarray  # [-] (4,) progress of each swing in [0, 1]
    swing_phase_rate: float  # [1/s]


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
        for i in range(a1.N_LEGS):
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

    name, n_rows = "friction", 5 * a1.N_LEGS

    def __init__(self, lambda_min_n: float) -> None:
        self.lambda_min_n = lambda_min_n  # [N]
        self.start = 0

    def pattern(self, mask: np.ndarray) -> None:
        for i in range(a1.N_LEGS):
            mask[self.start + 5 * i : self.start + 5 * i + 5, NV + NU + 3 * i : NV + NU + 3 * i + 3] = True

    def labels(self) -> list[str]:
        return [f"{leg}_{k}" for leg in a1.LEGS for k in ("unilateral", "fx+", "fx-", "fy+", "fy-")]

    def init(self, qp: QPProblem) -> None:
        self._stance = np.zeros(a1.N_LEGS, bool)
        self._mu = np.full(a1.N_LEGS, np.nan)
        self._key: tuple[bytes, float] | None = None
        for i in range(a1.N_LEGS):
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
        for i in range(a1.N_LEGS):  # rewrite a foot's rows only when its contact mode or mu changed
            stance = bool(x.in_stance[i])
            if stance != self._stance[i] or (stance and x.mu != self._mu[i]):
                self._write_foot(qp, i, stance, x.mu)


class SwingBarrier:
    """One exponential-CBF row per foot (inactive for stance feet), written by a subclass's kernel, which also
    fills ``h`` [m] and ``h_e`` [m/s] (nan in stance). Each row reads psi(vdot) >= margin with
    psi = hdot_e + a2 h_e [m/s²] the ECBF condition and ``margin_mps2`` >= 0 a robustness margin (0: the
    paper's row). After a solve, :meth:`planned` records psi at the solution's vdot (``psi_planned``): the
    condition the filter believes the next instant satisfies."""

    name, n_rows, suffix = "barrier", a1.N_LEGS, "barrier"

    def __init__(self, alpha1: float, alpha2: float) -> None:
        self.alpha1, self.alpha2 = alpha1, alpha2
        self.start = 0
        self.margin_mps2 = 0.0  # [m/s²] robust margin on psi (set per tick by the filter when robust)
        self.h = np.full(a1.N_LEGS, np.nan)  # [m] barrier value per foot (nan in stance)
        self.h_e = np.full(a1.N_LEGS, np.nan)  # [m/s]
        self.psi_planned = np.full(a1.N_LEGS, np.nan)  # [m/s²] hdot_e + a2 h_e at the solution

    def pattern(self, mask: np.ndarray) -> None:
        mask[self.start : self.start + a1.N_LEGS, VDOT] = True

    def labels(self) -> list[str]:
        return [f"{leg}_{self.suffix}" for leg in a1.LEGS]

    def init(self, qp: QPProblem) -> None:
        qp.G[self.start : self.start + a1.N_LEGS] = 0.0
        qp.h[self.start : self.start + a1.N_LEGS] = INACTIVE_RHS

    def _tighten(self, qp: QPProblem) -> None:
        if self.margin_mps2 > 0.0:
            rows = slice(self.start, self.start + a1.N_LEGS)
            qp.h[rows] -= np.where(np.isfinite(self.h), self.margin_mps2, 0.0)

    def planned(self, qp: QPProblem, vdot: np.ndarray) -> None:
        """psi at the solution: the row's slack plus the margin (nan for stance feet)."""
        _planned_condition(qp.G, qp.h, self.start, vdot, self.margin_mps2, self.h, self.psi_planned)


class SwingClearanceECBF(SwingBarrier):
    """Ground-clearance exponential CBF (paper, "Ground Clearance Enforced by an ECBF"), one row per foot.

    h = p_z - r_foot - z(s) (foot-sphere bottom above the obstacle profile), hdot = v_z - z'(s) sdot,
    h_e = hdot + a1 h, and the row enforces a2 h_e + hdot_e >= 0 with
    hdot_e = (J_z vdot + (J̇v)_z) - z''(s) sdot² + a1 hdot  (s̈ = 0; the chain rule gives sdot², where the
    paper's printed formula has sdot). Written as  -J_z vdot <= a2 h_e + (J̇v)_z - z'' sdot² + a1 hdot.
    Stance feet get an inactive row (0 <= INACTIVE_RHS).
    """

    name, suffix = "ecbf", "clearance"

    def __init__(self, profile: ClearanceProfile, alpha1: float, alpha2: float) -> None:
        super().__init__(alpha1, alpha2)
        self.profile = profile

    def init(self, qp: QPProblem) -> None:
        self._c, self._c1, self._c2 = self.profile.coefficient_arrays()  # z, dz/ds, d²z/ds² (ascending)
        super().init(qp)

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        _ecbf_rows(qp.G, qp.h, self.start, m.foot_pos_in_world, m.foot_vel_in_world, m.foot_jac_in_world,
                   m.foot_jdotv_in_world, x.in_stance, x.swing_phase, x.swing_phase_rate, self._c, self._c1,
                   self._c2, self.alpha1, self.alpha2, a1.FOOT_RADIUS_M, self.h, self.h_e)  # fmt: skip
        self._tighten(qp)


class SwingObstacleECBF(SwingBarrier):
    """Swing-foot clearance of physical round obstacles (logs across the path), one row per foot: the
    paper's exponential CBF with the Euclidean clearance of the foot sphere from the nearest log as h.

    For a log with axis along world y through (x_o, z_o) and radius R, and the foot-sphere centre p (radius
    r): rho = |(p_x - x_o, p_z - z_o)|, n = (p - o)_xz / rho, h = rho - R - r (>= 0 <=> no contact),
    hdot = n . v_xz, hddot = n . a_xz + (|v_xz|² - hdot²) / rho with a = J vdot + J̇v. The row enforces
    hdot_e + a2 h_e >= 0 with h_e = hdot + a1 h:
    -(n_x J_x + n_z J_z) vdot <= a2 h_e + a1 hdot + n . (J̇v)_xz + (|v_xz|² - hdot²) / rho.
    Each swing foot is constrained by its nearest log (smallest h); stance feet get an inactive row.
    """

    name, suffix = "obstacle", "obstacle"

    def __init__(self, obstacles: tuple[Log, ...], alpha1: float, alpha2: float) -> None:
        if not obstacles:
            raise ValueError("SwingObstacleECBF needs at least one obstacle")
        super().__init__(alpha1, alpha2)
        self.obstacles = obstacles
        self._geometry = np.array([[ob.x_m, ob.z_m, ob.radius_m] for ob in obstacles])  # [m] (n_obstacles, 3)

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        _obstacle_rows(qp.G, qp.h, self.start, m.foot_pos_in_world, m.foot_vel_in_world, m.foot_jac_in_world,
                       m.foot_jdotv_in_world, x.in_stance, self._geometry, self.alpha1, self.alpha2,
                       a1.FOOT_RADIUS_M, self.h, self.h_e)  # fmt: skip
        self._tighten(qp)


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


@kernel
def _horner(coeffs, s):
    acc = 0.0
    for j in range(coeffs.shape[0] - 1, -1, -1):
        acc = acc * s + coeffs[j]
    return acc


@kernel
def _inactive_barrier_row(G, hvec, r, h_out, he_out, i):
    """A stance foot's barrier row: 0 <= INACTIVE_RHS, and nan barrier values."""
    for col in range(G.shape[1]):
        G[r, col] = 0.0
    hvec[r] = INACTIVE_RHS
    h_out[i] = np.nan
    he_out[i] = np.nan


@kernel
def _planned_condition(G, hvec, r0, vdot, margin, h, psi):
    """psi[i] = hvec[r0 + i] - G[r0 + i, :NV] vdot + margin for swing feet (finite h), nan for stance."""
    for i in range(h.shape[0]):
        if np.isfinite(h[i]):
            acc = hvec[r0 + i] + margin
            for col in range(NV):
                acc -= G[r0 + i, col] * vdot[col]
            psi[i] = acc
        else:
            psi[i] = np.nan


@kernel
def _ecbf_rows(G, hvec, r0, foot_pos, foot_vel, foot_jac, foot_jdotv, in_stance, swing_phase, sdot, c, c1, c2,
               alpha1, alpha2, foot_radius, h_out, he_out):  # fmt: skip
    """Row r0 + i per foot (see :class:`SwingClearanceECBF`): swing -> -J_z vdot <= a2 h_e + (J̇v)_z
    - z'' sdot² + a1 hdot, with h, h_e written to ``h_out``, ``he_out``; stance -> 0 <= INACTIVE_RHS
    and nan barrier values."""
    nv = foot_jac.shape[2]
    for i in range(foot_jac.shape[0]):
        r = r0 + i
        if in_stance[i]:
            _inactive_barrier_row(G, hvec, r, h_out, he_out, i)
            continue
        s = swing_phase[i]
        dz, ddz = _horner(c1, s), _horner(c2, s)
        h = foot_pos[i, 2] - foot_radius - _horner(c, s)
        hdot = foot_vel[i, 2] - dz * sdot
        h_e = hdot + alpha1 * h
        for col in range(nv):
            G[r, col] = -foot_jac[i, 2, col]
        hvec[r] = alpha2 * h_e + foot_jdotv[i, 2] - ddz * sdot * sdot + alpha1 * hdot
        h_out[i] = h
        he_out[i] = h_e


@kernel
def _obstacle_rows(G, hvec, r0, foot_pos, foot_vel, foot_jac, foot_jdotv, in_stance, geometry, alpha1, alpha2,
                   foot_radius, h_out, he_out):  # fmt: skip
    """Row r0 + i per foot (see :class:`SwingObstacleECBF`); ``geometry`` rows are (x_o, z_o, R) [m]."""
    nv = foot_jac.shape[2]
    for i in range(foot_jac.shape[0]):
        r = r0 + i
        if in_stance[i]:
            _inactive_barrier_row(G, hvec, r, h_out, he_out, i)
            continue
        px, pz = foot_pos[i, 0], foot_pos[i, 2]
        h, dx, dz, rho = np.inf, 0.0, 1.0, 1.0
        for k in range(geometry.shape[0]):
            ddx, ddz = px - geometry[k, 0], pz - geometry[k, 1]
            rr = np.sqrt(ddx * ddx + ddz * ddz)
            hk = rr - geometry[k, 2] - foot_radius
            if hk < h:
                h, dx, dz, rho = hk, ddx, ddz, max(rr, 1e-9)
        nx, nz = dx / rho, dz / rho
        vx, vz = foot_vel[i, 0], foot_vel[i, 2]
        hdot = nx * vx + nz * vz
        curvature = (vx * vx + vz * vz - hdot * hdot) / rho
        h_e = hdot + alpha1 * h
        for col in range(nv):
            G[r, col] = -(nx * foot_jac[i, 0, col] + nz * foot_jac[i, 2, col])
        hvec[r] = alpha2 * h_e + alpha1 * hdot + nx * foot_jdotv[i, 0] + nz * foot_jdotv[i, 2] + curvature
        h_out[i] = h
        he_out[i] = h_e
