"""Swing-foot clearance of the terrain's logs (``filter.barriers.obstacle``): the paper's ECBF with the
Euclidean clearance of the foot sphere as h."""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld, _inactive_barrier_row
from taslel_bench.filter.layout import TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.util.jit import kernel


class ObstacleClearance(Barrier):
    """Swing-foot clearance of the terrain's logs (cylinders across the path), one row per foot: the
    paper's exponential CBF with the Euclidean clearance of the foot sphere from the nearest log as h.

    For a log with axis along world y through (x_o, z_o) and radius R, and the foot-sphere centre p (radius
    r): rho = |(p_x - x_o, p_z - z_o)|, n = (p - o)_xz / rho, h = rho - R - r (>= 0 <=> no contact),
    hdot = n . v_xz, hddot = n . a_xz + (|v_xz|² - hdot²) / rho with a = J vdot + J̇v. The row enforces
    hdot_e + a2 h_e >= 0 with h_e = hdot + a1 h:
    -(n_x J_x + n_z J_z) vdot <= a2 h_e + a1 hdot + n . (J̇v)_xz + (|v_xz|² - hdot²) / rho.
    Each swing foot is constrained by its nearest log (smallest h); stance feet get an inactive row.
    """

    def __init__(self, world: BarrierWorld, name: str = "obstacle") -> None:
        super().__init__(world, name)
        self.logs = world.terrain.logs()
        if not self.logs:
            raise ValueError(f"filter.barriers.{name}: the terrain has no logs")
        self._geometry = np.array([[log.x_m, log.z_m, log.radius_m] for log in self.logs])  # [m] (n_logs, 3)

    @classmethod
    def applies(cls, world: BarrierWorld) -> bool:
        return bool(world.terrain.logs())

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        _obstacle_rows(qp.G, qp.h, self.start, m.foot_pos_in_world, m.foot_vel_in_world, m.foot_jac_in_world,
                       m.foot_jdotv_in_world, x.in_stance, self._geometry, self.alpha1, self.alpha2,
                       self.foot_radius_m, self.h, self.h_e)  # fmt: skip
        self.tighten(qp)


@kernel
def _obstacle_rows(G, hvec, r0, foot_pos, foot_vel, foot_jac, foot_jdotv, in_stance, geometry, alpha1, alpha2,
                   foot_radius, h_out, he_out):  # fmt: skip
    """Row r0 + i per foot (see :class:`ObstacleClearance`); ``geometry`` rows are (x_o, z_o, R) [m]."""
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
