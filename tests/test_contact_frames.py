"""Contact-frame readings checked against independent computations: the foot contact sensors' world-axes
force projected on the reader's normal, and the point Jacobian ``mj_jac`` at the contact position times
``qvel`` for the contact point's velocity."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from taslel_bench.plant.contact_frames import ContactFrameReader, ContactLog
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.build import Built
from tests.conftest import compose_cfg


@pytest.fixture(scope="module")
def logs_run():
    """The nominal trot into the logs for 2.5 s (it reaches the first log at x = 0.6 m), trace kept."""
    cfg = compose_cfg(["scenario=logs", "filter.enabled=false", "duration=2.5", "progress=false",
                       "record.mcap=false", "seed=0"])
    built = Built(cfg)
    res = built.episode.run()
    return built, res.trace


def test_contact_frame_force_agrees_with_the_foot_sensor(logs_run):
    """One contact per foot: f_n = f_sensor . n and |f_t| = |f_sensor - (f_sensor . n) n|, on the floor and on
    the logs (where the normal is not world z)."""
    _, tr = logs_run
    single = (tr.contact_fn_n[: tr.n] > 0).sum(axis=2) == 1
    main = tr.main_contact(slice(0, tr.n))
    f = tr.grf_plant_w[: tr.n]  # [N] on the foot, world axes (foot sensor)
    n = np.take_along_axis(tr.contact_normal_w[: tr.n], main[..., None, None], 2)[:, :, 0]
    fn = np.take_along_axis(tr.contact_fn_n[: tr.n], main[..., None], 2)[..., 0]
    ft = np.take_along_axis(tr.contact_ft_n[: tr.n], main[..., None], 2)[..., 0]
    f_n = np.einsum("nlj,nlj->nl", f, n)
    f_t = np.linalg.norm(f - f_n[..., None] * n, axis=2)
    assert single.sum() > 1000
    np.testing.assert_allclose(fn[single], f_n[single], atol=1e-6)
    np.testing.assert_allclose(ft[single], f_t[single], atol=1e-6)
    on_log = single & (n[..., 2] < 0.99) & (fn > 1.0)
    assert on_log.sum() > 5  # loaded contacts with a normal that is not world z were judged


def test_contact_point_velocity_is_the_point_jacobian_times_qvel():
    """A state with feet on the floor: the reader's tangential speed equals |(I - n n') J_p(contact.pos) qvel|
    from mj_jac on the foot's body, independent of mj_objectVelocity."""
    built = Built(compose_cfg(["scenario=logs", "progress=false", "record.mcap=false"]))
    m, d = built.mj_model, mujoco.MjData(built.mj_model)
    d.qpos[:] = built.episode.initial_qpos
    d.qpos[built.episode.bridge.free_qadr + 2] -= 0.008  # [m] the feet into the floor
    rng = np.random.default_rng(3)
    d.qvel[:] = rng.normal(0.0, 0.3, m.nv)
    mujoco.mj_forward(m, d)
    reader, log = ContactFrameReader(m), ContactLog(1)
    reader.record(d, log, 0)
    frames = reader.frames(log, 0, 1, np.zeros((1, quad.N_LEGS, 3)))
    jacp = np.zeros((3, m.nv))
    checked = 0
    feet = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f): i for i, f in enumerate(quad.FOOT_FRAMES)}
    for i in range(d.ncon):
        c = d.contact[i]
        foot = next((g for g in (c.geom1, c.geom2) if g in feet), None)
        if foot is None:
            continue
        mujoco.mj_jac(m, d, jacp, None, c.pos, m.geom_bodyid[foot])
        v = jacp @ d.qvel
        n = c.frame[:3]
        expected = np.linalg.norm(v - (v @ n) * n)
        leg = feet[foot]
        assert frames["contact_slip_mps"][0, leg, 0] == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert frames["contact_normal_w"][0, leg, 0, 2] == pytest.approx(1.0)  # floor, out of it
        assert frames["contact_fn_n"][0, leg, 0] > 0.0
        checked += 1
    assert checked >= 3


