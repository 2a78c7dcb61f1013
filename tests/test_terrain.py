"""The terrain object against MuJoCo's own geometry: its distances are what mj_geomDistance measures on the
compiled plant, its heights and frictions what the plant's contacts get; a new kind of terrain part is one
class outside the core."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from taslel_bench.interfaces import Box, FrictionStrips, Log, Plane, Terrain
from taslel_bench.plant.build import compile_plant, robot_spec

PROBE_RADIUS_M = 0.02


def _plant_with_probe(terrain: Terrain) -> tuple[mujoco.MjModel, mujoco.MjData, int]:
    """The A1 plant with ``terrain`` and a free-floating probe sphere (mocap, collides with nothing; contype 2
    so the URDF import does not discard it as a visual)."""
    spec = robot_spec()
    terrain.build(spec, np.random.default_rng(0))
    probe = spec.worldbody.add_body(name="probe", mocap=True)
    probe.add_geom(name="probe", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[PROBE_RADIUS_M, 0, 0], contype=2,
                   conaffinity=0)
    m = compile_plant(spec)
    return m, mujoco.MjData(m), m.body("probe").mocapid[0]


def _mujoco_distance(m, d, mocap, centre, geom_names, distmax: float = 10.0) -> float:
    d.mocap_pos[mocap] = centre
    mujoco.mj_forward(m, d)
    probe = m.geom("probe").id
    fromto = np.zeros(6)
    return min(mujoco.mj_geomDistance(m, d, probe, m.geom(g).id, distmax, fromto) for g in geom_names)


@pytest.mark.parametrize("seed", [0, 1])
def test_sphere_distance_is_mujocos_for_logs_and_boxes(seed):
    logs = (Log(x_m=0.8, z_m=-0.04, radius_m=0.1, half_width_m=0.5), Log(x_m=1.5, z_m=0.0, radius_m=0.05))
    step = Box(centre_m=(2.5, 0.0, 0.025), half_size_m=(0.3, 0.6, 0.025))
    terrain = Terrain((Plane(1.0), *logs, step))
    m, d, mocap = _plant_with_probe(terrain)
    names = ["floor", "obstacles_0", "obstacles_1", "terrain_1"]
    rng = np.random.default_rng(seed)
    centres = np.column_stack([rng.uniform(0.3, 3.0, 200), rng.uniform(-0.7, 0.7, 200), rng.uniform(0.0, 0.2, 200)])
    ours, normal, point = terrain.sphere_distance(centres, PROBE_RADIUS_M)
    theirs = np.array([_mujoco_distance(m, d, mocap, c, names) for c in centres])
    assert np.max(np.abs(ours - theirs)) < 1e-9
    # the normal is the gradient of the distance (finite differences) and the point lies at distance 0
    eps = 1e-6
    for k in range(0, 200, 20):
        grad = [(terrain.sphere_distance(centres[k] + eps * e, PROBE_RADIUS_M)[0][0] - ours[k]) / eps
                for e in np.eye(3)]
        assert np.allclose(grad, normal[k], atol=1e-4)
        assert abs(terrain.sphere_distance(point[k], 0.0)[0][0]) < 1e-9


def test_obstacle_distance_counts_only_obstacles():
    terrain = Terrain((Plane(1.0), Log(x_m=1.0, z_m=0.0, radius_m=0.1)))
    d, n, _ = terrain.obstacle_distance(np.array([[1.0, 0.0, 0.25]]), 0.02)
    assert d[0] == pytest.approx(0.25 - 0.1 - 0.02) and np.allclose(n[0], [0, 0, 1])
    assert math.isinf(Terrain((Plane(1.0),)).obstacle_distance(np.zeros((1, 3)), 0.02)[0][0])


def test_height_normal_friction_follow_the_highest_part():
    strips = FrictionStrips((1.0,), (0.8, 0.2))
    log = Log(x_m=2.0, z_m=0.0, radius_m=0.1, friction=0.5)
    terrain = Terrain((strips, log))
    assert terrain.friction_at((0.99, 0.0)) == 0.8 and terrain.friction_at((1.0, 0.0)) == 0.2  # edge: after
    assert terrain.height_at(2.0, 0.0) == pytest.approx(0.1) and terrain.friction_at((2.0, 0.0)) == 0.5
    assert terrain.height_at(2.06, 0.0) == pytest.approx(math.sqrt(0.1**2 - 0.06**2))
    assert np.allclose(terrain.normal_at(2.06, 0.0), [0.6, 0.0, 0.8])
    assert terrain.height_at(2.0, 0.6) == 0.0  # beyond the log's length
    assert np.array_equal(terrain.friction_under(np.array([[[0.0, 0.0], [2.0, 0.0]]])), [[0.8, 0.5]])


def test_the_plant_gets_the_terrains_friction_and_geometry():
    terrain = Terrain((FrictionStrips((1.0,), (0.8, 0.2)), Box((1.5, 0.0, 0.05), (0.1, 0.2, 0.05), friction=0.4)))
    m, d, mocap = _plant_with_probe(terrain)
    for name, mu in (("floor_before", 0.8), ("floor_after", 0.2), ("terrain_1", 0.4)):
        assert m.geom_friction[m.geom(name).id, 0] == mu
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor") < 0  # the strips replace the floor
    assert _mujoco_distance(m, d, mocap, (1.5, 0.0, 0.2), ["terrain_1"]) == pytest.approx(0.2 - 0.1 - 0.02)


def test_capsule_distance_of_a_leg_link_over_the_floor_and_a_log():
    terrain = Terrain((Plane(1.0), Log(x_m=1.0, z_m=0.0, radius_m=0.1)))
    d, _, _, axis_point = terrain.capsule_distance([0.5, 0.0, 0.3], [0.5, 0.0, 0.1], 0.015)
    assert d == pytest.approx(0.1 - 0.015) and np.allclose(axis_point, [0.5, 0.0, 0.1])
    d, _, point, _ = terrain.capsule_distance([1.0, 0.0, 0.3], [1.0, 0.0, 0.15], 0.015)
    assert d == pytest.approx(0.15 - 0.1 - 0.015) and np.allclose(point, [1.0, 0.0, 0.1])


def _mujoco_height(m, d, x, y, geom_names) -> float:
    """World z where a downward ray from 1 m up first hits one of ``geom_names`` (MuJoCo's mj_ray)."""
    mujoco.mj_forward(m, d)
    best = -math.inf
    for g in geom_names:
        geom = m.geom(g).id
        dist = mujoco.mj_rayGeom(m, d, geom, np.array([x, y, 1.0]), np.array([0.0, 0.0, -1.0])) if hasattr(
            mujoco, "mj_rayGeom") else None
        if dist is None:
            gid = np.zeros(1, np.int32)
            group = np.zeros(6, np.uint8)
            group[m.geom_group[geom]] = 1
            dist = mujoco.mj_ray(m, d, np.array([x, y, 1.0]), np.array([0.0, 0.0, -1.0]), group, 1, -1, gid)
            if gid[0] != geom:
                continue
        if dist >= 0.0:
            best = max(best, 1.0 - dist)
    return best


def _relief_terrain(seed: int) -> Terrain:
    from taslel_bench.interfaces import HeightField, Ramp, rough_heights

    heights = rough_heights(np.random.default_rng(seed), 21, 31, 0.03, 1, 3, 4)
    field = HeightField(heights, centre_x_m=3.75, centre_y_m=0.0, half_x_m=0.75, half_y_m=0.5)
    ramp = Ramp(start_x_m=0.5, run_m=1.5, angle_deg=10.0, half_width_m=0.6)
    plateau = Box(centre_m=(2.25, 0.0, ramp.rise_m / 2), half_size_m=(0.25, 0.6, ramp.rise_m / 2))  # covers its end
    return Terrain((Plane(1.0), ramp, field, plateau))


@pytest.mark.parametrize("seed", [0, 1])
def test_ramp_and_heightfield_distances_heights_normals_are_mujocos(seed):
    terrain = _relief_terrain(seed)
    m, d, mocap = _plant_with_probe(terrain)
    rng = np.random.default_rng(10 + seed)
    # above the ramp (and beside it), and above the heightfield: distance against mj_geomDistance
    for name, x_lo, x_hi, part in (("terrain_1", 0.3, 2.2, 1), ("terrain_2", 3.1, 4.4, 2)):
        centres = np.column_stack([rng.uniform(x_lo, x_hi, 60), rng.uniform(-0.4, 0.4, 60), rng.uniform(0.03, 0.4, 60)])
        ours, normal, point = terrain.parts[part].sphere_distance(centres, PROBE_RADIUS_M)
        # MuJoCo's heightfield distance holds only within a small distmax (with 10 m it reports prisms' far
        # sides): compare where the surface is within 0.1 m
        theirs = np.array([_mujoco_distance(m, d, mocap, c, [name], 0.1) for c in centres])
        close = theirs < 0.1
        assert close.sum() > 10
        assert np.max(np.abs(ours[close] - theirs[close])) < 2e-4, name
        for k in np.flatnonzero(close)[:10]:  # normal = gradient of the distance; the point lies on the surface
            grad = [(terrain.parts[part].sphere_distance(centres[k] + 1e-6 * e, PROBE_RADIUS_M)[0][0] - ours[k]) / 1e-6
                    for e in np.eye(3)]
            assert np.allclose(grad, normal[k], atol=1e-3)
            assert abs(terrain.parts[part].sphere_distance(point[k], 0.0)[0][0]) < 1e-9
    # heights (mj_ray straight down) and normals (finite differences of the height) of the surface
    for x, y in np.column_stack([rng.uniform(0.6, 4.4, 80), rng.uniform(-0.45, 0.45, 80)]):
        names = ["floor", "terrain_1", "terrain_2", "terrain_3"]
        assert terrain.height_at(x, y) == pytest.approx(_mujoco_height(m, d, x, y, names), abs=1e-7)  # float32 hfield
        n = terrain.normal_at(x, y)
        e = 1e-7
        gx = (terrain.surface_part(x, y).top_z(x + e, y) - terrain.surface_part(x, y).top_z(x - e, y)) / (2 * e)
        gy = (terrain.surface_part(x, y).top_z(x, y + e) - terrain.surface_part(x, y).top_z(x, y - e)) / (2 * e)
        assert np.allclose(n, np.array([-gx, -gy, 1.0]) / math.sqrt(1 + gx * gx + gy * gy), atol=1e-6)


def test_terrain_scenarios_are_real_geometry():
    from scenarios.rough import RoughGround
    from scenarios.slope import Slope
    from scenarios.steps import Steps
    from taslel_bench.sim.build import build_plant

    steps = Steps(height_m=0.05)
    assert [steps.terrain.height_at(x, 0.0) for x in (0.5, 1.0, 1.5, 2.1, 3.0)] == pytest.approx(
        [0, 0.05, 0.1, 0.05, 0]
    )
    slope = Slope(angle_deg=10.0, start_x_m=0.6, run_m=2.0)
    assert slope.terrain.height_at(1.6, 0.0) == pytest.approx(math.tan(math.radians(10.0)))
    assert np.allclose(slope.terrain.normal_at(1.6, 0.0), [-math.sin(math.radians(10)), 0, math.cos(math.radians(10))])
    rough0, rough1 = RoughGround(seed=0), RoughGround(seed=1)  # fixed reliefs (default: drawn at build)
    h0 = np.array([rough0.terrain.height_at(x, 0.2) for x in np.linspace(1.0, 5.0, 200)])
    h1 = np.array([rough1.terrain.height_at(x, 0.2) for x in np.linspace(1.0, 5.0, 200)])
    assert 0.01 < np.max(np.abs(h0)) <= 0.03 + 1e-12 and not np.allclose(h0, h1)  # seeded, +-3 cm
    assert rough0.terrain.height_at(0.0, 0.0) == 0.0  # flat where the robot stands
    for sc in (steps, slope, rough0):
        build_plant(sc)  # compiles with the terrain's geoms


def test_rough_relief_is_drawn_from_the_run_seed_when_built():
    from scenarios.rough import RoughGround
    from taslel_bench.sim.build import build_plant

    a, b, a_again = RoughGround(), RoughGround(), RoughGround()
    for sc, seed in ((a, 0), (b, 1), (a_again, 0)):
        with pytest.raises(RuntimeError):
            sc.terrain.height_at(2.0, 0.0)  # no relief before the plant is built
        m = build_plant(sc, seed=seed)
    xs = np.linspace(1.0, 5.0, 50)
    ha, hb, hc = ([s.terrain.height_at(x, 0.1) for x in xs] for s in (a, b, a_again))
    assert ha == hc and ha != hb
    assert m.nhfield == 1
