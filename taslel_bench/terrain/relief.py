"""Terrain parts with relief: an inclined plane (:class:`Ramp`, the ``slope`` scenario) and a MuJoCo heightfield
(:class:`HeightField`, the ``rough`` scenario). Same members as the parts of :mod:`taslel_bench.terrain.parts`
(role, ``add_to``, ``top_z``, ``normal``, ``friction_at``, ``sphere_distance``), world axes, z up, metres; each
answers what MuJoCo's collision geometry of the compiled plant gives (tests/test_terrain.py checks against
``mj_geomDistance`` and ``mj_ray``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from taslel_bench.terrain.geoms import add_terrain_geom, make_terrain
from taslel_bench.terrain.parts import GROUND, Distances, box_distance
from taslel_bench.util.jit import kernel


@dataclass(frozen=True)
class Ramp:
    """A plane rising at ``angle_deg`` along +x: its top surface is z = tan(angle) (x - ``start_x_m``) for x in
    [``start_x_m``, ``start_x_m`` + ``run_m``] and |y - ``y_m``| <= ``half_width_m``. In the plant, a box
    ``thickness_m`` thick pitched about world y whose top face is that surface (its lower edge sits at z = 0,
    its thickness below the floor). The box's end face below the upper edge leans forward (``thickness_m`` sin
    angle beyond it): cover it with what follows, e.g. a plateau :class:`Box` (the ``slope`` scenario does)."""

    start_x_m: float
    run_m: float  # [m] horizontal length of the incline
    angle_deg: float  # [deg] > 0: rising along +x
    half_width_m: float = 1.0
    thickness_m: float = 0.1
    friction: float = 1.0
    y_m: float = 0.0
    role: str = GROUND

    @property
    def rise_m(self) -> float:
        return self.run_m * math.tan(math.radians(self.angle_deg))

    def _frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rotation box -> world (3, 3), box centre [m], box half sizes [m]); box x along the incline, z its
        upward normal."""
        a = math.radians(self.angle_deg)
        c, s = math.cos(a), math.sin(a)
        rot = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
        half = np.array([self.run_m / (2.0 * c), self.half_width_m, self.thickness_m / 2.0])
        top_centre = np.array([self.start_x_m + self.run_m / 2.0, self.y_m, self.rise_m / 2.0])
        return rot, top_centre - half[2] * rot[:, 2], half

    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None:
        a = math.radians(self.angle_deg)
        _, centre, half = self._frame()
        quat = (math.cos(-a / 2.0), 0.0, math.sin(-a / 2.0), 0.0)  # rotation about y by -angle (wxyz)
        add_terrain_geom(spec, name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=list(half), friction=self.friction,
                         pos=tuple(centre), body=body, quat=list(quat), rgba=(0.5, 0.55, 0.5, 1.0))  # fmt: skip

    def top_z(self, x: float, y: float) -> float:
        inside = self.start_x_m <= x <= self.start_x_m + self.run_m and abs(y - self.y_m) <= self.half_width_m
        return math.tan(math.radians(self.angle_deg)) * (x - self.start_x_m) if inside else -math.inf

    def normal(self, x: float, y: float) -> np.ndarray:
        a = math.radians(self.angle_deg)
        return np.array([-math.sin(a), 0.0, math.cos(a)])

    def friction_at(self, x: float, y: float) -> float:
        return self.friction

    def x_range(self) -> tuple[float, float]:
        return self.start_x_m - self.thickness_m, self.start_x_m + self.run_m + self.thickness_m

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances:
        rot, centre, half = self._frame()
        local = (np.asarray(centres, float).reshape(-1, 3) - centre) @ rot  # world -> box axes
        d, normal, closest = box_distance(local, half)
        return d - radius, normal @ rot.T, closest @ rot.T + centre


