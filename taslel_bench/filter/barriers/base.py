"""A barrier family: one exponential-CBF row per leg in the QP's inequality block, the filter's list of them
(``filter.barriers``), and what the trace, MCAP and metrics read of each (its name, h, h_e and the
condition it planned).

A family is a subclass of :class:`Barrier` built from its config entry with the :class:`BarrierWorld` (the
terrain, the scenario's virtual profile, the ECBF gains). Its rows read ``psi(vdot) >= margin`` with
psi = hdot_e + a2 h_e [m/s²] the ECBF condition on h_e = hdot + a1 h; a row is inactive
(``0 <= INACTIVE_RHS``, h = nan) where the family does not apply on this tick (a stance foot, a leg far from
any obstacle). Adding a barrier = one subclass + one ``filter.barriers.<name>`` entry (docs/guides/extending.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from taslel_bench.filter.layout import INACTIVE_RHS, NV, VDOT, TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription, default_robot
from taslel_bench.terrain.profile import ClearanceProfile
from taslel_bench.terrain.terrain import Terrain
from taslel_bench.util.jit import kernel


@dataclass(frozen=True)
class BarrierWorld:
    """What a barrier family may read when it is built: the world's geometry and the ECBF gains."""

    terrain: Terrain
    profile: ClearanceProfile | None  # the paper's virtual obstacle z(s) (None: the scenario has none)
    alpha1: float  # [1/s]
    alpha2: float  # [1/s]
    robot: RobotDescription = field(default_factory=default_robot)  # whose feet and shins


class Barrier:
    """Exponential-CBF rows, one per name of :attr:`rows` (by default one per leg, in LEGS order; a family of
    other rows declares its own, e.g. the trunk's pitch and roll), written by a subclass's :meth:`write` (usually
    one compiled kernel), which also fills ``h`` [m] and ``h_e`` [m/s] (nan where a row is inactive). Each row reads
    psi(vdot) >= margin with psi = hdot_e + a2 h_e [m/s²] and ``margin_mps2`` >= 0 a robustness margin (0:
    the paper's row). After a solve, :meth:`planned` records psi at the solution's vdot (``psi_planned``):
    the condition the filter believes the next instant satisfies.

    ``name`` is the family's config key (``filter.barriers.<name>``), the suffix of its row labels
    (``FL_<name>``), and the middle of its trace columns (``FL_barrier_<name>_h_m``). Only the families whose rows
    are the legs enter the per-leg readings (``FL_barrier_h_m``, the psi columns, the MCAP's per-foot spheres).
    Subclasses override
    :meth:`write`, and :meth:`applies` when they need something of the world (a profile, obstacles)."""

    rows: tuple[str, ...] = quad.LEGS  # the family's row names (one QP row each)

    @property
    def n_rows(self) -> int:
        return len(self.rows)

    @property
    def per_leg(self) -> bool:
        """True when the family has one row per leg (LEGS order)."""
        return tuple(self.rows) == quad.LEGS

    def __init__(self, world: BarrierWorld, name: str) -> None:
        self.name = name
        self.alpha1, self.alpha2 = world.alpha1, world.alpha2
        self.foot_radius_m = world.robot.foot_radius_m  # [m] the robot's foot spheres
        self.start = 0  # first row in the QP's inequality block (set by the filter)
        self.margin_mps2 = 0.0  # [m/s²] robust margin on psi (set per tick by the filter when robust)
        self.h = np.full(self.n_rows, np.nan)  # [m] barrier value per row (nan where inactive)
        self.h_e = np.full(self.n_rows, np.nan)  # [m/s]
        self.psi_planned = np.full(self.n_rows, np.nan)  # [m/s²] hdot_e + a2 h_e at the solution

    @classmethod
    def applies(cls, world: BarrierWorld) -> bool:
        """Whether this family has rows in ``world`` (a family that needs a profile or obstacles says no
        without them: the filter then has no such rows)."""
        return True

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        """Write this tick's rows ``start .. start + n_rows`` of ``qp.G``/``qp.h`` and ``h``, ``h_e``."""
        raise NotImplementedError

    def pattern(self, mask: np.ndarray) -> None:
        mask[self.start : self.start + self.n_rows, VDOT] = True

    def labels(self) -> list[str]:
        return [f"{row}_{self.name}" for row in self.rows]

    def init(self, qp: QPProblem) -> None:
        qp.G[self.start : self.start + self.n_rows] = 0.0
        qp.h[self.start : self.start + self.n_rows] = INACTIVE_RHS

    def tighten(self, qp: QPProblem) -> None:
        """Subtract the robust margin from the active rows' right-hand sides (call at the end of write)."""
        if self.margin_mps2 > 0.0:
            rows = slice(self.start, self.start + self.n_rows)
            qp.h[rows] -= np.where(np.isfinite(self.h), self.margin_mps2, 0.0)

    def planned(self, qp: QPProblem, vdot: np.ndarray) -> None:
        """psi at the solution: the row's slack plus the margin (nan for stance feet)."""
        _planned_condition(qp.G, qp.h, self.start, vdot, self.margin_mps2, self.h, self.psi_planned)


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
