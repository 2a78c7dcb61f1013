"""The compiled terrain writes of ``filter=terrain`` (the terrain filter's cost work) against the code they replace:
the same bits on walking states over terrains of every compiled kind (planes, logs, boxes, a ramp, a heightfield whose
edge lies under the feet), with no foot in contact, every foot in contact and the gait's mix."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from taslel_bench.filter.barriers.leg_clearance import LegClearance
from taslel_bench.filter.barriers.leg_points import LegPoints
from taslel_bench.filter.barriers.terrain_clearance import TerrainClearance
from taslel_bench.filter.layout import TickInputs
from taslel_bench.filter.safety_filter import FilterSettings, SafetyFilter
from taslel_bench.interfaces import OBSTACLE, Box, HeightField, Log, Plane, Ramp, Terrain, rough_heights
from taslel_bench.terrain.packed import PackedTerrain, _norm3, _packed_distance, _take_closer, surface_normal
from taslel_bench.terrain.relief import heightfield_distance
from tests.test_filter import TightReference, inputs_for, walking_states, world


@pytest.fixture(scope="module")
def states():
    return walking_states(10)


def field_at(x_edge: float, role: str = OBSTACLE) -> HeightField:
    """A rough field (+-3 cm, 5 cm cells) whose lower-x edge is at ``x_edge`` [m]."""
    heights = rough_heights(np.random.default_rng(2), 41, 41, 0.03, 1, 0, 1)
    return HeightField(heights, centre_x_m=x_edge + 1.0, centre_y_m=0.0, half_x_m=1.0, half_y_m=1.0, role=role)


def terrains(foot_x: float) -> list[Terrain]:
    """Terrains around a walking state whose front feet are near ``foot_x`` [m]: a field with its edge 3 mm
    behind a front foot, logs and boxes under the legs, a ramp with a plateau."""
    return [
        Terrain((Plane(1.0), field_at(foot_x - 0.003))),
        Terrain((Plane(1.0), Log(foot_x + 0.02, -0.02, 0.06), Box((foot_x - 0.4, 0.0, 0.02), (0.1, 0.5, 0.02),
                                                                   role=OBSTACLE))),
        Terrain((Plane(1.0), Ramp(start_x_m=foot_x - 0.5, run_m=0.4, angle_deg=8.0, role=OBSTACLE),
                 Box((foot_x + 0.2, 0.0, 0.028), (0.3, 1.0, 0.028), role=OBSTACLE))),
        Terrain((Plane(1.0), field_at(foot_x - 0.6, role="ground"), Log(foot_x, 0.0, 0.04))),
    ]


def old_sphere_distance(packed: PackedTerrain, field: HeightField | None, c: np.ndarray, radius: float, tol: float):
    """The query before the heightfield moved into the kernel: the packed kernel, then the field's own query merged
    in Python order."""
    d, normal, point = np.empty(len(c)), np.empty((len(c), 3)), np.empty((len(c), 3))
    _packed_distance(packed.rows, c, radius, tol, d, normal, point)
    if field is not None:
        _take_closer(d, normal, point, *heightfield_distance(field, c, radius), tol)
    return d, normal, point


def test_packed_query_with_the_heightfield_gives_the_old_bits():
    field = field_at(0.5)
    rng = np.random.default_rng(4)
    c = np.column_stack([rng.uniform(0.3, 2.7, 600), rng.uniform(-1.2, 1.2, 600), rng.uniform(-0.05, 0.3, 600)])
    c[:40, 0] = 0.5 + rng.uniform(-1e-3, 1e-3, 40)  # over the field's edge
    for parts in (
        (Plane(1.0), field),
        (field,),
        (Plane(1.0), Log(1.0, 0.0, 0.05), field, Box((2.0, 0, 0.02), (0.2, 0.5, 0.02))),
    ):
        packed = PackedTerrain(parts)
        assert packed.compiled and packed.has_field
        for tol in (0.0, 0.005):
            for a, b in zip(
                old_sphere_distance(packed, field, c, 0.02, tol), packed.sphere_distance(c, 0.02, tol), strict=True
            ):
                assert np.array_equal(a, b)


def test_compiled_height_and_normal_are_the_parts_bit_for_bit():
    terrain = Terrain((Plane(1.0), Log(1.0, -0.02, 0.06), Box((1.6, 0.0, 0.03), (0.2, 0.5, 0.03)),
                       Ramp(start_x_m=2.0, run_m=0.5, angle_deg=12.0), field_at(2.6)))  # fmt: skip
    packed = terrain.packed()
    assert packed.compiled
    rng = np.random.default_rng(5)
    xy = np.column_stack([rng.uniform(0.5, 5.0, 3000), rng.uniform(-1.2, 1.2, 3000)])
    xy[:50, 0] = 2.6 + rng.uniform(-1e-3, 1e-3, 50)  # the field's edge
    xy[50:60, 0] = 1.0 - 0.06  # a log's edge
    out = np.empty(3)
    for x, y in xy:
        x, y = float(x), float(y)
        surface_normal(packed.surface_rows, packed.field_heights, packed.field_grid, x, y, out)
        assert np.array_equal(out, terrain.surface_part(x, y).normal(x, y))  # the Python normal_at
        assert np.array_equal(terrain.normal_at(x, y), out)
        assert terrain.height_at(x, y) == max(part.top_z(x, y) for part in terrain.parts)  # the Python height_at
    for (x0, y0), (x1, y1) in xy.reshape(-1, 2, 2)[:300]:  # the path maximum of the terrain-following nominal
        python = max(terrain.height_at(x0 + (x1 - x0) * k / 8, y0 + (y1 - y0) * k / 8) for k in range(9))
        assert terrain.highest_along((x0, y0), (x1, y1), 8) == python
    for v in rng.normal(size=(500, 3)) * rng.choice([1e-4, 1.0, 30.0], size=(500, 1)):
        assert _norm3(v) == np.linalg.norm(v)


class Pillar:
    """A part kind the packer does not know (the members the filter's queries use)."""

    role = OBSTACLE
    box = Box((0.3, 0.0, 0.1), (0.05, 0.05, 0.1))

    def sphere_distance(self, centres, radius):
        return self.box.sphere_distance(centres, radius)

    def top_z(self, x, y):
        return self.box.top_z(x, y)

    def normal(self, x, y):
        return self.box.normal(x, y)


def test_a_part_of_another_kind_keeps_the_python_query(states):
    assert not PackedTerrain((Plane(1.0), Pillar())).compiled
    pillar = Terrain((Plane(1.0), Pillar()))
    assert pillar.height_at(0.3, 0.0) == 0.2 and pillar.height_at(1.0, 0.0) == 0.0
    two = PackedTerrain((Plane(1.0), field_at(0.0), field_at(3.0)))  # two fields: both in Python
    assert not two.compiled and two.surface_rows is None and len(two.others) == 2
    undrawn = Terrain((Plane(1.0), HeightField(None, 1.0, 0.0, 0.5, 0.5, draw=lambda rng: np.zeros((3, 3)))))
    assert undrawn.packed().pending and not undrawn._packs  # not kept before the heights are drawn
    st, pm = states
    old, new = families(Terrain((Plane(1.0), Pillar())), True), families(Terrain((Plane(1.0), Pillar())), True)
    for state in st[:3]:
        x = inputs_for(pm, state, 0.8)
        for f_old, f_new in zip(old.ineq_families, new.ineq_families, strict=True):
            f_old.write_python(old.problem, x)
            f_new.write(new.problem, x)
        assert np.array_equal(old.problem.G, new.problem.G) and np.array_equal(old.problem.h, new.problem.h)


def families(terrain: Terrain, downhill: bool, along_nominal: bool = False) -> SafetyFilter:
    w = world(terrain=terrain)
    barriers = [TerrainClearance(w), TerrainClearance(w, "tc_all", role=None), LegClearance(w, "shin"),
                LegClearance(w, "shin_all", role=None, swing_only=True),
                LegClearance(w, "knee", part="knee", radius_m=0.02)]  # fmt: skip
    return SafetyFilter(FilterSettings(friction_cone="terrain", cone_edge_downhill=downhill,
                                       cone_edge_along_nominal=along_nominal), TightReference(), barriers,
                        terrain=terrain)  # fmt: skip


def stance_variants(x: TickInputs) -> list[TickInputs]:
    """The gait's stance set, no foot in contact, every foot in contact (each foot's own mu in the last)."""
    mu = np.array([0.3, 0.5, 0.7, 0.9])
    return [x, replace(x, in_stance=np.zeros(4, bool)), replace(x, in_stance=np.ones(4, bool), mu_per_foot=mu)]


@pytest.mark.parametrize(("downhill", "along_nominal"), [(False, False), (True, False), (True, True)])
def test_compiled_family_writes_give_the_python_writes_bits(states, downhill, along_nominal):
    st, pm = states
    pm.update(*st[0][:2])
    foot_x = float(pm.foot_pos_in_world[0, 0])
    rng = np.random.default_rng(3)
    for terrain in terrains(foot_x):
        old, new = families(terrain, downhill, along_nominal), families(terrain, downhill, along_nominal)
        active = 0
        for state in st:
            for x in stance_variants(inputs_for(pm, state, 0.8)):
                # nominal forces with a tangential part above and (last foot) below the turning threshold
                force = rng.normal(0.0, 15.0, (4, 3)) + np.array([0.0, 0.0, 40.0])
                force[3, :2] = 0.1
                old.friction.nominal_force[:] = force
                new.friction.nominal_force[:] = force
                for f_old, f_new in zip(old.ineq_families, new.ineq_families, strict=True):
                    f_old.write_python(old.problem, x)
                    f_new.write(new.problem, x)
                assert np.array_equal(old.problem.G, new.problem.G) and np.array_equal(old.problem.h, new.problem.h)
                for b_old, b_new in zip(old.barriers, new.barriers, strict=True):
                    assert np.array_equal(b_old.h, b_new.h, equal_nan=True)
                    assert np.array_equal(b_old.h_e, b_new.h_e, equal_nan=True)
                    active += int(np.isfinite(b_new.h).sum())
                for name in ("normals", "mu_used", "_stance", "_mu", "_written"):
                    assert np.array_equal(getattr(old.friction, name), getattr(new.friction, name), equal_nan=True)
        assert active > 0


def test_knee_views_follow_the_model(states):
    st, pm = states
    points = LegPoints(pm)
    for state in st[:4]:
        pm.update(*state[:2])
        assert np.array_equal(np.array(points.knee_views), points.knees())
    assert points.data is pm.data


def test_with_mu_scaled_is_dataclass_replace(states):
    st, pm = states
    feet = np.array([0.8, 0.6, 0.4, 0.2])
    x = replace(inputs_for(pm, st[0], 0.8), mu_per_foot=feet)
    a, b = x.with_mu_scaled(0.9), replace(x, mu=0.8 * 0.9, mu_per_foot=feet * 0.9)
    for name in TickInputs.__dataclass_fields__:
        va, vb = getattr(a, name), getattr(b, name)
        assert va is vb or np.array_equal(va, vb)
    assert (
        x.with_mu_scaled(0.9).mu_per_foot is not feet
        and replace(x, mu_per_foot=None).with_mu_scaled(0.9).mu_per_foot is None
    )


def test_heightfield_distance_within_a_cutoff_is_exact_below_it():
    """Below the cutoff the same bits as the exact query; at or beyond it any value >= the cutoff."""
    from taslel_bench.terrain.packed import FIELD_REACH_CELLS
    from taslel_bench.terrain.relief import _hfield_distance_within

    field = field_at(0.5)
    x0, y0, dx, dy = field._grid
    rng = np.random.default_rng(7)
    c = np.column_stack([rng.uniform(0.4, 2.6, 2000), rng.uniform(-1.1, 1.1, 2000), rng.uniform(-0.06, 0.3, 2000)])
    exact = heightfield_distance(field, c, 0.02)
    for cutoff in (0.0, 0.03, 0.08):
        d, n, p = np.empty(len(c)), np.empty((len(c), 3)), np.empty((len(c), 3))
        _hfield_distance_within(field.heights_m, x0, y0, dx, dy, c, 0.02, FIELD_REACH_CELLS, cutoff, d, n, p)
        near = exact[0] < cutoff
        assert near.sum() > 100 and (~near).sum() > 100
        assert np.array_equal(d[near], exact[0][near]) and np.array_equal(n[near], exact[1][near])
        assert np.array_equal(p[near], exact[2][near])
        assert np.all(d[~near] >= cutoff)