def test_leg_link_contact_beside_its_foot_is_told_from_one_away_from_it():
    """Two ticks of raw rows, each with the FL calf box touching log 0: 2.5 cm from the FL foot centre (the box
    grazing the log the foot stands on) and 11 cm from it (a calf strike). Both are link contacts; only the second
    is off the foot."""
    built = Built(compose_cfg(["scenario=logs", "progress=false", "record.mcap=false"]))
    m = built.mj_model
    calf = next(g for g in range(m.ngeom) if m.body(m.geom_bodyid[g]).name == "FL_calf"
                and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX)
    log_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "obstacles_0")
    reader, log = ContactFrameReader(m), ContactLog(2)
    fl = quad.LEGS.index("FL")
    foot_pos = np.zeros((2, quad.N_LEGS, 3))
    for k, away_m in enumerate((0.025, 0.11)):
        log.count[k] = 1
        log.geom[k, 0] = (log_geom, calf)
        log.dist[k, 0] = -0.002
        foot_pos[k, fl] = (0.66, 0.1, 0.05)
        log.pos[k, 0] = foot_pos[k, fl] + (-away_m, 0.0, 0.0)
    frames = reader.frames(log, 0, 2, foot_pos)
    assert frames["leg_link_obstacle_contact"][:, fl].tolist() == [True, True]
    assert frames["leg_link_obstacle_contact_off_foot"][:, fl].tolist() == [False, True]
    assert not frames["leg_link_obstacle_contact"][:, [i for i in range(quad.N_LEGS) if i != fl]].any()


def test_foot_cone_edge_is_the_contacts_edge_for_one_contact_and_the_net_force_for_two():
    """One contact per foot (the logs run): the foot's mean normal is that contact's normal and its edge flag is
    the contact's. Two contacts tilted +-30 deg about x, each at its cone edge (mu 0.5) with tangential forces
    that cancel sideways: the foot's net force is vertical, inside the cone about their mean normal (world z)."""
    from types import SimpleNamespace

    from taslel_bench.metrics.contacts import CONE_EDGE_FRACTION, _foot_cone_edge

    tilt = np.radians(30.0)
    normals = np.array([[0.0, -np.sin(tilt), np.cos(tilt)], [0.0, np.sin(tilt), np.cos(tilt)]])
    tangents = np.array([[0.0, np.cos(tilt), np.sin(tilt)], [0.0, -np.cos(tilt), np.sin(tilt)]])
    f_n, mu = 40.0, 0.5
    forces = f_n * normals + mu * f_n * tangents  # each at its cone edge, pushing the foot up the other flank
    tr = SimpleNamespace(grf_plant_w=forces.sum(axis=0)[None, None, :].repeat(4, axis=1),
                         foot_contact_normal_w=(f_n * normals).sum(axis=0)[None, None, :].repeat(4, axis=1))
    edge, loaded = _foot_cone_edge(tr, slice(0, 1), np.full((1, 4, 3), mu))
    assert loaded.all() and not edge.any()
    assert np.allclose(tr.grf_plant_w[0, 0, :2], 0.0)  # the tangential parts cancel: the net force is vertical

    single, per_contact, per_foot = _single_contact_edges(CONE_EDGE_FRACTION)
    assert single.sum() > 1000
    assert np.array_equal(per_contact[single], per_foot[single])


def _single_contact_edges(fraction: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The logs run's (single-contact feet, per-contact edge of the main contact, per-foot edge)."""
    from taslel_bench.metrics.contacts import _foot_cone_edge

    cfg = compose_cfg(["scenario=logs", "filter.enabled=false", "duration=1.5", "progress=false",
                       "record.mcap=false", "seed=0"])
    tr = Built(cfg).episode.run().trace
    tr.finalize()
    n = slice(0, tr.n)
    fn, ft, mu = tr.contact_fn_n[n], tr.contact_ft_n[n], tr.contact_mu[n]
    single = ((fn > 0).sum(axis=2) == 1) & (fn.max(axis=2) >= 1.0)
    main = np.argmax(fn, axis=2)[..., None]
    fn1, ft1, mu1 = (np.take_along_axis(a, main, 2)[..., 0] for a in (fn, ft, mu))
    per_contact = ft1 >= fraction * mu1 * fn1
    per_foot, _ = _foot_cone_edge(tr, n, mu)
    return single, per_contact, per_foot
