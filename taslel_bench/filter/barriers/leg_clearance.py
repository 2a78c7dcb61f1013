"""Whole-leg clearance (``filter.barriers.shin`` and ``filter.barriers.knee``, preset ``filter=terrain``): the
lower leg (a capsule from the knee towards the foot) or the knee (a sphere at the calf joint) kept off the
terrain and its obstacles, for every leg (a stance leg's shin can hit a log as the trunk moves over it)."""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.barriers.leg_points import LegPoints, _point_terms
from taslel_bench.filter.layout import INACTIVE_RHS, NV, TickInputs
from taslel_bench.interfaces import OBSTACLE, QPProblem
from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.packed import terrain_distance_within
from taslel_bench.util.jit import kernel

PARTS = ("shin", "knee")
SHIN_SAMPLES = 6  # points along the shin's axis (the closest of them is the capsule's closest point)


class LegClearance(Barrier):
    """One row per leg: h = d >= 0, d the distance [m] of a lower-leg piece to the terrain, with the Jacobian
    of the closest point. ``part``: ``shin`` -- a capsule of radius ``radius_m`` on the axis knee -> foot
    centre, from the knee to ``axis_fraction`` of the way (the rest is inside the foot sphere's reach), its
    distance the smallest over SHIN_SAMPLES points of the axis; ``knee`` -- a sphere of
    radius ``radius_m`` at the calf joint. A row is active only where h < ``activation_m`` (far legs get an
    inactive row, the solver sees fewer binding rows). ``role``: the parts measured -- by default the obstacles
    (logs, steps, a rough field): a shin on the flat floor is not a trip, and rows against the floor under a
    stance leg made the QP infeasible on 6 % of flat-ground ticks (measured, seed 0).

    With n the unit normal from the terrain to the closest axis point p (fixed to the calf body for this tick),
    hdot = n . v_p, hddot >= n . (J_p vdot + J̇_p v) (the distance's Hessian, positive semi-definite, dropped:
    conservative): -n'J_p vdot <= a2 h_e + a1 hdot + n . J̇_p v."""

    def __init__(self, world: BarrierWorld, name: str = "shin", part: str = "shin", radius_m: float | None = None,
                 axis_fraction: float | None = None, activation_m: float = 0.08, role: str | None = OBSTACLE,
                 swing_only: bool = False) -> None:  # fmt: skip
        super().__init__(world, name)
        if part not in PARTS:
            raise ValueError(f"filter.barriers.{name}.part={part!r}; valid: {', '.join(PARTS)}")
        self.terrain, self.part = world.terrain, part
        robot = world.robot  # radius and axis fraction default to the robot's shin capsule
        self.radius_m = float(radius_m if radius_m is not None else robot.shin_radius_m)  # [m]
        self.axis_fraction = float(axis_fraction if axis_fraction is not None else robot.shin_axis_fraction)  # [-]
        self.activation_m = float(activation_m)  # [m]
        self.role = role  # the terrain parts it keeps clear of (default the obstacles; None: every part)
        self._has_parts = any(role is None or part.role == role for part in world.terrain.parts)
        self.swing_only = bool(swing_only)  # rows for swing legs only (a stance leg's rows constrain the trunk)
        self._points: LegPoints | None = None
        self._fractions = np.linspace(0.0, self.axis_fraction, SHIN_SAMPLES)[None, :, None]  # along knee -> foot
        # the compiled write's inputs and per-tick scratch: axis points [m], their distances [m], normals, closest
        # terrain points [m], the legs with rows
        self._knee_only, self._fraction_list = part == "knee", np.ascontiguousarray(self._fractions.ravel())
        n = quad.N_LEGS * (1 if self._knee_only else SHIN_SAMPLES)
        self._scratch = (np.empty((n, 3)), np.empty(n), np.empty((n, 3)), np.empty((n, 3)), np.empty(quad.N_LEGS, bool))

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m = x.model
        if not self._has_parts:  # nothing of its role in this world: the rows stay inactive (init)
            return
        if self._points is None or self._points.model is not m or self._points.data is not m.data:
            self._points = LegPoints(m)  # (its knee views belong to one Pinocchio data object)
        packed = self.terrain.packed(self.role)
        if not packed.compiled:  # a part only Python measures
            self.write_python(qp, x)
            return
        k0, k1, k2, k3 = self._points.knee_views
        points, dist, normal, closest, legs = self._scratch
        d = m.data
        _leg_distance_rows(packed.rows, packed.field_heights, packed.field_grid, packed.has_field, k0, k1, k2, k3,
                           m.foot_pos_in_world, self._fraction_list, self._knee_only, self.radius_m, points,
                           dist, normal, closest, qp.G, qp.h, self.start, d.J, d.dJ, self._points.cols_array, x.v,
                           self.alpha1, self.alpha2, self.activation_m, x.in_stance, self.swing_only, legs, self.h,
                           self.h_e)  # fmt: skip
        self.tighten(qp)

    def write_python(self, qp: QPProblem, x: TickInputs) -> None:
        """:meth:`write` with the axis points in numpy and the terrain measured through
        :meth:`Terrain.near_distance` (a part the compiled query does not know; the reference of the compiled
        write in the tests)."""
        m, r0 = x.model, self.start
        if not self._has_parts:
            return
        if self._points is None or self._points.model is not m:
            self._points = LegPoints(m)
        knees = self._points.knees()  # [m] (4, 3)
        if self.part == "knee":
            axis = knees[:, None, :]
        else:  # SHIN_SAMPLES points from the knee to axis_fraction of the way to the foot centre, per leg
            axis = knees[:, None, :] + self._fractions * (m.foot_pos_in_world - knees)[:, None, :]
        points = np.ascontiguousarray(axis.reshape(-1, 3))
        dist, normal, _ = self.terrain.near_distance(points, self.radius_m, role=self.role)
        d = m.data
        legs = ~np.asarray(x.in_stance, bool) if self.swing_only else np.ones(quad.N_LEGS, bool)
        _leg_rows(qp.G, qp.h, r0, dist, normal, points, axis.shape[1], d.J, d.dJ, self._points.cols_array, x.v,
                  self.alpha1, self.alpha2, self.activation_m, legs, self.h, self.h_e)  # fmt: skip
        self.tighten(qp)


