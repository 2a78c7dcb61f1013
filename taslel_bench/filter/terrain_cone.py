"""Per-foot friction pyramids about the terrain normal under each foot (``filter.friction_cone: terrain``).

The paper's :class:`taslel_bench.filter.constraints.FrictionCone` uses world z as every foot's normal and one
mu for all four feet. Here a stance foot i gets the square pyramid about the contact normal n_i of the terrain
at that foot (the gradient of the foot sphere's distance to the terrain: on flat ground world z, on a log the
radial direction, on a slope or a heightfield triangle its face normal) with its own coefficient mu_i
(``TickInputs.mu_per_foot`` when the estimator gives one per foot, else the single ``mu`` broadcast):

    -n_i . lambda_i <= -lambda_min,   |t_k . lambda_i| <= (mu_i / sqrt 2) n_i . lambda_i  (k = 1, 2),

t_1 = world x projected on the tangent plane (normalised), t_2 = n_i x t_1; lambda_i on the robot, world
axes [N]. The square pyramid meets the true cone only along its four edges (t_1 +- t_2): along t_1 its
half-angle is atan(mu/sqrt 2), 35.3 deg at mu = 1, so a vertical force on a surface tilted more than that along
world x (a log's side: 10 % of loaded stance ticks on `logs`) is outside it although the true cone (45 deg)
holds it. ``edge_downhill`` (``filter.cone_edge_downhill``) turns the pyramid about n_i so that an edge lies
along the slope's steepest direction d (t_1 = (d + n x d)/sqrt 2): full mu up and down the slope, the pyramid
still inside the true cone; on a level surface the basis stays the paper's. ``edge_along_nominal``
(``filter.cone_edge_along_nominal``) turns it instead so that an edge lies along the tangential part of the
force the nominal torques would produce this tick (:attr:`TerrainFrictionCone.nominal_force`, from the
filter's own equality rows): the pyramid then holds the nominal's force whenever the true cone of the same mu
does, and its conservatism (mu/sqrt 2 across the edges) falls in directions the nominal is not pushing. Where
that tangential force is below EDGE_MIN_TANGENTIAL_N the downhill (or paper's) basis is used. On flat ground
with one mu and neither option the rows are the paper's exactly (tests/test_filter.py). Same rows, labels and
pattern as the paper's pyramid, so a persistent backend sees one layout.
"""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.constraints import FrictionCone
from taslel_bench.filter.layout import INACTIVE_RHS, NU, NV, TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.packed import _norm3, surface_normal, terrain_distance
from taslel_bench.terrain.parts import FrictionStrips, Plane
from taslel_bench.terrain.terrain import Terrain
from taslel_bench.util.jit import kernel

CORNER_TOL_M = 0.005  # [m] a foot within this of two parts takes the more upward normal (floor beside a log)
CONTACT_TOL_M = 0.005  # [m] a foot farther than this from the terrain takes the normal of the surface under it
EDGE_MIN_TANGENTIAL_N = 0.5  # [N] a nominal force with less tangential part than this does not turn the pyramid


