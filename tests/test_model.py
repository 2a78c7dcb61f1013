"""The controller's model (Pinocchio) against the plant (MuJoCo) and finite differences."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from taslel_bench.plant.bridge import StateBridge, quat_wxyz_to_matrix
from taslel_bench.plant.build import PlantOptions, build_plant, compile_plant, robot_spec
from taslel_bench.plant.contacts import FootContactReader, foot_geom_ids, measure_contact_friction
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.robot.model import RobotModel

A1 = load_robot("a1")
KIN = LegKinematics(A1)


@pytest.fixture(scope="module")
def setup():
    m = build_plant()
    return m, mujoco.MjData(m), StateBridge(m), RobotModel()


def random_state(pm: RobotModel, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    q = pin.randomConfiguration(pm.model, -np.ones(quad.NQ), np.ones(quad.NQ))
    q[7:] = rng.uniform(-0.8, 0.8, 12)
    q[9::3] = rng.uniform(-2.6, -1.0, 4)  # calf range
    return q, rng.normal(0.0, 2.0, quad.NV)


def same_random_state(m, d, br: StateBridge, pm: RobotModel, rng: np.random.Generator):
    """A random state set in both MuJoCo (forward dynamics run) and the model (updated); returns (q, v)."""
    q, v = random_state(pm, rng)
    br.qpos_mj(q, d.qpos)
    br.qvel_mj(q, v, d.qvel)
    mujoco.mj_forward(m, d)
    pm.update(q, v)
    return q, v


def velocity_map(br: StateBridge, q: np.ndarray) -> np.ndarray:
    """T with qvel_mujoco = T v_pinocchio (linear part rotated, joints permuted)."""
    T = np.zeros((quad.NV, quad.NV))
    for i in range(quad.NV):
        e = np.zeros(quad.NV)
        e[i] = 1.0
        br.qvel_mj(q, e, T[:, i])
    return T


def plant_model_errors(m, d, br: StateBridge, pm: RobotModel, q: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """Largest |plant - model| at the state (q, v) set in both (MuJoCo forward run, model updated): the mass matrix,
    the bias forces (the model's h less its known joint losses, which MuJoCo keeps outside qfrc_bias), the foot
    positions and their translational Jacobians (Pinocchio's velocity convention)."""
    T = velocity_map(br, q)
    M_mj = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M_mj)  # MuJoCo 4 signature
    # qacc = T vdot + Tdot v; Tdot v is R (w x v_lin) on the linear rows (linear velocity frame change)
    tdot_v = np.zeros(quad.NV)
    tdot_v[:3] = quat_wxyz_to_matrix(d.qpos[3:7]) @ np.cross(v[3:6], v[:3])
    losses = np.zeros(quad.NV)  # the known joint losses the model adds to h (the URDF's <dynamics>)
    losses[6:] = pm.joint_damping * v[6:] + pm.joint_frictionloss * np.tanh(v[6:] / pm.frictionloss_smoothing_radps)
    out = {"M": np.abs(T.T @ M_mj @ T - pm.M).max(),
           "h": np.abs(T.T @ (d.qfrc_bias + M_mj @ tdot_v) - (pm.h - losses)).max(), "pos": 0.0, "jac": 0.0}
    for i, foot in enumerate(quad.FOOT_FRAMES):
        sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, foot)
        out["pos"] = max(out["pos"], np.abs(d.site_xpos[sid] - pm.foot_pos_in_world[i]).max())
        jac = np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jac, None, sid)
        out["jac"] = max(out["jac"], np.abs(jac @ T - pm.foot_jac_in_world[i]).max())
    return out


def test_mass_bias_feet_match_mujoco(setup):
    m, d, br, pm = setup
    rng = np.random.default_rng(0)
    worst = {"M": 0.0, "h": 0.0, "pos": 0.0, "jac": 0.0}
    for _ in range(20):
        q, v = same_random_state(m, d, br, pm, rng)
        worst = {k: max(worst[k], e) for k, e in plant_model_errors(m, d, br, pm, q, v).items()}
    assert worst["M"] < 1e-9, worst
    assert worst["h"] < 1e-9, worst
    assert worst["pos"] < 1e-9, worst
    assert worst["jac"] < 1e-9, worst


def test_total_mass_matches(setup):
    m, _, _, pm = setup
    assert pm.total_mass_kg == pytest.approx(float(m.body_mass.sum()), abs=1e-12)
    assert pm.total_mass_kg == pytest.approx(13.741, abs=1e-9)  # URDF masses summed


