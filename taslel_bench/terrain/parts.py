"""The pieces a :class:`taslel_bench.terrain.terrain.Terrain` is made of: each one edits the plant's MjSpec and
answers what is true about its geometry (the same numbers the plant's collision geometry gives).

Frames and units: world axes, z up, metres. Every part has

* a **role**: :data:`GROUND` (what feet stand on) or :data:`OBSTACLE` (what a foot should step over: a touch
  outside stance is a trip; obstacle geoms hang on :data:`taslel_bench.terrain.geoms.OBSTACLE_BODY`);
* ``add_to(spec, body, name, rng)``: its MuJoCo geoms (static, terrain contact settings);
* ``top_z(x, y)``: the world z [m] of its upper surface over (x, y), ``-inf`` where it has none;
* ``normal(x, y)``: the unit upward normal of that surface;
* ``friction_at(x, y)``: its Coulomb coefficient [-] there;
* ``sphere_distance(centres, radius)``: for spheres of radius ``radius`` [m] at ``centres`` (n, 3) [m], the
  signed distance [m] of each sphere's surface to the part (< 0: penetrating), its gradient with respect to
  the centre (the unit normal pointing from the part to the sphere) and the closest point on the part.

A new kind of terrain is one class with these members (see docs/guides/extending.md).
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

from taslel_bench.terrain.geoms import add_terrain_geom, make_terrain

GROUND, OBSTACLE = "ground", "obstacle"
UP = np.array([0.0, 0.0, 1.0])
Distances = tuple[np.ndarray, np.ndarray, np.ndarray]  # (n,) [m], (n, 3) unit normals, (n, 3) points [m]


@runtime_checkable
class TerrainPart(Protocol):
    @property
    def role(self) -> str: ...  # GROUND or OBSTACLE; read-only, so frozen dataclasses match

    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None: ...

    def top_z(self, x: float, y: float) -> float: ...

    def normal(self, x: float, y: float) -> np.ndarray: ...

    def friction_at(self, x: float, y: float) -> float: ...

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances: ...


def _plane_distance(centres: np.ndarray, radius: float, z: float = 0.0) -> Distances:
    """Spheres above the horizontal plane at height ``z`` [m]."""
    c = np.asarray(centres, float).reshape(-1, 3)
    points = c.copy()
    points[:, 2] = z
    return c[:, 2] - z - radius, np.tile(UP, (len(c), 1)), points


@dataclass(frozen=True)
class Plane:
    """The flat floor z = 0 with one friction coefficient: the plant's own floor geom (named ``floor``, from
    the URDF plant or the plant file), whose friction is set to ``friction``."""

    friction: float = 1.0  # [-]
    role: str = GROUND

    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None:
        spec.geom("floor").friction[0] = self.friction

    def top_z(self, x: float, y: float) -> float:
        return 0.0

    def normal(self, x: float, y: float) -> np.ndarray:
        return UP.copy()

    def friction_at(self, x: float, y: float) -> float:
        return self.friction

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances:
        return _plane_distance(centres, radius)


@dataclass(frozen=True)
class FrictionStrips:
    """The floor z = 0 in strips across the path: friction ``frictions[i]`` between world x = ``edges_x_m[i-1]``
    and ``edges_x_m[i]`` (the first strip from -``half_length_m``, the last to +``half_length_m`` beyond the
    outer edges); a point on an edge belongs to the strip after it. Replaces the plant's floor by one box per
    strip (top face at z = 0, ``thickness_m`` thick)."""

    edges_x_m: tuple[float, ...]  # [m] increasing
    frictions: tuple[float, ...]  # [-] one more than edges
    half_length_m: float = 50.0  # [m] extent beyond the outer edges, and half-width along y
    thickness_m: float = 0.1  # [m]
    role: str = GROUND

    def __post_init__(self) -> None:
        if len(self.frictions) != len(self.edges_x_m) + 1 or list(self.edges_x_m) != sorted(self.edges_x_m):
            raise ValueError("FrictionStrips: frictions needs one entry more than the increasing edges_x_m")

    def _strip_boxes(self) -> list[tuple[float, float]]:
        """(centre x, half length) [m] of each strip's box."""
        e, half = self.edges_x_m, self.half_length_m
        boxes = [(e[0] - half, half)]
        boxes += [((a + b) / 2.0, (b - a) / 2.0) for a, b in itertools.pairwise(e)]
        return boxes + [(e[-1] + half, half)]

    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None:
        spec.delete(spec.geom("floor"))
        names = ("floor_before", "floor_after") if len(self.frictions) == 2 else None
        for i, ((cx, half_x), mu) in enumerate(zip(self._strip_boxes(), self.frictions, strict=True)):
            shade = 0.55 + 0.35 * i / max(1, len(self.frictions) - 1)
            add_terrain_geom(spec, name=names[i] if names else f"floor_{i}", type=mujoco.mjtGeom.mjGEOM_BOX,
                             size=[half_x, self.half_length_m, self.thickness_m / 2], friction=mu,
                             pos=(cx, 0.0, -self.thickness_m / 2), rgba=(0.55, 0.6, shade, 1.0))  # fmt: skip

    def top_z(self, x: float, y: float) -> float:
        return 0.0

    def normal(self, x: float, y: float) -> np.ndarray:
        return UP.copy()

    def friction_at(self, x: float, y: float) -> float:
        return self.frictions[bisect.bisect_right(self.edges_x_m, float(x))]

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances:
        return _plane_distance(centres, radius)