@dataclass(frozen=True, eq=False)
class HeightField:
    """A MuJoCo heightfield: vertex heights ``heights_m`` (rows along world y, columns along x) [m, world z] on a
    regular grid centred at (``centre_x_m``, ``centre_y_m``) with half extents ``half_x_m``, ``half_y_m``.
    MuJoCo splits each cell into two triangles along the diagonal from (row r, col c) to (r + 1, c + 1); the
    surface here is the same triangulation, so heights, normals and distances are the plant's."""

    heights_m: np.ndarray | None  # (nrow, ncol) [m]; None: drawn by ``draw`` when the plant is built
    centre_x_m: float
    centre_y_m: float
    half_x_m: float
    half_y_m: float
    friction: float = 1.0
    base_m: float = 0.05  # [m] depth of MuJoCo's solid base below the lowest vertex
    role: str = GROUND
    draw: Callable[[np.random.Generator], np.ndarray] | None = None  # heights from the terrain's generator
    _grid: tuple[float, float, float, float] | None = field(init=False, repr=False)  # (x0, y0, dx, dy); None: not drawn

    def __post_init__(self) -> None:
        if self.heights_m is None:
            if self.draw is None:
                raise ValueError("HeightField: give heights_m or draw")
            object.__setattr__(self, "_grid", None)
            return
        self._set_heights(self.heights_m)

    def _set_heights(self, heights: np.ndarray) -> None:
        h = np.asarray(heights, float)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError("HeightField: heights_m must be a (nrow >= 2, ncol >= 2) array")
        object.__setattr__(self, "heights_m", h)
        dx, dy = 2.0 * self.half_x_m / (h.shape[1] - 1), 2.0 * self.half_y_m / (h.shape[0] - 1)
        object.__setattr__(self, "_grid", (self.centre_x_m - self.half_x_m, self.centre_y_m - self.half_y_m, dx, dy))

    # --------------------------------------------------------------------------------------- plant
    def add_to(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, rng: np.random.Generator) -> None:
        """The hfield asset and geom; a field without heights draws them from ``rng`` first (the one
        generator of the terrain, seeded from the run seed)."""
        if self.draw is not None and self.heights_m is None:
            self._set_heights(self.draw(rng))
        h, _ = self._drawn()  # given, or drawn just above (__post_init__ rejects a field with neither)
        lo, span = float(h.min()), max(float(h.max() - h.min()), 1e-9)
        spec.add_hfield(name=f"{name}_hfield", size=[self.half_x_m, self.half_y_m, span, self.base_m],
                        nrow=h.shape[0], ncol=h.shape[1], userdata=((h - lo) / span).ravel().tolist())  # fmt: skip
        geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=f"{name}_hfield",
                             pos=[self.centre_x_m, self.centre_y_m, lo], rgba=[0.5, 0.5, 0.45, 1.0])  # fmt: skip
        make_terrain(geom, self.friction)

    # ------------------------------------------------------------------------------------- surface
    def _drawn(self) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        """(heights, grid (x0, y0, dx, dy)) once the heights exist."""
        if self.heights_m is None or self._grid is None:
            raise RuntimeError("HeightField: heights are drawn when the plant is built (Terrain.build) first")
        return self.heights_m, self._grid

    def _cell(self, x: float, y: float) -> tuple[int, int, float, float] | None:
        h, (x0, y0, dx, dy) = self._drawn()
        u, w = (x - x0) / dx, (y - y0) / dy
        nrow, ncol = h.shape
        if not (0.0 <= u <= ncol - 1 and 0.0 <= w <= nrow - 1):
            return None
        c, r = min(int(u), ncol - 2), min(int(w), nrow - 2)
        return r, c, u - c, w - r

    def _plane(self, x: float, y: float) -> tuple[float, float, float] | None:
        """(z, dz/dx, dz/dy) of the triangle under (x, y), None outside the grid."""
        cell = self._cell(x, y)
        if cell is None:
            return None
        r, c, a, b = cell
        h, (_, _, dx, dy) = self._drawn()
        h00, h11 = h[r, c], h[r + 1, c + 1]
        if a >= b:  # triangle (r, c), (r, c + 1), (r + 1, c + 1)
            ga, gb = h[r, c + 1] - h00, h11 - h[r, c + 1]
        else:  # triangle (r, c), (r + 1, c), (r + 1, c + 1)
            ga, gb = h11 - h[r + 1, c], h[r + 1, c] - h00
        return h00 + ga * a + gb * b, ga / dx, gb / dy

    def top_z(self, x: float, y: float) -> float:
        plane = self._plane(x, y)
        return plane[0] if plane is not None else -math.inf

    def normal(self, x: float, y: float) -> np.ndarray:
        plane = self._plane(x, y)
        if plane is None:
            return np.array([0.0, 0.0, 1.0])
        n = np.array([-plane[1], -plane[2], 1.0])
        return n / np.linalg.norm(n)

    def friction_at(self, x: float, y: float) -> float:
        return self.friction

    def x_range(self) -> tuple[float, float]:
        return self.centre_x_m - self.half_x_m, self.centre_x_m + self.half_x_m

    # ------------------------------------------------------------------------------------ distance
    def _triangles_near(self, x: float, y: float, reach: int) -> np.ndarray:
        """(T, 3, 3) world vertices of the triangles of the cells within ``reach`` cells of (x, y)."""
        h, (x0, y0, dx, dy) = self._drawn()
        nrow, ncol = h.shape
        c = min(max(math.floor((x - x0) / dx), 0), ncol - 2)
        r = min(max(math.floor((y - y0) / dy), 0), nrow - 2)
        rows = np.arange(max(r - reach, 0), min(r + reach, nrow - 2) + 1)
        cols = np.arange(max(c - reach, 0), min(c + reach, ncol - 2) + 1)
        rr, cc = (a.ravel() for a in np.meshgrid(rows, cols, indexing="ij"))

        def vertex(ri, ci):
            return np.stack([x0 + ci * dx, y0 + ri * dy, h[ri, ci]], axis=-1)

        v00, v01, v10, v11 = vertex(rr, cc), vertex(rr, cc + 1), vertex(rr + 1, cc), vertex(rr + 1, cc + 1)
        return np.concatenate([np.stack([v00, v01, v11], 1), np.stack([v00, v10, v11], 1)])

    def sphere_distance(self, centres: np.ndarray, radius: float) -> Distances:
        """Distance of each sphere to the triangulated surface (the closest triangle of the cells within two
        cells of the centre; exact up to that horizontal reach), negative below the surface. Outside the grid:
        +inf. Compiled (:func:`heightfield_distance`); :meth:`sphere_distance_reference` is the same in numpy."""
        if self._grid is None:
            raise RuntimeError("HeightField: heights are drawn when the plant is built (Terrain.build) first")
        return heightfield_distance(self, centres, radius)

    def sphere_distance_reference(self, centres: np.ndarray, radius: float) -> Distances:
        """:meth:`sphere_distance` in numpy, triangle by triangle (the reference of the compiled one)."""
        c = np.asarray(centres, float).reshape(-1, 3)
        n = len(c)
        d, normal, point = np.full(n, np.inf), np.tile([0.0, 0.0, 1.0], (n, 1)), c.copy()
        for k in range(n):
            x, y, z = c[k]
            surface = self.top_z(x, y)
            if not math.isfinite(surface):
                continue
            tri = self._triangles_near(x, y, 2)
            q = _closest_on_triangles(c[k], tri)
            gap = np.linalg.norm(q - c[k], axis=1)
            j = int(np.argmin(gap))
            below = z < surface
            sign = -1.0 if below else 1.0
            d[k] = sign * gap[j] - radius
            if gap[j] > 1e-12:
                normal[k] = sign * (c[k] - q[j]) / gap[j]
            else:
                normal[k] = self.normal(x, y)
            point[k] = q[j]
        return d, normal, point


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Closest point to ``p`` (3,) on each triangle of ``tri`` (T, 3, 3): the projection on its plane when it
    falls inside, else the closest point of its three edges."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac = b - a, c - a
    nrm = np.cross(ab, ac)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    proj = p - np.sum((p - a) * nrm, axis=1, keepdims=True) * nrm
    # barycentric coordinates of the projection
    v0, v1, v2 = ab, ac, proj - a
    d00, d01, d11 = np.sum(v0 * v0, 1), np.sum(v0 * v1, 1), np.sum(v1 * v1, 1)
    d20, d21 = np.sum(v2 * v0, 1), np.sum(v2 * v1, 1)
    den = d00 * d11 - d01 * d01
    bv, bw = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
    inside = (bv >= 0.0) & (bw >= 0.0) & (bv + bw <= 1.0)
    best = proj.copy()
    best_gap = np.where(inside, np.linalg.norm(proj - p, axis=1), np.inf)
    for e0, e1 in ((a, b), (b, c), (c, a)):
        seg = e1 - e0
        t = np.clip(np.sum((p - e0) * seg, 1) / np.sum(seg * seg, 1), 0.0, 1.0)
        q = e0 + t[:, None] * seg
        gap = np.linalg.norm(q - p, axis=1)
        better = gap < best_gap
        best[better], best_gap[better] = q[better], gap[better]
    return best