@kernel
def _leg_distance_rows(rows, field_heights, field_grid, has_field, k0, k1, k2, k3, foot_pos, fractions, knee_only,
                       radius, points, dist, normal, closest, G, hvec, r0, J_world, dJ_world, cols, v, alpha1, alpha2,
                       activation, in_stance, swing_only, legs, h_out, he_out):  # fmt: skip
    """:meth:`LegClearance.write` in one call: the axis points per leg (the knee ``k0`` .. ``k3`` [m, world] if
    ``knee_only``, else knee + f (foot - knee) for each of ``fractions``) into ``points``, their distances to the
    packed terrain (:func:`terrain_distance`), the legs with rows (every leg, or the swing legs if ``swing_only``)
    into ``legs``, then the rows (:func:`_leg_rows`)."""
    n_per_leg = 1 if knee_only else fractions.shape[0]
    for i in range(foot_pos.shape[0]):
        knee = k0 if i == 0 else k1 if i == 1 else k2 if i == 2 else k3
        for j in range(n_per_leg):
            for a in range(3):
                points[i * n_per_leg + j, a] = (
                    knee[a] if knee_only else knee[a] + fractions[j] * (foot_pos[i, a] - knee[a])
                )
        legs[i] = not in_stance[i] if swing_only else True
    # exact below the activation distance, the only distances the rows use (a point at least that far from a
    # heightfield is not measured to it: _hfield_distance_within)
    terrain_distance_within(rows, field_heights, field_grid, has_field, points, radius, 0.0, activation, dist, normal,
                            closest)  # fmt: skip
    _leg_rows(G, hvec, r0, dist, normal, points, n_per_leg, J_world, dJ_world, cols, v, alpha1, alpha2, activation,
              legs, h_out, he_out)


@kernel
def _leg_rows(G, hvec, r0, dist, normal, points, n_per_leg, J_world, dJ_world, cols, v, alpha1, alpha2, activation,
              legs, h_out, he_out):  # fmt: skip
    """Row r0 + i per leg i (see :class:`LegClearance`): the closest of the leg's ``n_per_leg`` axis points
    (``dist``, ``normal`` from the terrain query), its Jacobian on the calf body, the ECBF row; inactive
    (0 <= INACTIVE_RHS, nan h) where the distance is not finite or not below ``activation``."""
    nv = G.shape[1]
    jac = np.zeros((3, NV))
    vel, jdotv = np.zeros(3), np.zeros(3)
    for i in range(cols.shape[0]):
        r = r0 + i
        for c in range(nv):
            G[r, c] = 0.0
        hvec[r] = INACTIVE_RHS
        h_out[i], he_out[i] = np.nan, np.nan
        k = i * n_per_leg
        for j in range(i * n_per_leg + 1, (i + 1) * n_per_leg):
            if dist[j] < dist[k]:
                k = j
        d = dist[k]
        if not legs[i] or not np.isfinite(d) or d >= activation:
            continue
        jac[:] = 0.0
        _point_terms(J_world, dJ_world, cols[i], points[k], v, jac, vel, jdotv)
        n0, n1, n2 = normal[k, 0], normal[k, 1], normal[k, 2]
        hdot = n0 * vel[0] + n1 * vel[1] + n2 * vel[2]
        h_e = hdot + alpha1 * d
        for c in range(NV):
            G[r, c] = -(n0 * jac[0, c] + n1 * jac[1, c] + n2 * jac[2, c])
        hvec[r] = alpha2 * h_e + alpha1 * hdot + n0 * jdotv[0] + n1 * jdotv[1] + n2 * jdotv[2]
        h_out[i], he_out[i] = d, h_e
