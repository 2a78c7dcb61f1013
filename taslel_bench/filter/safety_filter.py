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
target is therefore (vdot_nom, lambda_nom), the prediction for u = u_nom (one solve of the equality rows
per tick): when no inequality binds, u = u_nom exactly for any eps. ``regularization_target: zero`` gives
the textbook form.

Formulation (``formulation``): ``full`` (the paper's) hands the backend the QP in X = (vdot, u,
lambda). ``condensed`` (default) hands it the *same* minimisation with the 30 equality rows eliminated: one solve
with the (vdot, lambda) columns of the equality rows (:mod:`taslel_bench.filter.equality_solve`, leg by leg)
gives (vdot, lambda) = z0 - Z u, so the backend sees a 12-variable QP in u (P = I + eps Z'Z, the G rows
and the torque bounds), and (vdot, lambda) is recovered from its u. Both have the same minimiser (tested
to 1e-6 N·m); the full QP is still written every tick (``problem``); ``record.qps`` saves the one the
backend got. ``condensed`` exists because the backend's cost grows with the rows and variables it sees:
it is the faster formulation for every backend (``results/bench/tick.md``).

The numeric work of a tick (rows, equality solve, condensation, splitting the answer) runs in compiled
kernels (:mod:`taslel_bench.util.jit`) at the end of this module and in :mod:`taslel_bench.filter.constraints`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from taslel_bench.filter.barriers.base import Barrier
from taslel_bench.filter.constraints import ContactOrSwing, EqualityFamily, EquationsOfMotion, FrictionCone
from taslel_bench.filter.equality_solve import FreeBlockSolver, solve_free
from taslel_bench.filter.layout import INACTIVE_RHS, LAM, N_VARS, NL, NU, NV, VDOT, TickInputs, U
from taslel_bench.filter.robust import DisturbanceObserver, RobustMargin, RobustSettings
from taslel_bench.filter.terrain_cone import TerrainFrictionCone, contact_normals
from taslel_bench.interfaces import QPBackend, QPProblem, QPSolution
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import default_robot
from taslel_bench.robot.model import RobotModel
from taslel_bench.terrain.terrain import Terrain
from taslel_bench.util.jit import kernel

FALLBACKS = ("nominal", "hold_last")
REGULARIZATION_TARGETS = ("nominal", "zero")
FORMULATIONS = ("full", "condensed")
_WORLD_Z = np.tile([0.0, 0.0, 1.0], (quad.N_LEGS, 1))  # the paper's pyramid's normal at every foot
FRICTION_CONES = ("pyramid", "terrain")  # the paper's (world z, one mu) | per foot about the terrain normal
RELAXATIONS = ("none", "priority")  # on an infeasible QP: fall back at once | drop barrier families, last first
STANCE_SOURCES = ("schedule", "contact", "estimate")  # gait | plant contact flags | contact estimate