def contact_normals(terrain: Terrain, foot_pos_in_world: np.ndarray, foot_radius_m: float) -> np.ndarray:
    """(4, 3) unit normals of the terrain at the foot spheres: for a foot within CONTACT_TOL_M of the terrain
    the gradient of its distance to it (of two parts within CORNER_TOL_M, the more upward one: a foot on the
    floor against a log's side stands on the floor); for a foot farther away (a stance foot that has not
    landed yet) the normal of the surface under it -- the nearest part could be a log's side beside it."""
    dist, normal, _ = terrain.near_distance(foot_pos_in_world, foot_radius_m, CORNER_TOL_M)
    for i in np.flatnonzero(dist > CONTACT_TOL_M):
        normal[i] = terrain.normal_at(float(foot_pos_in_world[i, 0]), float(foot_pos_in_world[i, 1]))
    return normal


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors, in the same float operations as ``np.cross`` (the same bits) at ~1/20 of its
    cost on one pair (np.cross: ~29 us here)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2): world x projected on the plane normal to ``normal`` (world y if x is parallel), then n x t1."""
    t1 = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    if np.linalg.norm(t1) < 1e-6:
        t1 = np.array([0.0, 1.0, 0.0]) - normal[1] * normal
    t1 /= np.linalg.norm(t1)
    return t1, cross3(normal, t1)


def downhill_edge_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2) with t1 - t2 along the steepest descent d of the plane normal to ``normal`` (a pyramid edge
    there); :func:`tangent_basis` when the plane is level (|n_z| within 1e-6 of 1)."""
    d = normal[2] * normal - np.array([0.0, 0.0, 1.0])  # -z projected on the tangent plane
    size = np.linalg.norm(d)
    if size < 1e-6:
        return tangent_basis(normal)
    return edge_basis(normal, d / size)


def edge_basis(normal: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2) with t1 - t2 along the unit tangent ``d`` (a pyramid edge there: full mu along d)."""
    e = cross3(normal, d)
    t1 = (d + e) / np.sqrt(2.0)
    return t1, cross3(normal, t1)


def nominal_edge_basis(normal: np.ndarray, force: np.ndarray, fallback) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2) with an edge along the tangential part of ``force`` [N] (world) on the plane normal to
    ``normal``; ``fallback(normal)`` when that part is below EDGE_MIN_TANGENTIAL_N."""
    fn = force[0] * normal[0] + force[1] * normal[1] + force[2] * normal[2]  # as the compiled write
    d = force - fn * normal
    size = np.linalg.norm(d)
    if size < EDGE_MIN_TANGENTIAL_N:
        return fallback(normal)
    return edge_basis(normal, d / size)


