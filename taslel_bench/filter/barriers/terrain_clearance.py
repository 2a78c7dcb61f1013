"""Swing-foot clearance of the real terrain (``filter.barriers.terrain_clearance``, preset ``filter=terrain``):
an exponential CBF on the foot sphere's distance to the terrain object (every part: floor, steps, slope,
heightfield, logs), instead of the paper's phase polynomial over a flat floor."""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.layout import INACTIVE_RHS, NV, TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import a1


class TerrainClearance(Barrier):
    """One row per swing foot: h = d(p) - c(s) >= 0 with d the signed distance [m] of the foot sphere (centre p,
    world) to the terrain (:meth:`taslel_bench.terrain.terrain.Terrain.sphere_distance`; on flat ground or a
    slope the height above the surface under the foot along its normal, at a step's edge or a log the
    Euclidean distance) and c(s) = ``lift_m`` 16 s² (1 - s)² a required lift over the swing phase s (0 at
    lift-off and touchdown, ``lift_m`` mid-swing).

    With n = grad d (the unit normal from the closest terrain point to p): hdot = n . v - c'(s) sdot and
    hddot >= n . (J vdot + J̇v) - c''(s) sdot² (the distance's Hessian is positive semi-definite for the convex
    pieces the terrain is made of, so dropping it makes the row conservative). The row enforces
    hdot_e + a2 h_e >= 0 with h_e = hdot + a1 h:  -n'J vdot <= a2 h_e + a1 hdot + n . J̇v - c'' sdot².
    Stance feet (the filter's stance set) get an inactive row."""

    def __init__(self, world: BarrierWorld, name: str = "terrain_clearance", lift_m: float = 0.02) -> None:
        super().__init__(world, name)
        self.terrain = world.terrain
        self.lift_m = float(lift_m)  # [m]

    def _lift(self, s: float) -> tuple[float, float, float]:
        """(c, dc/ds, d²c/ds²) of c(s) = lift 16 s² (1 - s)²."""
        k = 16.0 * self.lift_m
        return k * s * s * (1 - s) ** 2, k * (2 * s - 6 * s * s + 4 * s**3), k * (2 - 12 * s + 12 * s * s)

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m, r0 = x.model, self.start
        swing = ~np.asarray(x.in_stance, bool)
        qp.G[r0 : r0 + a1.N_LEGS] = 0.0
        qp.h[r0 : r0 + a1.N_LEGS] = INACTIVE_RHS
        self.h[:], self.h_e[:] = np.nan, np.nan
        if not swing.any():
            return
        legs = np.flatnonzero(swing)
        dist, normal, _ = self.terrain.near_distance(m.foot_pos_in_world[legs], a1.FOOT_RADIUS_M)
        sdot = x.swing_phase_rate
        for d, n, i in zip(dist, normal, legs):
            if not np.isfinite(d):
                continue
            c, dc, ddc = self._lift(float(x.swing_phase[i]))
            h = d - c
            hdot = float(n @ m.foot_vel_in_world[i]) - dc * sdot
            h_e = hdot + self.alpha1 * h
            qp.G[r0 + i, :NV] = -(n @ m.foot_jac_in_world[i])
            qp.h[r0 + i] = self.alpha2 * h_e + self.alpha1 * hdot + float(n @ m.foot_jdotv_in_world[i]) - ddc * sdot**2
            self.h[i], self.h_e[i] = h, h_e
        self.tighten(qp)
