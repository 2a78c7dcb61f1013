"""The world's geometry and surface, one object: what the plant is built with, what the barriers keep the
robot clear of, and what the contact and clearance metrics judge against.

A :class:`Terrain` is a tuple of parts (:mod:`taslel_bench.terrain.parts`: the floor, friction strips, logs,
boxes, or a class of your own with the same members). It edits the plant's ``MjSpec`` (:meth:`Terrain.build`,
with an explicit ``np.random.Generator`` for parts drawn at random) and answers, in world axes [m]:

* :meth:`height_at` / :meth:`normal_at` / :meth:`friction_at`: the surface under (x, y) -- the part whose top
  is highest there (:meth:`highest_along`: the highest of it along a segment);
* :meth:`sphere_distance` (every part) and :meth:`obstacle_distance` (obstacle parts only): signed distance
  of spheres to the terrain with its gradient (unit normal) and closest point;
* :meth:`capsule_distance`: the same for a capsule (a leg link), by the closest of points along its axis;
* :meth:`friction_under`: the friction under many (x, y) at once (metrics, after the episode).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from taslel_bench.terrain.geoms import add_obstacle_sensors, obstacle_body
from taslel_bench.terrain.packed import PackedTerrain, highest_along, surface_height, surface_normal
from taslel_bench.terrain.parts import GROUND, OBSTACLE, Distances, Log, Plane, TerrainPart

CAPSULE_SAMPLES = 9  # points along a capsule's axis in :meth:`Terrain.capsule_distance`


@dataclass(frozen=True)
class Terrain:
    parts: tuple[TerrainPart, ...] = (Plane(),)
    _uniform_friction: float | None = field(init=False, repr=False, compare=False)
    _packs: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # a part with one coefficient has ``friction``; one whose friction varies (FrictionStrips) has not
        frictions = {getattr(p, "friction", None) for p in self.parts}
        one = frictions.pop() if len(frictions) == 1 else None  # None: a part without one, or several
        object.__setattr__(self, "parts", tuple(self.parts))
        object.__setattr__(self, "_uniform_friction", float(one) if one is not None else None)
        object.__setattr__(self, "_packs", {})  # role -> PackedTerrain (packed())

    # ------------------------------------------------------------------------------------------ plant
    def build(self, spec: mujoco.MjSpec, rng: np.random.Generator) -> None:
        """Add every part to the plant spec: ground parts on the world body, obstacle parts on the static
        obstacle body (``obstacles_<i>``), whose per-foot contact sensors count trips."""
        obstacles = [p for p in self.parts if p.role == OBSTACLE]
        body = obstacle_body(spec) if obstacles else None
        n_ground = n_obstacle = 0
        for part in self.parts:
            if part.role == OBSTACLE:
                assert body is not None  # made above: there are obstacle parts
                part.add_to(spec, body, f"{body.name}_{n_obstacle}", rng)
                n_obstacle += 1
            else:
                part.add_to(spec, spec.worldbody, f"terrain_{n_ground}", rng)
                n_ground += 1
        if obstacles:
            add_obstacle_sensors(spec)

    # ----------------------------------------------------------------------------------- the surface
    def surface_part(self, x: float, y: float) -> TerrainPart:
        """The part whose top surface is highest over (x, y) (the first of equals)."""
        best, best_z = self.parts[0], -math.inf
        for part in self.parts:
            z = part.top_z(x, y)
            if z > best_z:
                best, best_z = part, z
        return best

    def height_at(self, x: float, y: float) -> float:
        """World z [m] of the surface over (x, y) (compiled when every part's kind is known to
        :mod:`taslel_bench.terrain.packed`: the same numbers)."""
        packed = self.packed()
        if packed.compiled:
            return surface_height(packed.surface_rows, packed.field_heights, packed.field_grid, float(x), float(y))
        return max(part.top_z(x, y) for part in self.parts)

    def highest_along(self, start_xy: tuple[float, float], end_xy: tuple[float, float], samples: int) -> float:
        """The largest :meth:`height_at` [m, world z] at ``samples`` + 1 evenly spaced points from ``start_xy`` to
        ``end_xy`` [m, world] (both ends included; compiled as :meth:`height_at`)."""
        (x0, y0), (x1, y1) = start_xy, end_xy
        packed = self.packed()
        if packed.compiled:
            return highest_along(packed.surface_rows, packed.field_heights, packed.field_grid, float(x0), float(y0),
                                 float(x1), float(y1), int(samples))  # fmt: skip
        return max(self.height_at(x0 + (x1 - x0) * k / samples, y0 + (y1 - y0) * k / samples)
                   for k in range(samples + 1))  # fmt: skip

    def normal_at(self, x: float, y: float) -> np.ndarray:
        """Unit upward normal (3,) of the surface over (x, y) (compiled as :meth:`height_at`)."""
        packed = self.packed()
        if packed.compiled:
            out = np.empty(3)
            surface_normal(packed.surface_rows, packed.field_heights, packed.field_grid, float(x), float(y), out)
            return out
        return self.surface_part(x, y).normal(x, y)

    def friction_at(self, xy_in_world) -> float:
        """Coulomb coefficient [-] of the surface over world (x, y) [m] (called every control tick: a terrain
        with one friction answers without looking)."""
        if self._uniform_friction is not None:
            return self._uniform_friction
        x, y = float(xy_in_world[0]), float(xy_in_world[1])
        return self.surface_part(x, y).friction_at(x, y)

    def friction_under(self, xy: np.ndarray) -> np.ndarray:
        """Friction [-] under each of ``xy`` (..., 2) [m] (repeated points answered once)."""
        xy = np.asarray(xy, float)
        flat = xy.reshape(-1, 2)
        if self._uniform_friction is not None:
            return np.full(xy.shape[:-1], self._uniform_friction)
        cache: dict[tuple[float, float], float] = {}
        out = np.empty(flat.shape[0])
        for j, (x, y) in enumerate(flat):
            key = (float(x), float(y))
            if key not in cache:
                cache[key] = self.friction_at(key)
            out[j] = cache[key]
        return out.reshape(xy.shape[:-1])

    # --------------------------------------------------------------------------------------- distances
    def sphere_distance(self, centres: np.ndarray, radius: float, role: str | None = None,
                        reach_m: float | None = None) -> Distances:
        """For spheres (n, 3) [m] of radius ``radius`` [m]: signed distance [m] to the nearest part (of
        ``role`` if given), its unit normal (the gradient wrt the centre) and the closest point. Distances
        are +inf (normals up) when no part has the role. ``reach_m``: skip parts with an ``x_range`` farther
        than this along x from every centre (their distance is then larger than ``reach_m``; a per-tick
        query near the robot)."""
        c = np.asarray(centres, float).reshape(-1, 3)
        d = np.full(len(c), np.inf)
        normal = np.tile(np.array([0.0, 0.0, 1.0]), (len(c), 1))
        point = c.copy()
        x_lo, x_hi = (float(c[:, 0].min()), float(c[:, 0].max())) if len(c) else (0.0, 0.0)
        for part in self.parts:
            if role is not None and part.role != role:
                continue
            if reach_m is not None and (x_range := getattr(part, "x_range", None)) is not None:
                a, b = x_range()
                if a - x_hi > reach_m or x_lo - b > reach_m:
                    continue
            dp, n_p, p_p = part.sphere_distance(c, radius)
            closer = dp < d
            d, normal[closer], point[closer] = np.where(closer, dp, d), n_p[closer], p_p[closer]
        return d, normal, point

    def near_distance(self, centres: np.ndarray, radius: float, upward_tol_m: float = 0.0,
                      role: str | None = None) -> Distances:
        """:meth:`sphere_distance` over every part, for the control tick: the simple parts through one compiled
        kernel (:mod:`taslel_bench.terrain.packed`, same numbers) with one heightfield, parts of other kinds in
        Python.
        ``upward_tol_m``: see :meth:`PackedTerrain.sphere_distance` (the contact normal of a foot in a corner).
        ``role``: only the parts of that role (+inf distances without any)."""
        return self.packed(role).sphere_distance(centres, radius, upward_tol_m)

    def packed(self, role: str | None = None) -> PackedTerrain:
        """The parts of ``role`` (every part: None) packed for the compiled query, made on the first call and kept
        (once a heightfield's heights are drawn: :meth:`build`)."""
        packed = self._packs.get(role)
        if packed is None:
            packed = PackedTerrain([p for p in self.parts if role is None or p.role == role])
            if not packed.pending:
                self._packs[role] = packed
        return packed

    def obstacle_distance(self, centres: np.ndarray, radius: float) -> Distances:
        """:meth:`sphere_distance` to the obstacle parts only (+inf without obstacles)."""
        return self.sphere_distance(centres, radius, OBSTACLE)

    def capsule_distance(self, p0: np.ndarray, p1: np.ndarray, radius: float,
                         role: str | None = None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """A capsule of axis p0 -> p1 [m] and radius ``radius`` [m] (a leg link): (signed distance [m], unit
        normal, closest terrain point, the point on the axis it is measured from), the smallest over
        :data:`CAPSULE_SAMPLES` points along the axis (exact for planes; within the sampling step otherwise)."""
        s = np.linspace(0.0, 1.0, CAPSULE_SAMPLES)[:, None]
        axis_points = (1.0 - s) * np.asarray(p0, float) + s * np.asarray(p1, float)
        d, normal, point = self.sphere_distance(axis_points, radius, role)
        k = int(np.argmin(d))
        return float(d[k]), normal[k], point[k], axis_points[k]

    # ---------------------------------------------------------------------------------------- queries
    @property
    def uniform_friction(self) -> float | None:
        """The one Coulomb coefficient [-] of every part, None when the friction varies over the terrain."""
        return self._uniform_friction

    @property
    def has_obstacles(self) -> bool:
        return any(p.role == OBSTACLE for p in self.parts)

    def logs(self) -> tuple[Log, ...]:
        """The logs across the path (the swing-foot log barrier's geometry)."""
        return tuple(p for p in self.parts if isinstance(p, Log))

    def ground_parts(self) -> tuple[TerrainPart, ...]:
        return tuple(p for p in self.parts if p.role == GROUND)