class TerrainFrictionCone(FrictionCone):
    """The square pyramid about each stance foot's terrain normal with its own mu (module doc)."""

    def __init__(self, lambda_min_n: float, terrain: Terrain, edge_downhill: bool = False,
                 edge_along_nominal: bool = False) -> None:
        super().__init__(lambda_min_n)
        self.terrain = terrain
        self.basis = downhill_edge_basis if edge_downhill else tangent_basis  # (t1, t2) of a normal
        self.edge_along_nominal = bool(edge_along_nominal)
        # [N] (4, 3) this tick's force on each foot under the nominal torques, world axes (set by the filter
        # before :meth:`write` when ``edge_along_nominal``)
        self.nominal_force = np.zeros((quad.N_LEGS, 3))
        self.flat = all(isinstance(p, (Plane, FrictionStrips)) for p in terrain.parts)  # normal: world z
        self.normals = np.tile([0.0, 0.0, 1.0], (quad.N_LEGS, 1))  # the last normals used (world)
        self.mu_used = np.full(quad.N_LEGS, np.nan)  # [-] the last per-foot coefficients used
        self._written = np.full((quad.N_LEGS, 3), np.nan)  # normals the rows were last written with
        self.edge_downhill = bool(edge_downhill)
        self._dist, self._point = np.empty(quad.N_LEGS), np.empty((quad.N_LEGS, 3))  # scratch of the compiled write

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        packed = self.terrain.packed()
        if not packed.compiled:  # a part only Python measures
            self.write_python(qp, x)
            return
        mu = self._feet_mu(x)
        _cone_rows(packed.rows, packed.field_heights, packed.field_grid, packed.has_field, packed.surface_rows,
                   x.model.foot_pos_in_world, x.model.robot.foot_radius_m, self.flat, self.edge_downhill,
                   self.edge_along_nominal, self.nominal_force, x.in_stance, mu, self.lambda_min_n, self.start, qp.G,
                   qp.h, self.normals, self._stance, self._mu, self._written, self._dist, self._point)  # fmt: skip

    def _feet_mu(self, x: TickInputs) -> np.ndarray:
        """``mu_used`` (4,) [-] set to this tick's coefficient of each foot: ``mu_per_foot``, or ``mu`` for all four
        (written in place: no array made per tick)."""
        self.mu_used[:] = x.mu_per_foot if x.mu_per_foot is not None else x.mu
        return self.mu_used

    def write_python(self, qp: QPProblem, x: TickInputs) -> None:
        """:meth:`write` with the normals from :func:`contact_normals` and each foot's rows in numpy (a part the
        compiled query does not know; the reference of the compiled write in the tests)."""
        if not self.flat:
            self.normals[:] = contact_normals(self.terrain, x.model.foot_pos_in_world, x.model.robot.foot_radius_m)
        mu = self._feet_mu(x)
        for i in range(quad.N_LEGS):
            if x.in_stance[i]:
                same = self._stance[i] and mu[i] == self._mu[i] and np.array_equal(self.normals[i], self._written[i])
                # rewrite a foot's rows only when its mode, normal or mu changed (turned with the nominal's force:
                # every tick)
                if not same or self.edge_along_nominal:
                    self._write_foot_about(qp, i, self.normals[i], float(mu[i]))
            elif self._stance[i]:
                self._write_foot(qp, i, False, np.nan)

    def _write_foot_about(self, qp: QPProblem, i: int, n: np.ndarray, mu: float) -> None:
        r, c = self.start + 5 * i, NV + NU + 3 * i
        if self.edge_along_nominal:
            t1, t2 = nominal_edge_basis(n, self.nominal_force[i], self.basis)
        else:
            t1, t2 = self.basis(n)
        mu_t = mu / np.sqrt(2.0)
        block = qp.G[r : r + 5, c : c + 3]
        block[0], block[1], block[2] = -n, t1 - mu_t * n, -t1 - mu_t * n
        block[3], block[4] = t2 - mu_t * n, -t2 - mu_t * n
        qp.h[r : r + 5] = (-self.lambda_min_n, 0.0, 0.0, 0.0, 0.0)
        self._stance[i], self._mu[i] = True, mu
        self._written[i] = n


# ------------------------------------------------------------------------------------------ compiled write
# The same float operations as the numpy code above (tests/test_terrain_filter.py compares the bits).


@kernel
def _cross_into(a, b, out):
    """out = a x b (as :func:`cross3`)."""
    out[0], out[1], out[2] = a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@kernel
def _tangent_basis_into(n, t1, t2):
    """:func:`tangent_basis` into ``t1``, ``t2``."""
    t1[0], t1[1], t1[2] = 1.0 - n[0] * n[0], 0.0 - n[0] * n[1], 0.0 - n[0] * n[2]
    if _norm3(t1) < 1e-6:
        t1[0], t1[1], t1[2] = 0.0 - n[1] * n[0], 1.0 - n[1] * n[1], 0.0 - n[1] * n[2]
    size = _norm3(t1)
    for a in range(3):
        t1[a] /= size
    _cross_into(n, t1, t2)


@kernel
def _downhill_edge_basis_into(n, t1, t2):
    """:func:`downhill_edge_basis` into ``t1``, ``t2`` (``t2`` is scratch for d, then for e)."""
    d = np.empty(3)
    d[0], d[1], d[2] = n[2] * n[0] - 0.0, n[2] * n[1] - 0.0, n[2] * n[2] - 1.0
    size = _norm3(d)
    if size < 1e-6:
        _tangent_basis_into(n, t1, t2)
        return
    for a in range(3):
        d[a] /= size
    _edge_basis_into(n, d, t1, t2)


@kernel
def _edge_basis_into(n, d, t1, t2):
    """:func:`edge_basis` into ``t1``, ``t2`` (``t2`` is scratch for e first)."""
    _cross_into(n, d, t2)  # e
    root2 = np.sqrt(2.0)
    for a in range(3):
        t1[a] = (d[a] + t2[a]) / root2
    _cross_into(n, t1, t2)


