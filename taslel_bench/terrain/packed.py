"""The terrain's distance query compiled for the control tick: the parts of simple shapes (floor planes, logs,
boxes, ramps) packed into one array and measured by one Numba kernel together with one heightfield (its heights
and grid handed to the same kernel); other parts by their own ``sphere_distance``. Same numbers as
:meth:`Terrain.sphere_distance` (tested), ~1 µs per point instead of ~50 µs per part and call.

A terrain whose parts are all known here (:attr:`PackedTerrain.compiled`) is also measured from inside other
kernels (:func:`terrain_distance`, :func:`surface_normal`: the barrier families and the terrain cone write their
rows in one compiled call per tick); one with a part of another kind is measured in Python, as before.
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.terrain.parts import Box, FrictionStrips, Log, Plane
from taslel_bench.terrain.relief import HeightField, Ramp, _hfield_distance_within, _hfield_top
from taslel_bench.util.jit import kernel

PLANE, LOG, ORIENTED_BOX = 0.0, 1.0, 2.0
ROW = 17  # kind + up to 16 parameters
FIELD_REACH_CELLS = 2  # a heightfield's distance: the triangles within this many cells (HeightField.sphere_distance)
# kinds of the surface rows (top z and upward normal over (x, y), Terrain.surface_part's order)
S_FLAT, S_LOG, S_BOX, S_RAMP, S_FIELD = 0.0, 1.0, 2.0, 3.0, 4.0


def pack(part) -> np.ndarray | None:
    """One row describing ``part`` for the kernel, or None for a part the kernel does not know."""
    row = np.zeros(ROW)
    if isinstance(part, (Plane, FrictionStrips)):
        row[0], row[1] = PLANE, float(part.top_z(0.0, 0.0))
    elif isinstance(part, Log):
        row[0] = LOG
        row[1:6] = (part.x_m, part.y_m, part.z_m, part.radius_m, part.half_width_m)
    elif isinstance(part, Box):
        row[0] = ORIENTED_BOX
        row[1:4], row[4:7], row[7:16] = part.centre_m, part.half_size_m, np.eye(3).ravel()
    elif isinstance(part, Ramp):
        rot, centre, half = part._frame()
        row[0] = ORIENTED_BOX
        row[1:4], row[4:7], row[7:16] = centre, half, rot.ravel()
    else:
        return None
    return row


def surface_row(part) -> np.ndarray | None:
    """One row for :func:`surface_normal` (the part's ``top_z`` and ``normal``), None for a kind it does not know."""
    row = np.zeros(ROW)
    if isinstance(part, (Plane, FrictionStrips)):
        row[0], row[1] = S_FLAT, float(part.top_z(0.0, 0.0))
    elif isinstance(part, Log):
        row[0] = S_LOG
        row[1:6] = (part.x_m, part.y_m, part.z_m, part.radius_m, part.half_width_m)
    elif isinstance(part, Box):
        row[0] = S_BOX
        row[1:4], row[4:7] = part.centre_m, part.half_size_m
    elif isinstance(part, Ramp):  # top z = tan(angle) (x - start) and the normal, as Ramp.top_z / normal compute them
        a = math.radians(part.angle_deg)
        row[0] = S_RAMP
        row[1:6] = (part.start_x_m, part.start_x_m + part.run_m, part.y_m, part.half_width_m, math.tan(a))
        row[6:9] = (-math.sin(a), 0.0, math.cos(a))
    elif isinstance(part, HeightField):
        row[0] = S_FIELD
    else:
        return None
    return row


class PackedTerrain:
    """The packed parts of one terrain (rows), its one heightfield measured in the same kernel (``field_heights``,
    ``field_grid`` = (x0, y0, dx, dy) [m]; a 2 x 2 placeholder and ``has_field`` False without one) and the others
    (queried in Python). ``compiled``: no part is left to Python (the kernels of the tick can measure it);
    ``surface_rows``: the parts in their order for :func:`surface_normal` (None unless compiled)."""

    def __init__(self, parts) -> None:
        rows, self.others = [], []
        fields = [p for p in parts if isinstance(p, HeightField) and p._grid is not None]
        field = fields[0] if len(fields) == 1 else None  # several fields (none in the scenarios): all in Python
        for part in parts:
            row = pack(part)
            if row is not None:
                rows.append(row)
            elif part is not field:
                self.others.append(part)
        self.rows = np.array(rows) if rows else np.zeros((0, ROW))
        self.has_field = field is not None
        self.field_heights = np.ascontiguousarray(field.heights_m, float) if field is not None else np.zeros((2, 2))
        self.field_grid = np.array(field._grid if field is not None else (0.0, 0.0, 1.0, 1.0), float)
        self.compiled = not self.others
        self.pending = any(isinstance(p, HeightField) and p._grid is None for p in parts)  # heights not drawn yet
        surface = [surface_row(p) for p in parts]
        self.surface_rows = np.array(surface) if self.compiled and surface else None

    def sphere_distance(self, centres: np.ndarray, radius: float,
                        upward_tol_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
        """The smallest distance over the parts; with ``upward_tol_m`` > 0, among parts within that much of
        the smallest, the one whose normal points most upward (a foot in the corner of the floor and a log's
        or step's side stands on the floor: its contact normal is the floor's)."""
        c = np.ascontiguousarray(np.asarray(centres, float).reshape(-1, 3))
        d, normal, point = np.empty(len(c)), np.empty((len(c), 3)), np.empty((len(c), 3))
        terrain_distance(self.rows, self.field_heights, self.field_grid, self.has_field, c, radius, upward_tol_m, d,
                         normal, point)  # fmt: skip
        for part in self.others:
            dp, n_p, p_p = part.sphere_distance(c, radius)
            _take_closer(d, normal, point, dp, n_p, p_p, upward_tol_m)
        return d, normal, point


@kernel
def terrain_distance(rows, field_heights, field_grid, has_field, centres, radius, upward_tol, d, normal, point):
    """:meth:`PackedTerrain.sphere_distance` of its compiled parts into ``d`` (n,) [m], ``normal`` (n, 3) and
    ``point`` (n, 3) [m, world]: the packed rows, then the heightfield (if ``has_field``) merged as a part after
    them (:func:`_take_closer`, the order of the Python query)."""
    terrain_distance_within(rows, field_heights, field_grid, has_field, centres, radius, upward_tol, np.inf, d, normal,
                            point)  # fmt: skip


@kernel
def terrain_distance_within(rows, field_heights, field_grid, has_field, centres, radius, upward_tol, cutoff, d, normal,
                            point):  # fmt: skip
    """:func:`terrain_distance` exact below ``cutoff`` [m]: a sphere whose heightfield distance is at least
    ``cutoff`` may get any value >= ``cutoff`` for it (:func:`_hfield_distance_within`; with ``upward_tol`` 0 its
    merged distance is then exact where below ``cutoff``, and >= ``cutoff`` elsewhere). +inf: every distance exact."""
    _packed_distance(rows, centres, radius, upward_tol, d, normal, point)
    if has_field:
        n = centres.shape[0]
        d_f, n_f, p_f = np.empty(n), np.empty((n, 3)), np.empty((n, 3))
        _hfield_distance_within(field_heights, field_grid[0], field_grid[1], field_grid[2], field_grid[3], centres,
                                radius, FIELD_REACH_CELLS, cutoff, d_f, n_f, p_f)  # fmt: skip
        _take_closer(d, normal, point, d_f, n_f, p_f, upward_tol)


@kernel
def _surface_top(row, field_heights, field_grid, x, y):
    """World z [m] of one surface row's top over (x, y) (-inf where it has none): the part's ``top_z``."""
    kind = row[0]
    if kind == S_FLAT:
        return row[1]
    if kind == S_LOG:
        if abs(y - row[2]) > row[5]:
            return -np.inf
        over = (x - row[1]) ** 2 - row[4] ** 2
        return row[3] + np.sqrt(-over) if over <= 0.0 else -np.inf
    if kind == S_BOX:
        return row[3] + row[6] if abs(x - row[1]) <= row[4] and abs(y - row[2]) <= row[5] else -np.inf
    if kind == S_RAMP:
        inside = row[1] <= x <= row[2] and abs(y - row[3]) <= row[4]
        return row[5] * (x - row[1]) if inside else -np.inf
    return _hfield_top(field_heights, field_grid[0], field_grid[1], field_grid[2], field_grid[3], x, y)[0]


@kernel
def surface_height(surface_rows, field_heights, field_grid, x, y):
    """:meth:`Terrain.height_at` (x, y): the highest part's top z [m, world] over (x, y) (-inf over none)."""
    top = -np.inf
    for r in range(surface_rows.shape[0]):
        top = max(top, _surface_top(surface_rows[r], field_heights, field_grid, x, y))
    return top


@kernel
def highest_along(surface_rows, field_heights, field_grid, x0, y0, x1, y1, samples):
    """The largest :func:`surface_height` [m] at the ``samples`` + 1 points x0 + (x1 - x0) k / samples (and the
    same in y), k = 0 .. samples, from (x0, y0) to (x1, y1) [m, world]."""
    top = -np.inf
    for k in range(samples + 1):
        x = x0 + (x1 - x0) * k / samples
        y = y0 + (y1 - y0) * k / samples
        top = max(top, surface_height(surface_rows, field_heights, field_grid, x, y))
    return top


@kernel
def _norm3(v):
    """|v| of a 3-vector as ``np.linalg.norm`` computes it (sqrt of BLAS's dot: the same bits)."""
    return np.sqrt(np.dot(v, v))


@kernel
def surface_normal(surface_rows, field_heights, field_grid, x, y, out):
    """``out`` (3,) = :meth:`Terrain.normal_at` (x, y): the unit upward normal of the highest part over (x, y),
    the first of equals, each part's own ``normal``."""
    best, best_z = 0, -np.inf
    for r in range(surface_rows.shape[0]):
        z = _surface_top(surface_rows[r], field_heights, field_grid, x, y)
        if z > best_z:
            best, best_z = r, z
    row = surface_rows[best]
    kind = row[0]
    out[0], out[1], out[2] = 0.0, 0.0, 1.0
    if kind == S_LOG:
        if abs(y - row[2]) > row[5] or (x - row[1]) ** 2 - row[4] ** 2 > 0.0:
            return
        dx = x - row[1]
        out[0], out[1], out[2] = dx, 0.0, np.sqrt(max(row[4] ** 2 - dx * dx, 0.0))
        for a in range(3):
            out[a] /= row[4]
    elif kind == S_RAMP:
        out[0], out[1], out[2] = row[6], row[7], row[8]
    elif kind == S_FIELD:
        z, gx, gy, inside = _hfield_top(field_heights, field_grid[0], field_grid[1], field_grid[2], field_grid[3], x, y)
        if inside:
            out[0], out[1], out[2] = -gx, -gy, 1.0
            size = _norm3(out)
            for a in range(3):
                out[a] /= size


@kernel
def _take_closer(d, normal, point, dp, n_p, p_p, upward_tol):
    """Where the other part is closer (with ``upward_tol`` > 0: closer by more than it, or within it and more
    upward), take its distance, normal and point (in place; one loop instead of numpy masks on 4-24 rows)."""
    for k in range(d.shape[0]):
        if upward_tol == 0.0:
            closer = dp[k] < d[k]
        else:
            closer = dp[k] < d[k] - upward_tol or (dp[k] < d[k] + upward_tol and n_p[k, 2] > normal[k, 2])
        if closer:
            d[k] = dp[k]
            for a in range(3):
                normal[k, a] = n_p[k, a]
                point[k, a] = p_p[k, a]


@kernel
def _packed_distance(rows, centres, radius, upward_tol, d_out, n_out, p_out):
    """Per centre, the smallest signed distance over the packed parts (see :func:`pack`), its unit normal and
    closest point (world) -- the members of the parts' own ``sphere_distance``; with ``upward_tol`` > 0 a
    part within that of the best replaces it when its normal points more upward."""
    loc, cl, nl = np.empty(3), np.empty(3), np.empty(3)  # a box's point, closest point and normal (box axes)
    for k in range(centres.shape[0]):
        cx, cy, cz = centres[k, 0], centres[k, 1], centres[k, 2]
        best, bn0, bn1, bn2, bp0, bp1, bp2 = np.inf, 0.0, 0.0, 1.0, cx, cy, cz
        for r in range(rows.shape[0]):
            kind = rows[r, 0]
            if kind == 0.0:
                z = rows[r, 1]
                dist, n0, n1, n2, q0, q1, q2 = cz - z - radius, 0.0, 0.0, 1.0, cx, cy, z
            elif kind == 1.0:
                x0, y0, z0, R, hw = rows[r, 1], rows[r, 2], rows[r, 3], rows[r, 4], rows[r, 5]
                dx, dz = cx - x0, cz - z0
                beyond = abs(cy - y0) - hw
                dy = 0.0
                if beyond > 0.0:
                    dy = beyond if cy - y0 >= 0.0 else -beyond
                rho = np.sqrt(dx * dx + dy * dy + dz * dz)
                s = max(rho, 1e-12)
                n0, n1, n2 = dx / s, dy / s, dz / s
                dist = rho - R - radius
                q0, q1, q2 = x0 + R * n0, cy - dy + R * n1, z0 + R * n2
            else:
                c0, c1, c2 = rows[r, 1], rows[r, 2], rows[r, 3]
                h = (rows[r, 4], rows[r, 5], rows[r, 6])
                # local = R' (c - centre), R row-major in rows[r, 7:16]
                w0, w1, w2 = cx - c0, cy - c1, cz - c2
                for a in range(3):
                    loc[a] = rows[r, 7 + a] * w0 + rows[r, 10 + a] * w1 + rows[r, 13 + a] * w2
                out2 = 0.0
                for a in range(3):
                    cl[a] = min(max(loc[a], -h[a]), h[a])
                    out2 += (loc[a] - cl[a]) ** 2
                out = np.sqrt(out2)
                nl[0], nl[1], nl[2] = 0.0, 0.0, 0.0
                if out > 0.0:
                    for a in range(3):
                        nl[a] = (loc[a] - cl[a]) / out
                    dist = out - radius
                else:  # inside: the nearest face
                    axis, gap = 0, np.inf
                    for a in range(3):
                        g = h[a] - abs(loc[a])
                        if g < gap:
                            axis, gap = a, g
                    sgn = 1.0 if loc[axis] >= 0.0 else -1.0
                    nl[axis] = sgn
                    cl[axis] = h[axis] * sgn
                    dist = -gap - radius
                n0 = rows[r, 7] * nl[0] + rows[r, 8] * nl[1] + rows[r, 9] * nl[2]
                n1 = rows[r, 10] * nl[0] + rows[r, 11] * nl[1] + rows[r, 12] * nl[2]
                n2 = rows[r, 13] * nl[0] + rows[r, 14] * nl[1] + rows[r, 15] * nl[2]
                q0 = c0 + rows[r, 7] * cl[0] + rows[r, 8] * cl[1] + rows[r, 9] * cl[2]
                q1 = c1 + rows[r, 10] * cl[0] + rows[r, 11] * cl[1] + rows[r, 12] * cl[2]
                q2 = c2 + rows[r, 13] * cl[0] + rows[r, 14] * cl[1] + rows[r, 15] * cl[2]
            if dist < best - upward_tol or (dist < best + upward_tol and (upward_tol == 0.0 or n2 > bn2)
                                              and (upward_tol > 0.0 or dist < best)):
                best, bn0, bn1, bn2, bp0, bp1, bp2 = dist, n0, n1, n2, q0, q1, q2
        d_out[k] = best
        n_out[k, 0], n_out[k, 1], n_out[k, 2] = bn0, bn1, bn2
        p_out[k, 0], p_out[k, 1], p_out[k, 2] = bp0, bp1, bp2