@dataclass(frozen=True)
class Log:
    """A cylinder lying across the path, its axis along world y through (``x_m``, ``y_m``, ``z_m``), radius
    ``radius_m``, spanning y in ``y_m`` +- ``half_width_m``: a MuJoCo capsule (exact sphere-capsule contact,
    so the distance below is the collision's). Its top is ``z_m + radius_m``; sunk into the floor when
    ``z_m < radius_m``. ``top_z`` ignores the capsule's rounded ends beyond the half width."""

    x_m: float
    z_m: float
    radius_m: float
    half_width_m: float = 0.5
    friction: float = 1.0
    y_m: float = 0.0
    role: str = OBSTACLE

    @property
    def top_m(self) -> float:
        return self.z_m + self.radius_m

    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None:
        axis_along_y = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # capsule axis: local z -> world y
        geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                             size=[self.radius_m, self.half_width_m, 0.0], pos=[self.x_m, self.y_m, self.z_m],
                             quat=axis_along_y, rgba=[0.55, 0.4, 0.25, 1.0])  # fmt: skip
        make_terrain(geom, self.friction)

    def _over(self, x: float, y: float) -> float:
        """(x - x_m)² - R² (< 0 over the log) or +inf outside its length."""
        if abs(y - self.y_m) > self.half_width_m:
            return math.inf
        return (x - self.x_m) ** 2 - self.radius_m**2

    def top_z(self, x: float, y: float) -> float:
        over = self._over(x, y)
        return self.z_m + math.sqrt(-over) if over <= 0.0 else -math.inf

    def normal(self, x: float, y: float) -> np.ndarray:
        if self._over(x, y) > 0.0:
            return UP.copy()
        dx = x - self.x_m
        return np.array([dx, 0.0, math.sqrt(max(self.radius_m**2 - dx * dx, 0.0))]) / self.radius_m

    def friction_at(self, x: float, y: float) -> float:
        return self.friction

    def x_range(self) -> tuple[float, float]:
        return self.x_m - self.radius_m, self.x_m + self.radius_m

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances:
        c = np.asarray(centres, float).reshape(-1, 3)
        dx, dz = c[:, 0] - self.x_m, c[:, 2] - self.z_m
        beyond = np.abs(c[:, 1] - self.y_m) - self.half_width_m
        dy = np.where(beyond > 0.0, np.copysign(np.maximum(beyond, 0.0), c[:, 1] - self.y_m), 0.0)
        rho = np.hypot(np.hypot(dx, dy), dz)  # = hypot(dx, dz) exactly over the log's length (dy = 0)
        safe = np.maximum(rho, 1e-12)
        normal = np.stack([dx, dy, dz], axis=1) / safe[:, None]
        axis_point = np.stack([np.full_like(dx, self.x_m), c[:, 1] - dy, np.full_like(dx, self.z_m)], axis=1)
        return rho - self.radius_m - radius, normal, axis_point + self.radius_m * normal


@dataclass(frozen=True)
class Box:
    """An axis-aligned box (a step, a block) centred at ``centre_m`` with half sizes ``half_size_m`` [m]."""

    centre_m: tuple[float, float, float]
    half_size_m: tuple[float, float, float]
    friction: float = 1.0
    role: str = GROUND

    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None:
        add_terrain_geom(spec, name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=list(self.half_size_m),
                         friction=self.friction, pos=self.centre_m, body=body,
                         rgba=(0.5, 0.5, 0.55, 1.0))  # fmt: skip

    def top_z(self, x: float, y: float) -> float:
        (cx, cy, cz), (hx, hy, hz) = self.centre_m, self.half_size_m
        return cz + hz if abs(x - cx) <= hx and abs(y - cy) <= hy else -math.inf

    def normal(self, x: float, y: float) -> np.ndarray:
        return UP.copy()

    def friction_at(self, x: float, y: float) -> float:
        return self.friction

    def x_range(self) -> tuple[float, float]:
        return self.centre_m[0] - self.half_size_m[0], self.centre_m[0] + self.half_size_m[0]

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances:
        centre = np.asarray(self.centre_m, float)
        d, normal, closest = box_distance(np.asarray(centres, float).reshape(-1, 3) - centre,
                                          np.asarray(self.half_size_m, float))
        return d - radius, normal, closest + centre


def box_distance(local: np.ndarray, half: np.ndarray) -> Distances:
    """Points ``local`` (n, 3) in the frame of a box of half sizes ``half`` [m] centred at the origin: signed
    distance to its surface (< 0 inside), the outward unit normal (gradient) and the closest surface point."""
    closest = np.clip(local, -half, half)
    outside = local - closest
    out_dist = np.linalg.norm(outside, axis=1)
    inside = out_dist == 0.0
    d = out_dist.copy()
    normal = outside / np.maximum(out_dist, 1e-12)[:, None]
    if inside.any():  # inside: distance to the nearest face (negative), normal of that face
        gap = half - np.abs(local[inside])
        axis = np.argmin(gap, axis=1)
        rows = np.arange(axis.size)
        d[inside] = -gap[rows, axis]
        n_in = np.zeros((axis.size, 3))
        n_in[rows, axis] = np.sign(local[inside][rows, axis]) + (local[inside][rows, axis] == 0.0)
        normal[inside] = n_in
        pts = local[inside].copy()
        pts[rows, axis] = half[axis] * n_in[rows, axis]
        closest[inside] = pts
    return d, normal, closest