@kernel
def _foot_rows_about(G, hvec, r, c, n, mu, lambda_min, downhill, along_nominal, force):
    """A stance foot's 5 rows about the normal ``n`` with coefficient ``mu``
    (:meth:`TerrainFrictionCone._write_foot_about`; ``force``: the nominal's force on it, world)."""
    t1, t2 = np.empty(3), np.empty(3)
    turned = False
    if along_nominal:  # :func:`nominal_edge_basis`
        d = np.empty(3)
        fn = force[0] * n[0] + force[1] * n[1] + force[2] * n[2]
        for a in range(3):
            d[a] = force[a] - fn * n[a]
        size = _norm3(d)
        if size >= EDGE_MIN_TANGENTIAL_N:
            for a in range(3):
                d[a] /= size
            _edge_basis_into(n, d, t1, t2)
            turned = True
    if not turned and downhill:
        _downhill_edge_basis_into(n, t1, t2)
    elif not turned:
        _tangent_basis_into(n, t1, t2)
    mu_t = mu / np.sqrt(2.0)
    for a in range(3):
        G[r, c + a] = -n[a]
        G[r + 1, c + a] = t1[a] - mu_t * n[a]
        G[r + 2, c + a] = -t1[a] - mu_t * n[a]
        G[r + 3, c + a] = t2[a] - mu_t * n[a]
        G[r + 4, c + a] = -t2[a] - mu_t * n[a]
    hvec[r] = -lambda_min
    for k in range(1, 5):
        hvec[r + k] = 0.0


@kernel
def _cone_normals(rows, field_heights, field_grid, has_field, surface_rows, foot_pos, foot_radius, normals, dist,
                  point):  # fmt: skip
    """:func:`contact_normals` into ``normals`` (4, 3) (``dist``, ``point``: scratch)."""
    terrain_distance(rows, field_heights, field_grid, has_field, foot_pos, foot_radius, CORNER_TOL_M, dist,
                     normals, point)  # fmt: skip
    for i in range(foot_pos.shape[0]):
        if dist[i] > CONTACT_TOL_M:
            surface_normal(surface_rows, field_heights, field_grid, foot_pos[i, 0], foot_pos[i, 1], normals[i])


@kernel
def _cone_rows(rows, field_heights, field_grid, has_field, surface_rows, foot_pos, foot_radius, flat, downhill,
               along_nominal, nominal_force, in_stance, mu, lambda_min, r0, G, hvec, normals, stance, mu_written,
               written, dist, point):  # fmt: skip
    """:meth:`TerrainFrictionCone.write_python` in one call: the normals (unless ``flat``), then per foot its rows
    rewritten when its mode, normal or mu changed, or on every tick with ``along_nominal`` (``stance``,
    ``mu_written``, ``written``: what they were written with)."""
    if not flat:
        _cone_normals(rows, field_heights, field_grid, has_field, surface_rows, foot_pos, foot_radius, normals, dist,
                      point)
    for i in range(foot_pos.shape[0]):
        r, c = r0 + 5 * i, NV + NU + 3 * i
        if in_stance[i]:
            same = stance[i] and mu[i] == mu_written[i] and not along_nominal
            for a in range(3):
                same = same and normals[i, a] == written[i, a]
            if not same:
                _foot_rows_about(G, hvec, r, c, normals[i], mu[i], lambda_min, downhill, along_nominal,
                                 nominal_force[i])
                stance[i], mu_written[i] = True, mu[i]
                for a in range(3):
                    written[i, a] = normals[i, a]
        elif stance[i]:
            for k in range(5):
                for a in range(3):
                    G[r + k, c + a] = 0.0
                hvec[r + k] = INACTIVE_RHS
            stance[i], mu_written[i] = False, np.nan