def rough_heights(rng: np.random.Generator, nrow: int, ncol: int, amplitude_m: float, smoothing_cells: int,
                  flat_cols: int, ramp_cols: int) -> np.ndarray:  # fmt: skip
    """Seeded rough ground: uniform noise smoothed by a (2k + 1)² box filter (k = ``smoothing_cells``), scaled
    so its largest magnitude is ``amplitude_m``, zero on the first ``flat_cols`` columns (where the robot
    stands) and blended in linearly over the next ``ramp_cols``. (nrow, ncol) [m]."""
    k = max(int(smoothing_cells), 0)
    noise = rng.uniform(-1.0, 1.0, (nrow + 2 * k, ncol + 2 * k))
    kernel_sum = np.zeros((nrow, ncol))
    for i in range(2 * k + 1):
        for j in range(2 * k + 1):
            kernel_sum += noise[i : i + nrow, j : j + ncol]
    smooth = kernel_sum - kernel_sum.mean()
    smooth *= amplitude_m / max(np.abs(smooth).max(), 1e-12)
    blend = np.clip((np.arange(ncol) - flat_cols) / max(ramp_cols, 1), 0.0, 1.0)
    return smooth * blend[None, :]


def heightfield_distance(field, centres: np.ndarray, radius: float) -> Distances:
    """:meth:`HeightField.sphere_distance_reference` compiled (the same triangles within two cells, the same
    signs)."""
    c = np.ascontiguousarray(np.asarray(centres, float).reshape(-1, 3))
    d, normal, point = np.empty(len(c)), np.empty((len(c), 3)), np.empty((len(c), 3))
    x0, y0, dx, dy = field._grid
    _hfield_distance(field.heights_m, x0, y0, dx, dy, c, radius, 2, d, normal, point)
    return d, normal, point


