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
still inside the true cone; on a level surface the basis stays the paper's. On flat ground with one mu the
rows are the paper's exactly (tests/test_filter.py). Same rows, labels and pattern as the paper's pyramid, so
a persistent backend sees one layout.
"""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.constraints import FrictionCone
from taslel_bench.filter.layout import NU, NV, TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import a1
from taslel_bench.terrain.parts import FrictionStrips, Plane
from taslel_bench.terrain.terrain import Terrain

CORNER_TOL_M = 0.005  # [m] a foot within this of two parts takes the more upward normal (floor beside a log)
CONTACT_TOL_M = 0.005  # [m] a foot farther than this from the terrain takes the normal of the surface under it


def contact_normals(terrain: Terrain, foot_pos_in_world: np.ndarray) -> np.ndarray:
    """(4, 3) unit normals of the terrain at the foot spheres: for a foot within CONTACT_TOL_M of the terrain
    the gradient of its distance to it (of two parts within CORNER_TOL_M, the more upward one: a foot on the
    floor against a log's side stands on the floor); for a foot farther away (a stance foot that has not
    landed yet) the normal of the surface under it -- the nearest part could be a log's side beside it."""
    dist, normal, _ = terrain.near_distance(foot_pos_in_world, a1.FOOT_RADIUS_M, CORNER_TOL_M)
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
    d /= size
    e = cross3(normal, d)
    t1 = (d + e) / np.sqrt(2.0)
    return t1, cross3(normal, t1)


class TerrainFrictionCone(FrictionCone):
    """The square pyramid about each stance foot's terrain normal with its own mu (module doc)."""

    def __init__(self, lambda_min_n: float, terrain: Terrain, edge_downhill: bool = False) -> None:
        super().__init__(lambda_min_n)
        self.terrain = terrain
        self.basis = downhill_edge_basis if edge_downhill else tangent_basis  # (t1, t2) of a normal
        self.flat = all(isinstance(p, (Plane, FrictionStrips)) for p in terrain.parts)  # normal: world z
        self.normals = np.tile([0.0, 0.0, 1.0], (a1.N_LEGS, 1))  # the last normals used (world)
        self.mu_used = np.full(a1.N_LEGS, np.nan)  # [-] the last per-foot coefficients used
        self._written = np.full((a1.N_LEGS, 3), np.nan)  # normals the rows were last written with

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        if not self.flat:
            self.normals[:] = contact_normals(self.terrain, x.model.foot_pos_in_world)
        mu = x.mu_per_foot if x.mu_per_foot is not None else np.full(a1.N_LEGS, x.mu)
        for i in range(a1.N_LEGS):
            if x.in_stance[i]:
                same = self._stance[i] and mu[i] == self._mu[i] and np.array_equal(self.normals[i], self._written[i])
                if not same:  # rewrite a foot's rows only when its mode, normal or mu changed
                    self._write_foot_about(qp, i, self.normals[i], float(mu[i]))
            elif self._stance[i]:
                self._write_foot(qp, i, False, np.nan)
        self.mu_used[:] = mu

    def _write_foot_about(self, qp: QPProblem, i: int, n: np.ndarray, mu: float) -> None:
        r, c = self.start + 5 * i, NV + NU + 3 * i
        t1, t2 = self.basis(n)
        mu_t = mu / np.sqrt(2.0)
        block = qp.G[r : r + 5, c : c + 3]
        block[0], block[1], block[2] = -n, t1 - mu_t * n, -t1 - mu_t * n
        block[3], block[4] = t2 - mu_t * n, -t2 - mu_t * n
        qp.h[r : r + 5] = (-self.lambda_min_n, 0.0, 0.0, 0.0, 0.0)
        self._stance[i], self._mu[i] = True, mu
        self._written[i] = n