@dataclass(frozen=True)
class FilterSettings:
    enabled: bool = True
    regularization: float = 1e-5  # eps on vdot and lambda (keeps P positive definite)
    regularization_target: str = "nominal"  # "nominal" (vdot_nom, lambda_nom) or "zero"
    lambda_min_n: float = 1.0  # [N] minimum normal force of a stance foot
    contact_velocity_gain: float = 0.0  # [1/s] k_v in J vdot + J̇v = -k_v J v (0 = paper's eq. 3)
    # [N·m] per joint, core order (the robot's: settings.filter_settings)
    torque_limit_nm: tuple[float, ...] = field(default_factory=lambda: default_robot().torque_limit_nm)
    ecbf_enabled: bool = True  # only used when the scenario provides a clearance profile
    ecbf_alpha1: float = 20.0  # [1/s]
    ecbf_alpha2: float = 20.0  # [1/s]
    fallback: str = "nominal"  # on QP failure: pass u_nom ("nominal") or the last filtered u ("hold_last")
    stance_source: str = "schedule"  # "schedule" (gait) or "contact" (plant contact flags)
    formulation: str = "condensed"  # "condensed" (backend sees u only) or "full" (X = (vdot, u, lambda), paper)
    robust: RobustSettings = field(default_factory=RobustSettings)  # margins for a wrong model (off)
    control_dt_s: float = 0.001  # [s] the control period (the robust margin's running statistics)
    friction_cone: str = "pyramid"  # "pyramid" (paper: world z, one mu) | "terrain" (per foot, terrain normal)
    cone_edge_downhill: bool = False  # terrain cone: a pyramid edge down the slope (full mu there), not world x
    # terrain cone: each stance pyramid turned per tick so an edge lies along the nominal torques' tangential
    # force on that foot (full mu where the nominal pushes); below 0.5 N of it, the basis above
    cone_edge_along_nominal: bool = False
    # a stance foot whose force under the nominal torques (the stance model's) has a normal part below
    # lambda_min_n -- the nominal is lifting it off -- is swing for this tick: no contact rows, no cone
    release_lifted_feet: bool = False
    relaxation: str = "none"  # "none" (failure -> fallback) | "priority" (drop barrier families, last first)
    # [N·m] per joint: |u - u_nom| at most this on a stance leg's / a swing leg's joints (inf: the paper's, only
    # the torque limits bound u)
    correction_limit_stance_nm: float = math.inf
    correction_limit_swing_nm: float = math.inf
    # the stance limit is lifted, tick by tick, for each stance leg whose foot the nominal's force would slide
    # (outside the foot's cone at the filter's mu without the margin, about the terrain normal, or a normal part
    # below lambda_min): the filter may move a stance leg only to stop its foot sliding
    correction_limit_stance_unless_sliding: bool = False
    # [-] with the option above: a stance foot whose nominal force has a tangential part beyond this times its
    # normal part (or a normal part below lambda_min) would slide on any ground -- the nominal pushing against
    # an obstacle, or placing or lifting the foot -- and is neither held nor moved: it is out of the contact
    # model this tick (no contact rows, no cone, lambda = 0) and its leg keeps the nominal's torques (inf: every
    # such foot is held, its leg free to move)
    sliding_ratio_max: float = math.inf
    # [-] a stance foot whose terrain normal has n_z below this is no support to the filter: no contact rows and
    # no cone for it (lambda = 0, the leg's motion free), its barrier rows those of a stance foot (none); None: off
    support_min_normal_z: float | None = None


@dataclass
class FilterResult:
    u: np.ndarray  # [N·m] torques sent to the plant (core order)
    lam: np.ndarray  # [N] (12,) predicted contact forces on the robot, world axes (nan on failure)
    vdot: np.ndarray  # (18,) predicted acceleration (nan on failure)
    status: str
    used_fallback: bool
    build_time_s: float
    solve: QPSolution | None = field(default=None)
    ecbf_margin_mps2: float = 0.0  # [m/s²] robust margin the ECBF rows had this tick (0: the paper's rows)
    relaxed: tuple[str, ...] = ()  # barrier families dropped this tick to make the QP feasible (relaxation)