@kernel
def _closest_on_segment(px, py, pz, ax, ay, az, bx, by, bz):
    """(squared distance, closest point) from p to the segment a-b."""
    sx, sy, sz = bx - ax, by - ay, bz - az
    t = ((px - ax) * sx + (py - ay) * sy + (pz - az) * sz) / (sx * sx + sy * sy + sz * sz)
    t = min(max(t, 0.0), 1.0)
    qx, qy, qz = ax + t * sx, ay + t * sy, az + t * sz
    return (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2, qx, qy, qz


@kernel
def _closest_on_triangle(p, a, b, c, out):
    """Closest point ``out`` (3,) on triangle (a, b, c) to ``p``; returns its distance (scalar arithmetic:
    the projection on the plane when inside, else the closest of the three edges)."""
    px, py, pz = p[0], p[1], p[2]
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nx, ny, nz = aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / nn, ny / nn, nz / nn
    off = (px - a[0]) * nx + (py - a[1]) * ny + (pz - a[2]) * nz
    jx, jy, jz = px - off * nx, py - off * ny, pz - off * nz
    vx, vy, vz = jx - a[0], jy - a[1], jz - a[2]
    d00 = abx * abx + aby * aby + abz * abz
    d01 = abx * acx + aby * acy + abz * acz
    d11 = acx * acx + acy * acy + acz * acz
    d20 = vx * abx + vy * aby + vz * abz
    d21 = vx * acx + vy * acy + vz * acz
    den = d00 * d11 - d01 * d01
    bv, bw = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
    if bv >= 0.0 and bw >= 0.0 and bv + bw <= 1.0:
        out[0], out[1], out[2] = jx, jy, jz
        return abs(off)
    best, qx, qy, qz = _closest_on_segment(px, py, pz, a[0], a[1], a[2], b[0], b[1], b[2])
    g, rx, ry, rz = _closest_on_segment(px, py, pz, b[0], b[1], b[2], c[0], c[1], c[2])
    if g < best:
        best, qx, qy, qz = g, rx, ry, rz
    g, rx, ry, rz = _closest_on_segment(px, py, pz, c[0], c[1], c[2], a[0], a[1], a[2])
    if g < best:
        best, qx, qy, qz = g, rx, ry, rz
    out[0], out[1], out[2] = qx, qy, qz
    return np.sqrt(best)


@kernel
def _hfield_top(h, x0, y0, dx, dy, x, y):
    """(z, dz/dx, dz/dy, inside) of the triangulated surface at (x, y) (MuJoCo's diagonal r,c -> r+1,c+1)."""
    nrow, ncol = h.shape
    u, w = (x - x0) / dx, (y - y0) / dy
    if not (0.0 <= u <= ncol - 1 and 0.0 <= w <= nrow - 1):
        return -np.inf, 0.0, 0.0, False
    c, r = min(int(u), ncol - 2), min(int(w), nrow - 2)
    a, b = u - c, w - r
    h00, h11 = h[r, c], h[r + 1, c + 1]
    if a >= b:
        ga, gb = h[r, c + 1] - h00, h11 - h[r, c + 1]
    else:
        ga, gb = h11 - h[r + 1, c], h[r + 1, c] - h00
    return h00 + ga * a + gb * b, ga / dx, gb / dy, True


@kernel
def _cell_corners(h, x0, y0, dx, dy, r, c, A, B, C, D):
    """The four vertices [m, world] of cell (row r, column c): A (r, c), B (r, c + 1), C (r + 1, c),
    D (r + 1, c + 1)."""
    A[0], A[1], A[2] = x0 + c * dx, y0 + r * dy, h[r, c]
    B[0], B[1], B[2] = x0 + (c + 1) * dx, y0 + r * dy, h[r, c + 1]
    C[0], C[1], C[2] = x0 + c * dx, y0 + (r + 1) * dy, h[r + 1, c]
    D[0], D[1], D[2] = x0 + (c + 1) * dx, y0 + (r + 1) * dy, h[r + 1, c + 1]


@kernel
def _hfield_distance(h, x0, y0, dx, dy, centres, radius, reach, d_out, n_out, p_out):
    """Signed distance [m] of spheres (``centres`` (n, 3) [m, world], ``radius`` [m]) to the triangulated surface of
    heights ``h`` on the grid (x0, y0, dx, dy) [m], from the triangles within ``reach`` cells; its unit normal and
    closest point (:meth:`HeightField.sphere_distance`)."""
    _hfield_distance_within(h, x0, y0, dx, dy, centres, radius, reach, np.inf, d_out, n_out, p_out)


@kernel
def _hfield_distance_within(h, x0, y0, dx, dy, centres, radius, reach, cutoff, d_out, n_out, p_out):
    """:func:`_hfield_distance` exact below ``cutoff`` [m]: a sphere above the surface whose distance is at least
    ``cutoff`` may be reported at any distance >= ``cutoff`` (+inf, normal up, point = centre, when even the highest
    vertex of the cells within reach is that far below it) -- for a caller that only asks which spheres are within
    ``cutoff`` and how far (a leg barrier's activation distance). ``cutoff`` = +inf: every distance exact."""
    nrow, ncol = h.shape
    q = np.empty(3)
    best_q = np.empty(3)
    A, B, C, D = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for k in range(centres.shape[0]):
        p = centres[k]
        surface, gx, gy, inside = _hfield_top(h, x0, y0, dx, dy, p[0], p[1])
        d_out[k] = np.inf
        n_out[k, 0], n_out[k, 1], n_out[k, 2] = 0.0, 0.0, 1.0
        p_out[k, 0], p_out[k, 1], p_out[k, 2] = p[0], p[1], p[2]
        if not inside:
            continue
        c0 = min(max(int(np.floor((p[0] - x0) / dx)), 0), ncol - 2)
        r0 = min(max(int(np.floor((p[1] - y0) / dy)), 0), nrow - 2)
        r_lo, r_hi = max(r0 - reach, 0), min(r0 + reach, nrow - 2)
        c_lo, c_hi = max(c0 - reach, 0), min(c0 + reach, ncol - 2)
        if cutoff < np.inf and p[2] - _highest(h, r_lo, r_hi + 1, c_lo, c_hi + 1) - radius >= cutoff + 1e-9:
            continue  # every candidate triangle lies at least cutoff below the sphere
        # the cell under the point bounds the minimum: a cell whose box (its x-y rectangle, its heights' range)
        # is farther than that holds no closer point and is skipped (the same result: the numpy reference,
        # tests/test_terrain_filter.py::test_packed_heightfield_distance_equals_the_part); above the surface a
        # cell farther than cutoff + radius is skipped too (what it holds is at least cutoff away)
        _cell_corners(h, x0, y0, dx, dy, r0, c0, A, B, C, D)
        bound = min(_closest_on_triangle(p, A, B, D, q), _closest_on_triangle(p, A, C, D, q)) + 1e-9
        if p[2] >= surface:
            bound = min(bound, cutoff + radius + 1e-9)
        best = np.inf
        for r in range(r_lo, r_hi + 1):
            for c in range(c_lo, c_hi + 1):
                lo = min(h[r, c], h[r, c + 1], h[r + 1, c], h[r + 1, c + 1])
                hi = max(h[r, c], h[r, c + 1], h[r + 1, c], h[r + 1, c + 1])
                ex = max(x0 + c * dx - p[0], 0.0, p[0] - (x0 + (c + 1) * dx))
                ey = max(y0 + r * dy - p[1], 0.0, p[1] - (y0 + (r + 1) * dy))
                ez = max(lo - p[2], 0.0, p[2] - hi)
                if ex * ex + ey * ey + ez * ez > bound * bound:
                    continue
                _cell_corners(h, x0, y0, dx, dy, r, c, A, B, C, D)
                g = _closest_on_triangle(p, A, B, D, q)
                if g < best:
                    best = g
                    best_q[:] = q
                g = _closest_on_triangle(p, A, C, D, q)
                if g < best:
                    best = g
                    best_q[:] = q
        if best == np.inf:  # above the surface, nothing within cutoff (only with a finite cutoff)
            continue
        sign = -1.0 if p[2] < surface else 1.0
        d_out[k] = sign * best - radius
        if best > 1e-12:
            for a in range(3):
                n_out[k, a] = sign * (p[a] - best_q[a]) / best
        else:
            nz = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
            n_out[k, 0], n_out[k, 1], n_out[k, 2] = -gx * nz, -gy * nz, nz
        p_out[k, 0], p_out[k, 1], p_out[k, 2] = best_q[0], best_q[1], best_q[2]


@kernel
def _highest(h, r0, r1, c0, c1):
    """The largest vertex height [m] of rows r0..r1 and columns c0..c1 (both inclusive)."""
    top = -np.inf
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            top = max(top, h[r, c])
    return top
