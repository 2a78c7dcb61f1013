"""Swing-foot clearance of the real terrain (``filter.barriers.terrain_clearance``, preset ``filter=terrain``):
an exponential CBF on the foot sphere's distance to the terrain object (every part: floor, steps, slope,
heightfield, logs), instead of the paper's phase polynomial over a flat floor."""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld, _inactive_barrier_row
from taslel_bench.filter.layout import TickInputs
from taslel_bench.interfaces import OBSTACLE, QPProblem
from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.packed import terrain_distance
from taslel_bench.util.fields import number
from taslel_bench.util.jit import kernel


class TerrainClearance(Barrier):
    """One row per swing foot: h = d(p) - c(s) >= 0 with d the signed distance [m] of the foot sphere (centre p,
    world) to the terrain (:meth:`taslel_bench.terrain.terrain.Terrain.sphere_distance`; on flat ground or a
    slope the height above the surface under the foot along its normal, at a step's edge or a log the
    Euclidean distance) and c(s) = ``lift_m`` 16 s² (1 - s)² - ``touchdown_allowance_m`` s⁴ the required
    lift over the swing phase s (0 at lift-off, ~``lift_m`` mid-swing, -allowance at touchdown: the foot may
    reach the ground at the nominal speed instead of approaching it exponentially -- without the allowance
    the foot still hovers when its stance begins, and the stance rows then plan support from a foot in the
    air: the trot fell on flat ground in 2 of 3 seeds within 5 s).

    With n = grad d (the unit normal from the closest terrain point to p): hdot = n . v - c'(s) sdot and
    hddot >= n . (J vdot + J̇v) - c''(s) sdot² (the distance's Hessian is positive semi-definite for the convex
    pieces the terrain is made of, so dropping it makes the row conservative). The row enforces
    hdot_e + a2 h_e >= 0 with h_e = hdot + a1 h:  -n'J vdot <= a2 h_e + a1 hdot + n . J̇v - c'' sdot².
    Stance feet (the filter's stance set) get an inactive row. ``role``: the parts measured, by default the
    obstacles (steps, logs, a rough field, an incline): the flat floor needs no row (it is where the foot
    lands), and rows against it bound a foot that lifted late on mu = 0.2 -- the filter then forced it up
    with 10-36 N·m and the trot fell at 1.3 s (measured, seed 0).

    ``max_normal_z``: a row only where the unit normal from the closest terrain point has n_z below this value
    (default 1.0: every swing foot). With e.g. 0.7 a foot above the top of a step, a log or a bump (n_z near 1:
    the surface it is about to land on) gets no row, and a foot beside a riser face or at an edge (the normal
    tilts toward the horizontal) keeps it. Measured on steps with the terrain-following nominal (+experiment=terrain):
    the row bound on ~30 % of swing ticks, mostly braking the descent onto a step's top in the second half of the
    swing (swing phase p10-p90 0.44-0.95 for the front feet)."""

    def __init__(self, world: BarrierWorld, name: str = "terrain_clearance", lift_m: float = 0.02,
                 touchdown_allowance_m: float = 0.015, role: str | None = OBSTACLE,
                 max_normal_z: float = 1.0) -> None:  # fmt: skip
        super().__init__(world, name)
        self.role = role  # the terrain parts it keeps the foot clear of (default the obstacles; None: all)
        self._has_parts = any(role is None or part.role == role for part in world.terrain.parts)
        self.terrain = world.terrain
        self.lift_m = float(lift_m)  # [m]
        self.touchdown_allowance_m = float(touchdown_allowance_m)  # [m]
        # [-] rows only where the terrain normal's z is below this (1: every swing foot)
        self.max_normal_z = number(f"filter.barriers.{name}.max_normal_z", max_normal_z, -1.0, 1.0)
        self._dist = np.empty(quad.N_LEGS)  # [m] per-tick scratch of the compiled write: distance, normal, point
        self._normal, self._point = np.empty((quad.N_LEGS, 3)), np.empty((quad.N_LEGS, 3))

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        if not self._has_parts:  # nothing of its role in this world: the rows stay inactive (init)
            return
        packed, m = self.terrain.packed(self.role), x.model
        if not packed.compiled:  # a part only Python measures
            self.write_python(qp, x)
            return
        _terrain_distance_rows(packed.rows, packed.field_heights, packed.field_grid, packed.has_field,
                               m.foot_pos_in_world, self.foot_radius_m, self._dist, self._normal, self._point, qp.G,
                               qp.h, self.start, m.foot_vel_in_world, m.foot_jac_in_world, m.foot_jdotv_in_world,
                               x.in_stance, x.swing_phase, x.swing_phase_rate, 16.0 * self.lift_m,
                               self.touchdown_allowance_m, self.max_normal_z, self.alpha1, self.alpha2, self.h,
                               self.h_e)  # fmt: skip
        self.tighten(qp)

    def write_python(self, qp: QPProblem, x: TickInputs) -> None:
        """:meth:`write` with the terrain measured through :meth:`Terrain.near_distance` (a part the compiled
        query does not know; the reference of the compiled write in the tests)."""
        m = x.model
        dist, normal, _ = self.terrain.near_distance(m.foot_pos_in_world, self.foot_radius_m, role=self.role)
        _terrain_rows(qp.G, qp.h, self.start, dist, normal, m.foot_vel_in_world, m.foot_jac_in_world,
                      m.foot_jdotv_in_world, x.in_stance, x.swing_phase, x.swing_phase_rate, 16.0 * self.lift_m,
                      self.touchdown_allowance_m, self.max_normal_z, self.alpha1, self.alpha2, self.h,
                      self.h_e)  # fmt: skip
        self.tighten(qp)