def test_foot_jdotv_matches_finite_differences(setup):
    _, _, _, pm = setup
    rng = np.random.default_rng(1)
    dt = 1e-6
    for _ in range(5):
        q, v = random_state(pm, rng)
        pm.update(q, v)
        jdotv = pm.foot_jdotv_in_world.copy()
        jac0 = pm.foot_jac_in_world.copy()
        pm.update(pin.integrate(pm.model, q, v * dt), v)
        jac1 = pm.foot_jac_in_world.copy()
        fd = np.einsum("lij,j->li", (jac1 - jac0) / dt, v)
        assert np.abs(fd - jdotv).max() < 1e-4 * max(1.0, np.abs(jdotv).max())


def test_foot_terms_match_pinocchio_frame_api(setup):
    """The compiled foot terms (from data.J, data.dJ and the frame placements) equal Pinocchio's own frame
    algorithms: getFrameJacobian and getFrameClassicalAcceleration in LOCAL_WORLD_ALIGNED at the foot."""
    _, _, _, pm = setup
    rng = np.random.default_rng(7)
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for _ in range(5):
        q, v = random_state(pm, rng)
        pm.update(q, v)
        md = pm.model.createData()
        pin.computeJointJacobians(pm.model, md, q)
        pin.forwardKinematics(pm.model, md, q, v, np.zeros(quad.NV))
        pin.updateFramePlacements(pm.model, md)
        for i, fid in enumerate(pm.foot_frame_ids):
            jac = pin.getFrameJacobian(pm.model, md, fid, lwa)[:3]
            acc = pin.getFrameClassicalAcceleration(pm.model, md, fid, lwa).linear
            np.testing.assert_allclose(pm.foot_pos_in_world[i], md.oMf[fid].translation, atol=1e-14)
            np.testing.assert_allclose(pm.foot_jac_in_world[i], jac, atol=1e-13)
            np.testing.assert_allclose(pm.foot_jdotv_in_world[i], acc, atol=1e-11)
            np.testing.assert_allclose(pm.foot_vel_in_world[i], jac @ v, atol=1e-12)


def test_foot_velocity_matches_mujoco(setup):
    """Foot-centre velocities (world axes) against MuJoCo's site velocity at the same state, through the
    bridge (independent of the model's Jacobians)."""
    m, d, br, pm = setup
    rng = np.random.default_rng(2)
    res = np.zeros(6)
    for _ in range(10):
        same_random_state(m, d, br, pm, rng)
        for i, foot in enumerate(quad.FOOT_FRAMES):
            sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, foot)
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, sid, res, 0)  # world axes, [ang, lin]
            assert np.abs(res[3:] - pm.foot_vel_in_world[i]).max() < 1e-9


def test_bridge_round_trip(setup):
    m, _d, br, pm = setup
    rng = np.random.default_rng(3)
    q, v = random_state(pm, rng)
    qpos, qvel = np.zeros(m.nq), np.zeros(m.nv)
    br.qpos_mj(q, qpos)
    br.qvel_mj(q, v, qvel)
    assert np.allclose(br.q_pin(qpos), q, atol=1e-15)
    assert np.allclose(br.v_pin(qpos, qvel), v, atol=1e-12)
    q2, v2 = np.zeros(quad.NQ), np.zeros(quad.NV)
    br.state_pin(qpos, qvel, q2, v2)  # the compiled tick read: same conversion
    assert np.allclose(q2, q, atol=1e-15) and np.allclose(v2, v, atol=1e-12)
    # leg order: core joint 0 is FL_hip, which MuJoCo (URDF order FR, FL, ...) stores at index 3
    assert br.joint_qadr[0] == 7 + 3
    ctrl = np.zeros(m.nu)
    u = np.arange(12.0)
    br.ctrl_mj(u, ctrl)
    fl_hip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "FL_hip_joint")
    assert ctrl[fl_hip] == 0.0 and ctrl[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "RR_calf_joint")] == 11.0


def test_leg_ik_inverts_fk_and_matches_pinocchio(setup):
    _, _, _, pm = setup
    rng = np.random.default_rng(4)
    for _ in range(50):
        qj = np.concatenate(
            [[rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 1.5), rng.uniform(-2.5, -1.0)] for _ in range(4)]
        )
        q = pin.neutral(pm.model)
        q[7:] = qj
        pm.update(q, np.zeros(quad.NV))
        for i in range(quad.N_LEGS):
            p = KIN.leg_fk(i, qj[3 * i : 3 * i + 3])
            assert np.allclose(p + A1.hip_positions_in_trunk[i], pm.foot_pos_in_world[i], atol=1e-12)
            assert np.allclose(KIN.leg_ik(i, p), qj[3 * i : 3 * i + 3], atol=1e-9)


