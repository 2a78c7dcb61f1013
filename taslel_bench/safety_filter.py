"""ID-CBF-QP safety filter (paper, "Inverse Dynamics Formulation with CBF Constraints").

    min_X 0.5 ||u - u_nom||² + 0.5 eps (||vdot - vdot_nom||² + ||lambda - lambda_nom||²)
    s.t. equations of motion, stance-contact acceleration, unilateral + friction pyramid (mu / sqrt 2),
         torque limits (as bounds on u), swing-foot ground-clearance ECBF rows.

:meth:`SafetyFilter.build` writes the QP into one preallocated :class:`QPProblem`; a backend
(:class:`taslel_bench.interfaces.QPBackend`) solves it; :meth:`SafetyFilter.filter` does both and applies
the failure policy. Build time and solve time are measured separately.

Regularisation: the equality constraints determine (vdot, lambda) uniquely from u, so eps only makes P
positive definite for the solvers. Regularising towards zero biases u by eps * (B'vdot + D'lambda) — up
to ~4 N·m at eps = 1e-5 on swing legs (measured: swing-joint accelerations reach 1e3 rad/s²). The default
target is therefore (vdot_nom, lambda_nom), the prediction for u = u_nom (one 30x30 solve per tick): when
no inequality binds, u = u_nom exactly for any eps. ``regularization_target: zero`` gives the textbook form.

Formulation (``formulation``): ``full`` (default, the paper's) hands the backend the QP in X = (vdot, u,
lambda). ``condensed`` hands it the *same* minimisation with the 30 equality rows eliminated: one LU of
the (vdot, lambda) columns of the equality rows gives (vdot, lambda) = z0 - Z u, so the backend sees a
12-variable QP in u (P = I + eps Z'Z, the G rows and the torque bounds), and (vdot, lambda) is recovered
from its u. Both have the same minimiser (tested to 1e-6 N·m); the full QP is still written every tick
(``problem``, what ``record.qps`` saves). ``condensed`` exists because the backend's cost grows with the
rows and variables it sees.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack

from taslel_bench import robot
from taslel_bench.constraints import (
    LAM,
    N_VARS,
    NL,
    NV,
    VDOT,
    ContactOrSwing,
    EqualityFamily,
    EquationsOfMotion,
    FrictionCone,
    SwingClearanceECBF,
    TickInputs,
    U,
)
from taslel_bench.interfaces import ClearanceProfile, QPBackend, QPProblem, QPSolution

FALLBACKS = ("nominal", "hold_last")
REGULARIZATION_TARGETS = ("nominal", "zero")
FORMULATIONS = ("full", "condensed")


@dataclass(frozen=True)
class FilterSettings:
    enabled: bool = True
    regularization: float = 1e-5  # eps on vdot and lambda (keeps P positive definite)
    regularization_target: str = "nominal"  # "nominal" (vdot_nom, lambda_nom) or "zero"
    lambda_min_n: float = 1.0  # [N] minimum normal force of a stance foot
    contact_velocity_gain: float = 0.0  # [1/s] k_v in J vdot + J̇v = -k_v J v (0 = paper's eq. 3)
    torque_limit_nm: float = robot.TORQUE_LIMIT_NM  # [N·m]
    ecbf_enabled: bool = True  # only used when the scenario provides a clearance profile
    ecbf_alpha1: float = 20.0  # [1/s]
    ecbf_alpha2: float = 20.0  # [1/s]
    fallback: str = "nominal"  # on QP failure: pass u_nom ("nominal") or the last filtered u ("hold_last")
    stance_source: str = "schedule"  # "schedule" (gait) or "contact" (plant contact flags)
    formulation: str = "full"  # "full" (backend sees X = (vdot, u, lambda)) or "condensed" (u only)


@dataclass
class FilterResult:
    u: np.ndarray  # [N·m] torques sent to the plant (core order)
    lam: np.ndarray  # [N] (12,) predicted contact forces on the robot, world axes (nan on failure)
    vdot: np.ndarray  # (18,) predicted acceleration (nan on failure)
    status: str
    used_fallback: bool
    build_time_s: float
    solve: QPSolution | None = field(default=None)


class SafetyFilter:
    """Owns the QP layout and the constraint families; one instance per episode."""

    def __init__(
        self, settings: FilterSettings, backend: QPBackend, profile: ClearanceProfile | None = None
    ) -> None:
        if settings.fallback not in FALLBACKS:
            raise ValueError(f"filter.fallback={settings.fallback!r}; valid: {', '.join(FALLBACKS)}")
        if settings.regularization_target not in REGULARIZATION_TARGETS:
            raise ValueError(
                f"filter.regularization_target={settings.regularization_target!r}; "
                f"valid: {', '.join(REGULARIZATION_TARGETS)}"
            )
        if settings.formulation not in FORMULATIONS:
            raise ValueError(f"filter.formulation={settings.formulation!r}; valid: {', '.join(FORMULATIONS)}")
        self.settings = settings
        self.backend = backend
        self.eq_families: list[EqualityFamily] = [EquationsOfMotion(), ContactOrSwing(settings.contact_velocity_gain)]
        self.friction = FrictionCone(settings.lambda_min_n)
        self.ecbf = (
            SwingClearanceECBF(profile, settings.ecbf_alpha1, settings.ecbf_alpha2)
            if (profile is not None and settings.ecbf_enabled)
            else None
        )
        ineq = [self.friction] + ([self.ecbf] if self.ecbf is not None else [])
        m_eq = 0
        for fam in self.eq_families:
            fam.start, m_eq = m_eq, m_eq + fam.n_rows
        m_in = 0
        for fam in ineq:
            fam.start, m_in = m_in, m_in + fam.n_rows
        self.ineq_families = ineq
        self.problem = self._allocate(m_eq, m_in)
        for fam in [*self.eq_families, *self.ineq_families]:
            fam.init(self.problem)
        self._A_free = np.zeros((m_eq, NV + NL), order="F")  # columns of (vdot, lambda): determined by u
        self._last_u: np.ndarray | None = None
        self.condensed: QPProblem | None = None
        if settings.formulation == "condensed":
            self._allocate_condensed(m_eq, m_in)

    def _allocate(self, m_eq: int, m_in: int) -> QPProblem:
        s = self.settings
        P = np.zeros((N_VARS, N_VARS))
        np.fill_diagonal(P, s.regularization)
        P[U, U] = np.eye(robot.N_JOINTS)
        lb = np.full(N_VARS, -np.inf)
        ub = np.full(N_VARS, np.inf)
        lb[U], ub[U] = -s.torque_limit_nm, s.torque_limit_nm
        A_pattern = np.zeros((m_eq, N_VARS), bool)
        G_pattern = np.zeros((m_in, N_VARS), bool)
        for fam in self.eq_families:
            fam.pattern(A_pattern)
        for fam in self.ineq_families:
            fam.pattern(G_pattern)
        labels = [lab for fam in self.ineq_families for lab in fam.labels()]
        return QPProblem(
            P=P,
            q=np.zeros(N_VARS),
            A=np.zeros((m_eq, N_VARS)),
            b=np.zeros(m_eq),
            G=np.zeros((m_in, N_VARS)),
            h=np.zeros(m_in),
            lb=lb,
            ub=ub,
            P_pattern=P != 0.0,
            A_pattern=A_pattern,
            G_pattern=G_pattern,
            layout={"vdot": VDOT, "u": U, "lambda": LAM},
            row_labels=labels,
        )

    @property
    def backend_problem(self) -> QPProblem:
        """The QP the backend is given: :attr:`condensed` (formulation "condensed") or :attr:`problem`."""
        return self.condensed if self.condensed is not None else self.problem

    def _allocate_condensed(self, m_eq: int, m_in: int) -> None:
        s, nu = self.settings, robot.N_JOINTS
        self._rhs = np.zeros((m_eq, 1 + nu), order="F")  # [b, A_u] -> LU solve -> [z0, Z]
        self._G_free = np.zeros((m_in, NV + NL))  # G columns of (vdot, lambda)
        self._x_full = np.zeros(N_VARS)
        self.condensed = QPProblem(
            P=np.eye(nu),
            q=np.zeros(nu),
            A=np.zeros((0, nu)),
            b=np.zeros(0),
            G=np.zeros((m_in, nu)),
            h=np.zeros(m_in),
            lb=np.full(nu, -s.torque_limit_nm),
            ub=np.full(nu, s.torque_limit_nm),
            P_pattern=np.ones((nu, nu), bool),
            A_pattern=np.zeros((0, nu), bool),
            G_pattern=np.ones((m_in, nu), bool),
            layout={"u": slice(0, nu)},
            row_labels=list(self.problem.row_labels),
        )

    def _condense(self, qp: QPProblem, u_nom: np.ndarray) -> bool:
        """Write :attr:`condensed` from the full ``qp``: (vdot, lambda) = z0 - Z u from the equality rows.
        Returns False if the (vdot, lambda) block is singular."""
        A_free, rhs, c = self._A_free, self._rhs, self.condensed
        A_free[:, :NV] = qp.A[:, VDOT]
        A_free[:, NV:] = qp.A[:, LAM]
        rhs[:, 0] = qp.b
        rhs[:, 1:] = qp.A[:, U]
        _, _, sol, info = lapack.dgesv(A_free, rhs, overwrite_a=1, overwrite_b=1)
        if info != 0:
            return False
        z0, Z = sol[:, 0], sol[:, 1:]  # (vdot, lambda) = z0 - Z u
        self._z0, self._Z = z0, Z
        G_free = self._G_free
        G_free[:, :NV] = qp.G[:, VDOT]
        G_free[:, NV:] = qp.G[:, LAM]
        np.matmul(G_free, Z, out=c.G)
        np.subtract(qp.G[:, U], c.G, out=c.G)
        np.matmul(G_free, z0, out=c.h)
        np.subtract(qp.h, c.h, out=c.h)
        eps = self.settings.regularization
        np.matmul(Z.T, Z, out=c.P)
        c.P *= eps
        c.P.flat[:: robot.N_JOINTS + 1] += 1.0
        # q = -u_nom - eps Z'(z0 - z_target); z_target = z0 - Z u_nom ("nominal") or 0 ("zero")
        if self.settings.regularization_target == "nominal":
            np.matmul(c.P, u_nom, out=c.q)
            np.negative(c.q, out=c.q)
        else:
            np.matmul(z0, Z, out=c.q)
            c.q *= -eps
            c.q -= u_nom
        return True

    def build(self, inputs: TickInputs, u_nom: np.ndarray) -> QPProblem:
        """Write this tick's QP (in place) and return it."""
        qp = self.problem
        qp.q[U] = -u_nom
        for fam in self.eq_families:
            fam.write(qp, inputs)
        for fam in self.ineq_families:
            fam.write(qp, inputs)
        if self.condensed is not None:
            self._condensed_ok = self._condense(qp, u_nom)
        elif self.settings.regularization_target == "nominal":
            self._regularize_towards_nominal(qp, u_nom)
        return qp

    def _regularize_towards_nominal(self, qp: QPProblem, u_nom: np.ndarray) -> None:
        """q[vdot, lambda] = -eps * (vdot_nom, lambda_nom), the equality solution for u = u_nom."""
        A_free = self._A_free  # Fortran-ordered scratch: LAPACK factorises it in place
        A_free[:, :NV] = qp.A[:, VDOT]
        A_free[:, NV:] = qp.A[:, LAM]
        rhs = qp.b - qp.A[:, U] @ u_nom
        _, _, z, info = lapack.dgesv(A_free, rhs, overwrite_a=1, overwrite_b=1)
        if info != 0:  # singular contact Jacobian: fall back to the zero target this tick
            qp.q[VDOT] = 0.0
            qp.q[LAM] = 0.0
            return
        eps = self.settings.regularization
        np.multiply(z[:NV], -eps, out=qp.q[VDOT])
        np.multiply(z[NV:], -eps, out=qp.q[LAM])

    def filter(self, inputs: TickInputs, u_nom: np.ndarray) -> FilterResult:
        """Build, solve, and apply the failure policy. Never raises for solver failures."""
        t0 = time.perf_counter()
        qp = self.build(inputs, u_nom)
        build_s = time.perf_counter() - t0
        try:
            if self.condensed is None:
                sol = self.backend.solve(qp)
            elif self._condensed_ok:
                sol = self.backend.solve(self.condensed)
            else:
                sol = QPSolution(None, "error: singular (vdot, lambda) block of the equality rows", 0.0)
        except Exception as exc:  # a backend bug must not end the episode: record it
            sol = QPSolution(None, f"error: {type(exc).__name__}: {exc}", 0.0)
        if sol.ok:
            x = sol.x
            if self.condensed is not None:  # recover (vdot, lambda) = z0 - Z u
                x = self._x_full
                x[U] = sol.x
                z = self._z0 - self._Z @ sol.x
                x[VDOT], x[LAM] = z[:NV], z[NV:]
            u = np.minimum(x[U], self.settings.torque_limit_nm)  # the QP's bounds hold to solver tolerance
            np.maximum(u, -self.settings.torque_limit_nm, out=u)
            self._last_u = u
            return FilterResult(u, x[LAM].copy(), x[VDOT].copy(), sol.status, False, build_s, sol)
        if self.settings.fallback == "hold_last" and self._last_u is not None:
            u = self._last_u.copy()
        else:
            u = u_nom.copy()
        status = sol.status if sol.status != "solved" else "non-finite solution"
        return FilterResult(u, np.full(NL, np.nan), np.full(NV, np.nan), status, True, build_s, sol)