@kernel
def _terrain_distance_rows(rows, field_heights, field_grid, has_field, foot_pos, radius, dist, normal, point, G, hvec,
                           r0, foot_vel, foot_jac, foot_jdotv, in_stance, swing_phase, sdot, k_lift, allowance,
                           max_normal_z, alpha1, alpha2, h_out, he_out):  # fmt: skip
    """The foot spheres' distances to the packed terrain (:func:`terrain_distance`, into the scratch ``dist``,
    ``normal``, ``point``), then the rows (:func:`_terrain_rows`): :meth:`TerrainClearance.write` in one call."""
    terrain_distance(rows, field_heights, field_grid, has_field, foot_pos, radius, 0.0, dist, normal, point)
    _terrain_rows(G, hvec, r0, dist, normal, foot_vel, foot_jac, foot_jdotv, in_stance, swing_phase, sdot, k_lift,
                  allowance, max_normal_z, alpha1, alpha2, h_out, he_out)


@kernel
def _terrain_rows(G, hvec, r0, dist, normal, foot_vel, foot_jac, foot_jdotv, in_stance, swing_phase, sdot, k_lift,
                  allowance, max_normal_z, alpha1, alpha2, h_out, he_out):  # fmt: skip
    """Row r0 + i per foot (see :class:`TerrainClearance`), c(s) = k_lift s² (1 - s)² - allowance s⁴."""
    nv = foot_jac.shape[2]
    for i in range(foot_jac.shape[0]):
        r = r0 + i
        if in_stance[i] or not np.isfinite(dist[i]) or (max_normal_z < 1.0 and normal[i, 2] >= max_normal_z):
            _inactive_barrier_row(G, hvec, r, h_out, he_out, i)
            continue
        s = swing_phase[i]
        c = k_lift * s * s * (1 - s) ** 2 - allowance * s**4
        dc = k_lift * (2 * s - 6 * s * s + 4 * s**3) - 4.0 * allowance * s**3
        ddc = k_lift * (2 - 12 * s + 12 * s * s) - 12.0 * allowance * s * s
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        h = dist[i] - c
        hdot = n0 * foot_vel[i, 0] + n1 * foot_vel[i, 1] + n2 * foot_vel[i, 2] - dc * sdot
        h_e = hdot + alpha1 * h
        for col in range(nv):
            G[r, col] = -(n0 * foot_jac[i, 0, col] + n1 * foot_jac[i, 1, col] + n2 * foot_jac[i, 2, col])
        hvec[r] = (alpha2 * h_e + alpha1 * hdot + n0 * foot_jdotv[i, 0] + n1 * foot_jdotv[i, 1]
                   + n2 * foot_jdotv[i, 2] - ddc * sdot * sdot)
        h_out[i], he_out[i] = h, h_e