class SafetyFilter:
    """Owns the QP layout and the constraint families; one instance per episode."""

    def __init__(
        self,
        settings: FilterSettings,
        backend: QPBackend,
        barriers: Sequence[Barrier] = (),
        terrain: Terrain | None = None,
    ) -> None:
        """``barriers``: the barrier families (rows in this order after the friction rows, which is also
        their priority: ``relaxation: priority`` drops the last first); with ``settings.ecbf_enabled`` false
        the filter has none. ``terrain``: the world's geometry (needed by ``friction_cone: terrain``)."""
        self.torque_limit_nm = np.array(settings.torque_limit_nm, dtype=float)  # [N·m] (12,) core order
        _check_choices(settings)
        self.settings = settings
        self.backend = backend
        # settings read on every tick, looked up once (the settings are frozen)
        self._robust = settings.robust.enabled
        self._friction_margin = settings.robust.friction_margin  # [-]
        self.eq_families: list[EqualityFamily] = [EquationsOfMotion(), ContactOrSwing(settings.contact_velocity_gain)]
        self.friction: FrictionCone = _friction_cone(settings, terrain)
        if settings.correction_limit_stance_nm < 0.0 or settings.correction_limit_swing_nm < 0.0:
            raise ValueError("filter.correction_limit_stance_nm and filter.correction_limit_swing_nm must be >= 0")
        # bounds |u - u_nom| <= limit per leg (stance / swing) on top of the torque limits: only when one is finite
        self._limit_correction = math.isfinite(settings.correction_limit_stance_nm) or math.isfinite(
            settings.correction_limit_swing_nm)
        self.terrain = terrain
        self._support_check = settings.support_min_normal_z is not None
        if self._support_check and terrain is None:
            raise ValueError("filter.support_min_normal_z needs the world's terrain")
        self.unsupported_ticks = 0  # ticks with a scheduled stance foot the filter took as no support
        self.released_ticks = 0  # ticks with a stance foot released because the nominal lifts it
        # [N] (4, 3) the nominal torques' foot forces, world axes (the terrain cone reads the same array)
        cone = self.friction
        own = np.zeros((quad.N_LEGS, 3))
        self._nominal_force = cone.nominal_force if isinstance(cone, TerrainFrictionCone) else own
        self.relaxed_ticks = 0  # ticks whose QP was solved only after dropping barrier families
        self.relaxed_by_family: dict[str, int] = {}  # family name -> ticks it was dropped
        self.barriers: list[Barrier] = list(barriers) if settings.ecbf_enabled else []
        self._relax_by_priority = settings.relaxation == "priority" and bool(self.barriers)
        self.robust = RobustMargin(settings.robust, settings.ecbf_alpha2, settings.control_dt_s)
        tau = settings.robust.observer_time_constant_s if settings.robust.enabled else 0.0
        self.observer = DisturbanceObserver(tau, settings.control_dt_s, NV) if tau > 0.0 else None
        ineq = [self.friction, *self.barriers]
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
        # the equality rows solved for (vdot, lambda): condensed -> [z0, Z] from [b, A_u] (13 right-hand
        # sides); full -> (vdot_nom, lambda_nom) from b - A_u u_nom (1), for the regularisation target
        n_rhs = 1 + quad.N_JOINTS if settings.formulation == "condensed" else 1
        self._equalities = FreeBlockSolver(n_rhs, self.eq_families[0].start, self.eq_families[1].start)
        self._rhs = np.zeros((m_eq, n_rhs))
        # the nominal torques' contact forces (cone_edge_along_nominal, release_lifted_feet)
        self._nominal_solver = FreeBlockSolver(1, self.eq_families[0].start, self.eq_families[1].start)
        self._nominal_rhs = np.zeros((m_eq, 1))
        self._stance_rows = np.zeros(quad.N_LEGS, bool)  # the stance set of this tick's contact rows
        self._forces_current = False  # whether _nominal_force holds the forces of those rows (set by build)
        self._sliding = np.zeros(quad.N_LEGS, bool)  # the stance feet the nominal's force would slide this tick
        self._unheld = np.zeros(quad.N_LEGS, bool)  # ... beyond sliding_ratio_max: not held, their legs not moved
        self._last_u: np.ndarray | None = None
        self.condensed: QPProblem | None = None
        if settings.formulation == "condensed":
            self._allocate_condensed(m_eq, m_in)

    def _allocate(self, m_eq: int, m_in: int) -> QPProblem:
        s = self.settings
        P = np.zeros((N_VARS, N_VARS))
        np.fill_diagonal(P, s.regularization)
        P[U, U] = np.eye(quad.N_JOINTS)
        lb = np.full(N_VARS, -np.inf)
        ub = np.full(N_VARS, np.inf)
        lb[U], ub[U] = -self.torque_limit_nm, self.torque_limit_nm
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
        nu = quad.N_JOINTS
        self.condensed = QPProblem(
            P=np.eye(nu),
            q=np.zeros(nu),
            A=np.zeros((0, nu)),
            b=np.zeros(0),
            G=np.zeros((m_in, nu)),
            h=np.zeros(m_in),
            lb=-self.torque_limit_nm.copy(),
            ub=self.torque_limit_nm.copy(),
            P_pattern=np.ones((nu, nu), bool),
            A_pattern=np.zeros((0, nu), bool),
            G_pattern=np.ones((m_in, nu), bool),
            layout={"u": slice(0, nu)},
            row_labels=list(self.problem.row_labels),
        )

    def _condense(self, qp: QPProblem, u_nom: np.ndarray) -> bool:
        """Write :attr:`condensed` from the full ``qp``: (vdot, lambda) = z0 - Z u from the equality rows.
        Returns False if the (vdot, lambda) block is singular."""
        c, sv = self.condensed, self._equalities
        assert c is not None  # called only when the filter condenses (self.condensed made)
        return _condense(qp.A, qp.b, qp.G, qp.h, u_nom, self.settings.regularization,
                         self.settings.regularization_target == "nominal", sv.rows, sv.workspace, self._rhs,
                         c.P, c.q, c.G, c.h)  # fmt: skip

    def supported(self, inputs: TickInputs) -> TickInputs:
        """``inputs`` with the stance feet whose terrain normal has n_z below ``support_min_normal_z`` (a toe
        against a riser face or a log's side) taken out of the stance set (the inputs themselves if none is)."""
        stance = np.asarray(inputs.in_stance, bool)
        if not stance.any():
            return inputs
        m, terrain = inputs.model, self.terrain
        assert terrain is not None  # checked when support_min_normal_z is set (__init__)
        normals = contact_normals(terrain, m.foot_pos_in_world, m.robot.foot_radius_m)
        keep = stance & (normals[:, 2] >= self.settings.support_min_normal_z)
        if np.array_equal(keep, stance):
            return inputs
        self.unsupported_ticks += 1
        return replace_stance(inputs, keep)

    def build(self, inputs: TickInputs, u_nom: np.ndarray) -> QPProblem:
        """Write this tick's QP (in place) and return it."""
        qp = self.problem
        qp.q[U] = -u_nom
        contact = self.supported(inputs) if self._support_check else inputs  # the stance set of the contact rows
        self._write_equalities(qp, contact)
        forces_current = False  # whether _nominal_force holds the forces of the rows now in qp
        if self.settings.release_lifted_feet:
            contact, forces_current = self._release_lifted(qp, contact, u_nom)
        if self.settings.cone_edge_along_nominal and not forces_current:  # the terrain cone reads _nominal_force
            self._nominal_forces(qp, u_nom, self._nominal_force)
            forces_current = True
        self._forces_current = forces_current  # whether _nominal_force holds the forces of the rows now in qp
        self.friction.write(qp, contact)
        self._stance_rows[:] = contact.in_stance  # the stance set of the rows written (after the release)
        if self._limit_correction:
            self._sliding_feet(qp, u_nom, inputs)
            if self._unheld.any():  # out of the contact model this tick: no contact rows, no cone, lambda = 0
                contact = replace_stance(contact, self._stance_rows & ~self._unheld)
                self._write_equalities(qp, contact)
                self.friction.write(qp, contact)
                self._stance_rows[:] = contact.in_stance
                self._forces_current = False
        for fam in self.barriers:
            fam.write(qp, inputs)
        if self.condensed is not None:
            self._condensed_ok = self._condense(qp, u_nom)
        elif self.settings.regularization_target == "nominal":
            self._regularize_towards_nominal(qp, u_nom)
        return qp

    def _write_equalities(self, qp: QPProblem, contact: TickInputs) -> None:
        """The equations of motion and the contact-or-swing rows for the stance set of ``contact``."""
        for fam in self.eq_families:
            fam.write(qp, contact)
        if self.observer is not None:  # M vdot + h = S u + J' lambda + d_hat (b = d_hat - h on the EoM rows)
            eom = self.eq_families[0]
            qp.b[eom.start : eom.start + NV] += self.observer.d_hat

    def _nominal_forces(self, qp: QPProblem, u_nom: np.ndarray, out: np.ndarray) -> None:
        """``out`` (4, 3) [N]: the foot forces (on the robot, world axes) the equality rows give for u = u_nom."""
        sv = self._nominal_solver
        _nominal_forces(qp.A, qp.b, u_nom, sv.rows, sv.workspace, self._nominal_rhs, out)

    def _foot_normals(self) -> np.ndarray:
        """(4, 3) the contact normal at each foot: the terrain cone's, last written; world z for the paper's."""
        return self.friction.normals if isinstance(self.friction, TerrainFrictionCone) else _WORLD_Z

    def lifted_feet(self, qp: QPProblem, contact: TickInputs, u_nom: np.ndarray) -> np.ndarray:
        """(4,) bool: stance feet (of ``contact``, whose rows ``qp`` holds) whose force under u_nom has a
        normal part below ``lambda_min_n``: sticking would need the ground to pull."""
        force = self._nominal_force
        self._nominal_forces(qp, u_nom, force)
        normal_n = np.einsum("ij,ij->i", force, self._foot_normals())
        return np.asarray(contact.in_stance, bool) & (normal_n < self.settings.lambda_min_n)

    def separating_feet(self, qp: QPProblem, feet: np.ndarray, u_nom: np.ndarray, m: RobotModel) -> np.ndarray:
        """(4,) bool: of ``feet`` (swing in ``qp``'s rows), those whose acceleration under u_nom, J vdot + J̇v
        (world), points away from the ground (a positive normal part)."""
        self._nominal_forces(qp, u_nom, self._nominal_force)
        vdot = self._nominal_rhs[:NV, 0]
        normals = self._foot_normals()
        out = np.zeros(quad.N_LEGS, bool)
        for i in np.flatnonzero(feet):
            acc = m.foot_jac_in_world[i] @ vdot + m.foot_jdotv_in_world[i]
            out[i] = float(acc @ normals[i]) > 0.0
        return out

    def _release_lifted(self, qp: QPProblem, contact: TickInputs, u_nom: np.ndarray) -> tuple[TickInputs, bool]:
        """``release_lifted_feet``: the stance feet u_nom pulls off the ground -- sticking needs a normal force
        below ``lambda_min_n`` and, let go, the foot accelerates away from the ground (the contact mode rigid
        contact gives them) -- become swing for this tick (the equality rows rewritten). A foot that would
        need a pull to stick yet accelerates into the ground when let go (it would slide) stays in stance.
        Returns (the inputs with that stance set, whether ``_nominal_force`` holds the forces of the rows
        written last)."""
        lifted = self.lifted_feet(qp, contact, u_nom)
        if not lifted.any():
            return contact, True
        stance = np.asarray(contact.in_stance, bool)
        self._write_equalities(qp, replace_stance(contact, stance & ~lifted))
        released = lifted & self.separating_feet(qp, lifted, u_nom, contact.model)
        rewritten = not np.array_equal(released, lifted)
        if rewritten:  # some stay: the rows of the feet released only
            self._write_equalities(qp, replace_stance(contact, stance & ~released))
        if not released.any():
            return contact, not rewritten
        self.released_ticks += 1
        return replace_stance(contact, stance & ~released), not rewritten

    def _regularize_towards_nominal(self, qp: QPProblem, u_nom: np.ndarray) -> None:
        """q[vdot, lambda] = -eps * (vdot_nom, lambda_nom), the equality solution for u = u_nom (zero target
        this tick if the contact Jacobian makes the (vdot, lambda) block singular)."""
        sv, eps = self._equalities, self.settings.regularization
        _nominal_target(qp.A, qp.b, u_nom, eps, sv.rows, sv.workspace, self._rhs, qp.q)

    def _sliding_feet(self, qp: QPProblem, u_nom: np.ndarray, inputs: TickInputs) -> None:
        """``correction_limit_stance_unless_sliding``: marks in ``_sliding`` (4,) the stance feet of the rows in
        ``qp`` on which the nominal torques' force lies outside the foot's cone (``inputs``' mu, which carries the
        friction margin, divided back by 1 - margin; a circular cone about the terrain normal) or has a normal
        part below ``lambda_min_n``; with a finite ``sliding_ratio_max`` only those whose force is within that
        ratio of tangential to normal, the others in ``_unheld`` (:meth:`build` takes them out of the contact
        rows). None of them when the option is off. The forces are solved for only when :meth:`build` left none
        for these rows (the release and the turned pyramids already need them)."""
        out, unheld = self._sliding, self._unheld
        out[:] = False
        unheld[:] = False
        if not self.settings.correction_limit_stance_unless_sliding:
            return
        force = self._nominal_force
        if not self._forces_current:
            self._nominal_forces(qp, u_nom, force)
            self._forces_current = True
        normals, feet_mu = self._foot_normals(), inputs.mu_per_foot
        ratio_max, lambda_min = self.settings.sliding_ratio_max, self.settings.lambda_min_n
        finite_ratio = math.isfinite(ratio_max)
        for i in np.flatnonzero(self._stance_rows):
            mu = (feet_mu[i] if feet_mu is not None else inputs.mu) / (1.0 - self._friction_margin)
            fn = float(force[i] @ normals[i])
            ft = float(np.linalg.norm(force[i] - fn * normals[i]))
            slides = fn < lambda_min or ft > mu * fn
            beyond = finite_ratio and (fn < lambda_min or ft > ratio_max * fn)  # would slide on any ground
            out[i] = slides and not beyond
            unheld[i] = slides and beyond

    def _correction_bounds(self, u_nom: np.ndarray, in_stance: np.ndarray, free: np.ndarray) -> None:
        """The backend problem's bounds on u: the torque limits intersected with u_nom +- the correction limit
        of each joint's leg (``correction_limit_stance_nm`` for the filter's stance legs, ``..._swing_nm`` for the
        others, none for the legs ``free`` (4,) marks); a u_nom beyond a torque limit gets the limit itself."""
        s, lim = self.settings, self.torque_limit_nm
        per_leg = np.where(np.asarray(in_stance, bool), s.correction_limit_stance_nm, s.correction_limit_swing_nm)
        per_leg = np.where(free, math.inf, per_leg)
        delta = np.repeat(per_leg, quad.N_JOINTS // quad.N_LEGS)
        lb = np.minimum(np.maximum(-lim, u_nom - delta), lim)
        ub = np.maximum(np.minimum(lim, u_nom + delta), -lim)
        if self.condensed is not None:
            self.condensed.lb[:], self.condensed.ub[:] = lb, ub
        else:
            self.problem.lb[U], self.problem.ub[U] = lb, ub

    def _solve(self, qp: QPProblem) -> QPSolution:
        """The backend's answer to this tick's QP (the condensed one with ``formulation: condensed``)."""
        try:
            if self.condensed is None:
                return self.backend.solve(qp)
            if self._condensed_ok:
                return self.backend.solve(self.condensed)
            return QPSolution(None, "error: singular (vdot, lambda) block of the equality rows", 0.0)
        except Exception as exc:  # a backend bug must not end the episode: record it
            return QPSolution(None, f"error: {type(exc).__name__}: {exc}", 0.0)

    def _relax(self, qp: QPProblem, u_nom: np.ndarray, sol: QPSolution) -> tuple[QPSolution, tuple[str, ...]]:
        """``relaxation: priority``: the QP failed; drop the barrier families one at a time, last in the list
        first (their rows become inactive, 0 <= INACTIVE_RHS, and their h nan), re-solving after each, until a
        solve succeeds. Returns (the last solution, the families dropped); counts the tick when one succeeds.
        The equations of motion, contact rows, friction cones and torque limits are never relaxed."""
        dropped: list[str] = []
        for barrier in reversed(self.barriers):
            rows = slice(barrier.start, barrier.start + barrier.n_rows)
            if np.all(qp.h[rows] == INACTIVE_RHS):
                continue
            qp.G[rows] = 0.0
            qp.h[rows] = INACTIVE_RHS
            barrier.h[:], barrier.h_e[:] = np.nan, np.nan
            dropped.append(barrier.name)
            if self.condensed is not None:
                self._condensed_ok = self._condense(qp, u_nom)
            sol = self._solve(qp)
            if sol.ok:
                self.relaxed_ticks += 1
                for name in dropped:
                    self.relaxed_by_family[name] = self.relaxed_by_family.get(name, 0) + 1
                break
        return sol, tuple(dropped)

    def reset(self) -> None:
        """Forget the backend's warm start and the last filtered u (a new episode)."""
        self.backend.reset()
        self._last_u = None
        self.relaxed_ticks = 0
        self.relaxed_by_family = {}
        self.unsupported_ticks = 0
        self.released_ticks = 0
        self.robust.reset()
        if self.observer is not None:
            self.observer.reset()

    def filter(self, inputs: TickInputs, u_nom: np.ndarray) -> FilterResult:
        """Build, solve, and apply the failure policy. Never raises for solver failures."""
        t0 = time.perf_counter()
        robust = self._robust
        if self.observer is not None:
            self.observer.update(inputs.v, inputs.in_stance)
        if robust:  # margins sized from the running shortfall of the realised barrier condition
            margin = self.robust.ecbf_margin_mps2
            for barrier in self.barriers:
                barrier.margin_mps2 = margin
        if self._friction_margin > 0.0:  # with or without the ECBF margins (robust.enabled)
            inputs = inputs.with_mu_scaled(1.0 - self._friction_margin)  # per-foot values too
        qp = self.build(inputs, u_nom)
        if self._limit_correction:
            self._correction_bounds(u_nom, inputs.in_stance, self._sliding)
        if robust:
            self.robust.observe(self.barriers)
        build_s = time.perf_counter() - t0
        sol = self._solve(qp)
        relaxed: tuple[str, ...] = ()
        ok = sol.ok
        if not ok and self._relax_by_priority:
            sol, relaxed = self._relax(qp, u_nom, sol)
            ok = sol.ok
        if ok:
            u, lam, vdot = np.empty(quad.N_JOINTS), np.empty(NL), np.empty(NV)
            # condensed: recover (vdot, lambda) = z0 - Z u; u clipped to the torque limit (the QP's bounds
            # hold to solver tolerance)
            _split_solution(sol.x, self.condensed is not None, self._rhs, self.torque_limit_nm, u, lam,
                            vdot)  # fmt: skip
            for barrier in self.barriers:  # the ECBF conditions the filter believes it planned
                barrier.planned(qp, vdot)
            if robust:
                self.robust.remember(self.barriers)
            if self.observer is not None:
                m = inputs.model
                jac_t_lambda = np.einsum("ikj,ik->j", m.foot_jac_in_world, lam.reshape(quad.N_LEGS, 3))
                self.observer.remember(inputs.v, m.M, m.h, u, jac_t_lambda, inputs.in_stance)
            self._last_u = u
            margin = self.barriers[0].margin_mps2 if self.barriers else 0.0
            return FilterResult(u, lam, vdot, sol.status, False, build_s, sol, margin, relaxed)
        for barrier in self.barriers:  # nothing planned on this tick
            barrier.psi_planned[:] = np.nan
        if self.observer is not None:
            self.observer.remember(inputs.v, inputs.model.M, inputs.model.h, u_nom, None, inputs.in_stance)
        if robust:
            self.robust.remember(self.barriers)
        u = self._last_u.copy() if self.settings.fallback == "hold_last" and self._last_u is not None else u_nom.copy()
        status = sol.status if sol.status != "solved" else "non-finite solution"
        return FilterResult(u, np.full(NL, np.nan), np.full(NV, np.nan), status, True, build_s, sol)


def _check_choices(settings: FilterSettings) -> None:
    """ValueError naming the key and the valid values for a settings choice that is not one of them."""
    choices = (("fallback", FALLBACKS), ("regularization_target", REGULARIZATION_TARGETS),
               ("formulation", FORMULATIONS), ("friction_cone", FRICTION_CONES), ("relaxation", RELAXATIONS))
    for key, valid in choices:
        value = getattr(settings, key)
        if value not in valid:
            raise ValueError(f"filter.{key}={value!r}; valid: {', '.join(valid)}")


def _friction_cone(settings: FilterSettings, terrain: Terrain | None) -> FrictionCone:
    """The paper's pyramid, or the per-foot terrain cone (``friction_cone: terrain``, which needs the terrain)."""
    if settings.friction_cone == "terrain":
        if terrain is None:
            raise ValueError("filter.friction_cone=terrain needs the world's terrain")
        return TerrainFrictionCone(settings.lambda_min_n, terrain, edge_downhill=settings.cone_edge_downhill,
                                   edge_along_nominal=settings.cone_edge_along_nominal)
    if settings.cone_edge_along_nominal:
        raise ValueError("filter.cone_edge_along_nominal=true needs filter.friction_cone=terrain (the "
                         "paper's pyramid keeps world x)")
    return FrictionCone(settings.lambda_min_n)


def replace_stance(x: TickInputs, in_stance: np.ndarray) -> TickInputs:
    """``x`` with the stance set ``in_stance`` (4,) bool."""
    return TickInputs(x.model, x.v, in_stance, x.mu, x.swing_phase, x.swing_phase_rate, x.mu_per_foot)


# ----------------------------------------------------------------------------------- compiled kernels
# The equality rows A X = b determine (vdot, lambda) from u: (vdot, lambda) = A_free^-1 (b - A_u u), with
# A_free the (vdot, lambda) columns of A (:mod:`taslel_bench.filter.equality_solve`).


@kernel
def _solve_for_u(A, b, u, rows, ws, rhs):
    """rhs[:, 0] = (vdot, lambda) of the equality rows for the torques ``u``: A_free^-1 (b - A_u u); False if
    A_free is singular."""
    for r in range(A.shape[0]):
        acc = b[r]
        for j in range(NU):
            acc -= A[r, NV + j] * u[j]
        rhs[r, 0] = acc
    return solve_free(A, rhs, rows, ws)


@kernel
def _nominal_target(A, b, u_nom, eps, rows, ws, rhs, q):
    """q[vdot, lambda] = -eps (vdot_nom, lambda_nom) with (vdot_nom, lambda_nom) = A_free^-1 (b - A_u u_nom);
    0 if A_free is singular."""
    ok = _solve_for_u(A, b, u_nom, rows, ws, rhs)
    for c in range(NV):
        q[c] = -eps * rhs[c, 0] if ok else 0.0
    for c in range(NL):
        q[NV + NU + c] = -eps * rhs[NV + c, 0] if ok else 0.0


@kernel
def _nominal_forces(A, b, u_nom, rows, ws, rhs, force):
    """``force`` (4, 3) [N] = lambda_nom, the contact forces (on the robot, world axes) of the equality rows
    under u = u_nom: A_free^-1 (b - A_u u_nom); zeros if A_free is singular."""
    ok = _solve_for_u(A, b, u_nom, rows, ws, rhs)
    for c in range(NL):
        force[c // 3, c % 3] = rhs[NV + c, 0] if ok else 0.0


@kernel
def _condense(A, b, G, h, u_nom, eps, nominal_target, rows, ws, rhs, Pc, qc, Gc, hc):
    """The 12-variable QP in u with (vdot, lambda) = z0 - Z u eliminated ([z0, Z] = A_free^-1 [b, A_u],
    kept in ``rhs``): Gc = G_u - G_free Z, hc = h - G_free z0, Pc = I + eps Z'Z, and qc = -Pc u_nom
    (target (vdot_nom, lambda_nom)) or -u_nom - eps Z'z0 (target 0). False if A_free is singular."""
    m_eq, nz = A.shape[0], NV + NL
    for r in range(m_eq):
        rhs[r, 0] = b[r]
        for j in range(NU):
            rhs[r, 1 + j] = A[r, NV + j]
    if not solve_free(A, rhs, rows, ws):
        return False
    for r in range(G.shape[0]):  # G rows are sparse (3 lambda entries, or a vdot row): skip zeros
        acc_h = h[r]
        for j in range(NU):
            Gc[r, j] = G[r, NV + j]
        for k in range(nz):
            g = G[r, k] if k < NV else G[r, NU + k]
            if g != 0.0:
                acc_h -= g * rhs[k, 0]
                for j in range(NU):
                    Gc[r, j] -= g * rhs[k, 1 + j]
        hc[r] = acc_h
    for i in range(NU):
        for j in range(i, NU):
            acc = 0.0
            for k in range(nz):
                acc += rhs[k, 1 + i] * rhs[k, 1 + j]
            Pc[i, j] = eps * acc + (1.0 if i == j else 0.0)
            Pc[j, i] = Pc[i, j]
    for i in range(NU):
        acc = 0.0
        if nominal_target:
            for j in range(NU):
                acc -= Pc[i, j] * u_nom[j]
        else:
            acc = -u_nom[i]
            for k in range(nz):
                acc -= eps * rhs[k, 1 + i] * rhs[k, 0]
        qc[i] = acc
    return True


@kernel
def _split_solution(x, condensed, rhs, torque_limit, u, lam, vdot):
    """(u, lambda, vdot) of a backend's solution ``x``: the blocks of X, or for the condensed QP u = x and
    (vdot, lambda) = z0 - Z u from ``rhs`` = [z0, Z]; u clipped to +-torque_limit (12,) per joint."""
    for j in range(NU):
        u[j] = min(max(x[j] if condensed else x[NV + j], -torque_limit[j]), torque_limit[j])
    for k in range(NV + NL):
        if condensed:
            z = rhs[k, 0]
            for j in range(NU):
                z -= rhs[k, 1 + j] * x[j]
        else:
            z = x[k] if k < NV else x[NU + k]
        if k < NV:
            vdot[k] = z
        else:
            lam[k - NV] = z
