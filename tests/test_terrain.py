"""The terrain object against MuJoCo's own geometry: its distances are what mj_geomDistance measures on the
compiled plant, its heights and frictions what the plant's contacts get; a new kind of terrain part is one
class outside the core."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from taslel_bench.interfaces import Box, FrictionStrips, Log, Plane, Terrain
from taslel_bench.plant.build import a1_spec, compile_plant

PROBE_RADIUS_M = 0.02


def _plant_with_probe(terrain: Terrain) -> tuple[mujoco.MjModel, mujoco.MjData, int]:
    """The A1 plant with ``terrain`` and a free-floating probe sphere (mocap, collides with nothing; contype 2
    so the URDF import does not discard it as a visual)."""
    spec = a1_spec()
    terrain.build(spec, np.random.default_rng(0))
    probe = spec.worldbody.add_body(name="probe", mocap=True)
    probe.add_geom(name="probe", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[PROBE_RADIUS_M, 0, 0], contype=2,
                   conaffinity=0)
    m = compile_plant(spec)
    return m, mujoco.MjData(m), m.body("probe").mocapid[0]


def _mujoco_distance(m, d, mocap, centre, geom_names) -> float:
    d.mocap_pos[mocap] = centre
    mujoco.mj_forward(m, d)
    probe = m.geom("probe").id
    fromto = np.zeros(6)
    return min(mujoco.mj_geomDistance(m, d, probe, m.geom(g).id, 10.0, fromto) for g in geom_names)


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
