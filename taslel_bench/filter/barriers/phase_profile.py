"""The paper's ground-clearance ECBF on its virtual obstacle profile z(s) (``filter.barriers.clearance``)."""

from __future__ import annotations

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld, _inactive_barrier_row
from taslel_bench.filter.layout import TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.util.jit import kernel


class PhaseProfileClearance(Barrier):
    """Ground-clearance exponential CBF (paper, "Ground Clearance Enforced by an ECBF"), one row per foot.

    h = p_z - r_foot - z(s) (foot-sphere bottom above the obstacle profile), hdot = v_z - z'(s) sdot,
    h_e = hdot + a1 h, and the row enforces a2 h_e + hdot_e >= 0 with
    hdot_e = (J_z vdot + (J̇v)_z) - z''(s) sdot² + a1 hdot  (s̈ = 0; the chain rule gives sdot², where the
    paper's printed formula has sdot). Written as  -J_z vdot <= a2 h_e + (J̇v)_z - z'' sdot² + a1 hdot.
    Stance feet get an inactive row (0 <= INACTIVE_RHS).
    """

    def __init__(self, world: BarrierWorld, name: str = "clearance") -> None:
        super().__init__(world, name)
        if world.profile is None:
            raise ValueError(f"filter.barriers.{name}: the scenario has no clearance profile")
        self.profile = world.profile
        self._c, self._c1, self._c2 = self.profile.coefficient_arrays()  # z, dz/ds, d²z/ds² (ascending)

    @classmethod
    def applies(cls, world: BarrierWorld) -> bool:
        return world.profile is not None

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        _ecbf_rows(qp.G, qp.h, self.start, m.foot_pos_in_world, m.foot_vel_in_world, m.foot_jac_in_world,
                   m.foot_jdotv_in_world, x.in_stance, x.swing_phase, x.swing_phase_rate, self._c, self._c1,
                   self._c2, self.alpha1, self.alpha2, self.foot_radius_m, self.h, self.h_e)  # fmt: skip
        self.tighten(qp)


@kernel
def _horner(coeffs, s):
    acc = 0.0
    for j in range(coeffs.shape[0] - 1, -1, -1):
        acc = acc * s + coeffs[j]
    return acc


@kernel
def _ecbf_rows(G, hvec, r0, foot_pos, foot_vel, foot_jac, foot_jdotv, in_stance, swing_phase, sdot, c, c1, c2,
               alpha1, alpha2, foot_radius, h_out, he_out):  # fmt: skip
    """Row r0 + i per foot (see :class:`PhaseProfileClearance`): swing -> -J_z vdot <= a2 h_e + (J̇v)_z
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