def test_plant_limits_and_friction(setup):
    m, _d, _br, _ = setup
    assert np.allclose(m.actuator_ctrlrange, [[-33.5, 33.5]] * 12)
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    spec = robot_spec(options=PlantOptions(floor_friction=0.3, timestep_s=0.002))
    m2 = compile_plant(spec)
    assert m2.opt.timestep == 0.002
    d2 = mujoco.MjData(m2)
    q = pin.neutral(RobotModel().model)
    q[2] = 0.3
    q[7:] = KIN.legs_ik([[0.0, g.lateral_m, -0.28] for g in A1.legs])
    StateBridge(m2).qpos_mj(q, d2.qpos)
    for _ in range(300):
        mujoco.mj_step(m2, d2)
    frictions = [mu for _, mu in measure_contact_friction(m2, d2)]
    assert frictions and np.allclose(frictions, 0.3)


def test_foot_contact_sensors_match_contact_forces(setup):
    """The sensor-based reader equals summing mj_contactForce over data.contact (sign: force on the foot)."""
    from taslel_bench.control.gait import GaitParams
    from taslel_bench.control.nominal import NominalController, PDGains

    m, _, br, _ = setup
    d = mujoco.MjData(m)
    ctl = NominalController(GaitParams(), PDGains())
    q = np.zeros(quad.NQ)
    q[6], q[2], q[7:] = 1.0, 0.29, ctl.stand_configuration()
    br.qpos_mj(q, d.qpos)
    reader = FootContactReader(m)
    feet = foot_geom_ids(m)
    sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f) for f in quad.FOOT_FRAMES]
    log, per_tick = [], []
    checked = 0
    for k in range(1500):
        br.ctrl_mj(ctl.compute(k * 1e-3, d.qpos[br.joint_qadr], d.qvel[br.joint_dadr]), d.ctrl)
        mujoco.mj_step(m, d)
        if k % 50:
            continue
        reader.read(d)
        ref = np.zeros((4, 3))
        f6 = np.zeros(6)
        for i in range(d.ncon):
            mujoco.mj_contactForce(m, d, i, f6)
            f_world = d.contact.frame[i].reshape(3, 3).T @ f6[:3]  # force of geom1 on geom2
            for leg, g in enumerate(feet):
                ref[leg] += f_world if d.contact.geom[i, 1] == g else 0.0
                ref[leg] -= f_world if d.contact.geom[i, 0] == g else 0.0
        assert np.allclose(reader.forces_in_world, ref, atol=1e-9)
        # position sensor = site position MuJoCo computed in the same step
        assert np.allclose(reader.foot_pos_in_world, d.site_xpos[sites], atol=1e-12)
        checked += int(reader.in_contact.sum())
        log.append(d.sensordata.copy())
        per_tick.append((reader.forces_in_world.copy(), reader.in_contact.copy(),
                         reader.slip_velocity_in_world.copy(), reader.foot_pos_in_world.copy()))
    assert checked > 20
    # the episode trace's vectorised path gives what read() gives tick by tick
    whole = reader.from_sensor_log(np.array(log))
    for key, j in (("forces_in_world", 0), ("in_contact", 1), ("slip_velocity_in_world", 2), ("foot_pos_in_world", 3)):
        assert np.array_equal(whole[key], np.array([row[j] for row in per_tick])), key
    # standing still, the feet carry the weight
    assert reader.body_contact is False


def test_controller_reference_table_matches_fresh_computation():
    """The per-period tables of q_des/qd_des and gait state return what a fresh computation gives."""
    from taslel_bench.control.gait import GaitParams
    from taslel_bench.control.nominal import NominalController, PDGains

    tab = NominalController(GaitParams(), PDGains(), stand_duration_s=0.5, fd_dt_s=1e-3)
    fresh = NominalController(GaitParams(), PDGains(), stand_duration_s=0.5, fd_dt_s=1e-3)
    fresh.use_tables = False
    assert tab._period_ticks == 400
    rng = np.random.default_rng(3)
    for k in range(2000):  # stand, first period (fills the tables), then 3 periods of look-ups
        t = k * 1e-3
        q, qd = rng.normal(size=12), rng.normal(size=12)
        assert np.abs(tab.compute(t, q, qd) - fresh.compute(t, q, qd)).max() < 1e-9
        assert np.abs(tab.qd_des - fresh.qd_des).max() < 1e-9
        if k >= 500:
            gs, ref = tab.contact_plan(t), fresh.gait.state(((k - 500) % 400) * 1e-3)
            dphi = abs(fresh.contact_plan(t).phi - gs.phi)  # the table's exact grid time vs t - 0.5 s, rounded
            assert min(dphi, 1.0 - dphi) < 1e-9
            assert np.array_equal(gs.in_stance, ref.in_stance) and np.allclose(gs.swing_phase, ref.swing_phase)
    assert tab._table_filled.all()
