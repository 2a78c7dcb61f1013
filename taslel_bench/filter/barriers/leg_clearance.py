"""Whole-leg clearance (``filter.barriers.shin`` and ``filter.barriers.knee``, preset ``filter=terrain``): the
lower leg (a capsule from the knee towards the foot) or the knee (a sphere at the calf joint) kept off the
terrain and its obstacles, for every leg (a stance leg's shin can hit a log as the trunk moves over it)."""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.barriers.leg_points import SHIN_RADIUS_M, LegPoints
from taslel_bench.filter.layout import INACTIVE_RHS, NV, TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import a1

PARTS = ("shin", "knee")
SHIN_SAMPLES = 6  # points along the shin's axis (the closest of them is the capsule's closest point)


class LegClearance(Barrier):
    """One row per leg: h = d >= 0, d the distance [m] of a lower-leg piece to the terrain, with the Jacobian
    of the closest point. ``part``: ``shin`` -- a capsule of radius ``radius_m`` on the axis knee -> foot
    centre, from the knee to ``axis_fraction`` of the way (the rest is inside the foot sphere's reach), its
    distance the smallest over SHIN_SAMPLES points of the axis; ``knee`` -- a sphere of
    radius ``radius_m`` at the calf joint. A row is active only where h < ``activation_m`` (far legs get an
    inactive row, the solver sees fewer binding rows).

    With n the unit normal from the terrain to the closest axis point p (fixed to the calf body for this tick),
    hdot = n . v_p, hddot >= n . (J_p vdot + J̇_p v) (the distance's Hessian, positive semi-definite, dropped:
    conservative): -n'J_p vdot <= a2 h_e + a1 hdot + n . J̇_p v."""

    def __init__(self, world: BarrierWorld, name: str = "shin", part: str = "shin", radius_m: float = SHIN_RADIUS_M,
                 axis_fraction: float = 0.7, activation_m: float = 0.08) -> None:  # fmt: skip
        super().__init__(world, name)
        if part not in PARTS:
            raise ValueError(f"filter.barriers.{name}.part={part!r}; valid: {', '.join(PARTS)}")
        self.terrain, self.part = world.terrain, part
        self.radius_m, self.axis_fraction, self.activation_m = float(radius_m), float(axis_fraction), float(activation_m)
        self._points: LegPoints | None = None

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m, r0 = x.model, self.start
        if self._points is None or self._points.model is not m:
            self._points = LegPoints(m)
        qp.G[r0 : r0 + a1.N_LEGS] = 0.0
        qp.h[r0 : r0 + a1.N_LEGS] = INACTIVE_RHS
        self.h[:], self.h_e[:] = np.nan, np.nan
        knees = np.array([self._points.knee(i) for i in range(a1.N_LEGS)])  # [m] (4, 3)
        if self.part == "knee":
            axis = knees[:, None, :]
        else:  # SHIN_SAMPLES points from the knee to axis_fraction of the way to the foot centre, per leg
            s = np.linspace(0.0, self.axis_fraction, SHIN_SAMPLES)[None, :, None]
            axis = knees[:, None, :] + s * (m.foot_pos_in_world - knees)[:, None, :]
        n_per_leg = axis.shape[1]
        dist, normal, _ = self.terrain.near_distance(axis.reshape(-1, 3), self.radius_m)
        for i in range(a1.N_LEGS):
            k = i * n_per_leg + int(np.argmin(dist[i * n_per_leg : (i + 1) * n_per_leg]))
            d, n, p = float(dist[k]), normal[k], axis.reshape(-1, 3)[k]
            if not np.isfinite(d) or d >= self.activation_m:
                continue
            jac, vel, jdotv = self._points.point_terms(i, p, x.v)
            hdot = float(n @ vel)
            h_e = hdot + self.alpha1 * d
            qp.G[r0 + i, :NV] = -(n @ jac)
            qp.h[r0 + i] = self.alpha2 * h_e + self.alpha1 * hdot + float(n @ jdotv)
            self.h[i], self.h_e[i] = d, h_e
        self.tighten(qp)
