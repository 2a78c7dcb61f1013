"""Slip detection from proprioception (leg kinematics, torques, trunk IMU) and the per-foot slip caps."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.legs import feet_and_jacobians, foot_forces_from_torques
from estimators.simple import FixedEstimator
from estimators.slip import SlipDetector, SlipSettings
from estimators.slip_bound import SlipBoundEstimator
from taslel_bench.interfaces import ImuSample, Proprioception
from taslel_bench.robot.model import RobotModel

STAND = np.array([0.0, 0.8, -1.6] * 4)  # [rad] standing A1


def test_leg_kinematics_match_pinocchio() -> None:
    """Foot positions (trunk frame) and leg Jacobians equal Pinocchio's at a random pose, trunk at identity."""
    rng = np.random.default_rng(0)
    q = np.zeros(19)
    q[6] = 1.0
    q[7:] = STAND + rng.normal(0, 0.3, 12)
    model = RobotModel()
    model.update(q, np.zeros(18))
    p, jac = feet_and_jacobians(q[7:])
    assert np.allclose(p, model.foot_pos_in_world, atol=1e-9)
    for leg in range(4):
        assert np.allclose(jac[leg], model.foot_jac_in_world[leg][:, 6 + 3 * leg : 9 + 3 * leg], atol=1e-9)


def test_torques_give_back_the_foot_force() -> None:
    """tau = -J' f for a known force on each foot: the force comes back."""
    _, jac = feet_and_jacobians(STAND)
    f = np.array([[5.0, -2.0, 40.0], [0.0, 3.0, 30.0], [-8.0, 1.0, 50.0], [1.0, 1.0, 20.0]])  # [N]
    tau = -np.einsum("lji,lj->li", jac, f).reshape(12)
    assert np.allclose(foot_forces_from_torques(jac, tau), f)


def _obs(t: float, qd: np.ndarray, tau: np.ndarray, accel_b=(0.0, 0.0, 9.81)) -> Proprioception:
    imu = ImuSample(np.array([1.0, 0, 0, 0]), np.zeros(3), np.asarray(accel_b, float))
    return Proprioception(t, STAND.copy(), qd, tau, imu=imu)


def _standing_torques(fz: float = 30.0, fx_front_left: float = 0.0) -> np.ndarray:
    """Joint torques holding fz [N] on every foot (and a forward push on FL)."""
    _, jac = feet_and_jacobians(STAND)
    f = np.tile([0.0, 0.0, fz], (4, 1))
    f[0, 0] = fx_front_left
    return -np.einsum("lji,lj->li", jac, f).reshape(12)


@pytest.mark.parametrize(("fast_speed", "first_tick"), [(10.0, 21), (0.4, 13)])
def test_detector_sees_the_foot_that_slides(fast_speed: float, first_tick: int) -> None:
    """Four loaded feet from tick 0, the trunk still (IMU at rest): from tick 5 FL's leg moves its foot
    backwards at 0.5 m/s while the others hold. Slow rule (fast rule out of reach): FL slips once its stance is
    judged (touchdown_s: tick 10), its mean over average_ticks is full (tick 19) and confirm_ticks have passed
    (tick 21). Fast rule (0.5 > 0.4 m/s): the trunk velocity is known from the first judged tick (10), so
    speeds count from tick 11, and fast_confirm_ticks = 3 fire at tick 13.
    The others never slip; FL's force ratio is the one its torques imply."""
    s = SlipSettings(touchdown_s=0.01, average_ticks=10, confirm_ticks=3, speed_mps=0.1, fast_touchdown_s=0.01,
                     fast_speed_mps=fast_speed, fast_confirm_ticks=3)
    det = SlipDetector(s)
    _, jac = feet_and_jacobians(STAND)
    qd = np.zeros(12)
    qd[0:3] = np.linalg.solve(jac[0], [-0.5, 0.0, 0.0])  # [rad/s] FL foot at -0.5 m/s relative to the trunk
    tau = _standing_torques(30.0, fx_front_left=6.0)
    first = None
    for k in range(40):
        st = det.step(_obs(k * 1e-3, np.zeros(12) if k < 5 else qd, tau))
        assert st.loaded.all() and not st.slipping[1:].any()
        if st.slipping[0] and first is None:
            first = k
    assert first == first_tick
    assert st.ratio[0] == pytest.approx(0.2, abs=1e-6)
    # the trunk velocity follows the three holding feet: FL (0.5 m/s > 4 x speed_mps) is left out of the odometry
    assert abs(det.velocity.v_w[0]) < 1e-9


def test_slip_caps_the_foot_and_the_feet_that_reach_its_place() -> None:
    """A slip of FL caps FL at the floor at once; RL (behind) is not capped while it is behind the slip."""
    est = SlipBoundEstimator(FixedEstimator(0.8), floor_mu=0.1, rise_per_s=0.0, ratio_scale=0.0,
                             detector={"touchdown_s": 0.0, "average_ticks": 1, "confirm_ticks": 1})
    est.reset()
    _, jac = feet_and_jacobians(STAND)
    qd = np.zeros(12)
    qd[0:3] = np.linalg.solve(jac[0], [-0.5, 0.0, 0.0])
    tau = _standing_torques(30.0)
    out = [est.step(_obs(k * 1e-3, np.zeros(12) if k < 3 else qd, tau)) for k in range(10)]
    assert out[0].mu_per_foot.tolist() == [0.8] * 4
    feet = out[-1].mu_per_foot
    assert feet[0] == pytest.approx(0.1)
    assert feet[1] == pytest.approx(0.1)  # FR stands beside the slip: it has reached it
    assert feet[2] == pytest.approx(0.8) and feet[3] == pytest.approx(0.8)  # hind feet: 0.36 m behind
    assert est.diagnostics()["foot_slips"] == 1


class _ImuRecorder:
    name = "imu_recorder"
    reads_imu = True

    def __init__(self) -> None:
        self.imu: list[ImuSample] = []

    def reset(self) -> None:
        self.imu.clear()

    def step(self, obs: Proprioception):
        from taslel_bench.interfaces import FrictionEstimate

        self.imu.append(obs.imu)
        return FrictionEstimate(mu=0.5)


def test_episode_passes_the_trunk_imu() -> None:
    """Proprioception.imu at tick k reads the state the tick starts from (the trace's row k - 1): attitude,
    gyro in trunk axes, and the accelerometer's specific force = R' (velocity change over the tick / dt - g)
    (+9.81 m/s² up when the trunk does not accelerate)."""
    from taslel_bench.sim.build import Built
    from tests.conftest import compose_cfg

    built = Built(compose_cfg(["duration=0.05", "progress=false", "record.mcap=false", "filter.enabled=false"]))
    rec = _ImuRecorder()
    built.episode.estimator = rec
    res = built.episode.run()
    tr = res.trace
    tr.finalize()
    dt = float(tr.t_s[1] - tr.t_s[0])
    for k in (2, 10, 40):
        imu = rec.imu[k]
        assert np.allclose(imu.quat_wxyz, tr.base_quat_wxyz[k - 1], atol=1e-12)
        assert np.allclose(imu.gyro_in_base, tr.base_angvel_b[k - 1], atol=1e-12)
        w, x, y, z = tr.base_quat_wxyz[k - 1]
        rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        acc_w = (tr.base_linvel_w[k - 1] - tr.base_linvel_w[k - 2]) / dt + np.array([0.0, 0.0, 9.81])
        assert np.allclose(imu.accel_in_base, rot.T @ acc_w, atol=1e-9)
    rec.imu.clear()
    _ImuRecorder.reads_imu = False  # an estimator that does not read it gets none (the tick does not sample it)
    try:
        built.episode.run()
    finally:
        _ImuRecorder.reads_imu = True
    assert len(rec.imu) > 40 and all(sample is None for sample in rec.imu)


def test_stance_detection_counts_stances_with_a_slip() -> None:
    """studies.estimator_slip_observability.stance_detection: stances of >= min_ticks after after_s, the share
    with a slip (up to 3 ticks past the stance) and the median tick of the stance the slip was first seen."""
    from studies.estimator_slip_observability import stance_detection

    t = np.arange(400) * 1e-3
    loaded = np.zeros((400, 2), bool)
    loaded[50:200, 0] = loaded[250:390, 0] = True  # two long stances of foot 0
    loaded[100:120, 1] = True  # a short one of foot 1: not counted
    slipping = np.zeros((400, 2), bool)
    slipping[290, 0] = True  # 40 ticks into the second stance
    slipping[110, 1] = True
    n, share, first = stance_detection(loaded, slipping, t, min_ticks=80, after_s=0.0)
    assert (n, share, first) == (2, 0.5, 40.0)
    assert stance_detection(loaded, slipping, t, min_ticks=80, after_s=0.1)[:2] == (1, 1.0)


def test_slip_kernel_matches_the_numpy_legs() -> None:
    """The compiled leg kinematics the detector's tick reads and the kernel's torque-implied forces equal
    estimators.legs' (numpy)."""
    from estimators.legs import chain_table
    from estimators.slip_kernel import _solve_transposed
    from taslel_bench.robot.leg_chain import feet_and_jacobians_into

    rng = np.random.default_rng(3)
    q = STAND + rng.normal(0, 0.3, 12)
    tau = rng.normal(0, 5, 12)
    p_ref, jac_ref = feet_and_jacobians(q)
    f_ref = foot_forces_from_torques(jac_ref, tau)
    p, jac, f = np.empty((4, 3)), np.empty((4, 3, 3)), np.empty(3)
    feet_and_jacobians_into(chain_table(), q, p, jac)
    assert np.allclose(p, p_ref) and np.allclose(jac, jac_ref)
    for i in range(4):
        _solve_transposed(jac[i], tau[3 * i : 3 * i + 3].copy(), f)
        assert np.allclose(f, f_ref[i])


def test_detector_reads_the_legs_of_its_robot() -> None:
    """SlipDetector(robot=...) uses that robot's chain: on the first tick (trunk at the origin, level IMU) its
    feet are the robot's feet in the trunk frame."""
    from taslel_bench.robot.description import load_robot
    from taslel_bench.robot.leg_chain import chain_table, feet_in_trunk

    go1 = load_robot("go1")
    out = SlipDetector(robot=go1).step(_obs(0.0, np.zeros(12), np.zeros(12)))
    np.testing.assert_allclose(out.feet_w, feet_in_trunk(chain_table(go1), STAND), rtol=0, atol=1e-12)
    assert np.abs(out.feet_w - feet_and_jacobians(STAND)[0]).max() > 1e-3  # not the A1's


def _feet(xy: list[list[float]]) -> object:
    from estimators.slip import FootState

    w = np.zeros((4, 3))
    w[:, :2] = xy
    return FootState(np.ones(4, bool), np.zeros(4, bool), np.zeros(4), np.full(4, np.nan), w, np.array([1.0, 0.0]))


def test_caps_relax_from_each_feet_arrival() -> None:
    """An event of FL at x = 0.2 m, t = 0 (rise 1/s, floor 0.1): FL is capped at once and relaxes from t = 0;
    RL (0.36 m behind) is not capped until it reaches x = 0.15 (behind_m 0.05), then starts at the floor;
    a foot more than ahead_m past the place is free again; own_ahead_m frees FL past 0.5 m."""
    est = SlipBoundEstimator(FixedEstimator(0.8), floor_mu=0.1, rise_per_s=1.0, behind_m=0.05, ahead_m=0.3,
                             own_ahead_m=0.3)
    est._add(0, np.array([0.2, 0.05]), 0.0)
    caps = est._caps(0.0, _feet([[0.2, 0.05], [0.2, -0.05], [-0.16, 0.05], [-0.16, -0.05]]))
    assert caps == pytest.approx([0.1, 0.1, np.inf, np.inf])  # FR stands beside the slip
    caps = est._caps(0.5, _feet([[0.3, 0.05], [0.3, -0.05], [0.16, 0.05], [-0.06, -0.05]]))
    assert caps == pytest.approx([0.6, 0.6, 0.1, np.inf])  # RL arrived at 0.5 s: from the floor
    caps = est._caps(0.8, _feet([[0.55, 0.05], [0.45, -0.05], [0.2, 0.05], [0.0, -0.05]]))
    assert caps == pytest.approx([np.inf, 0.9, 0.4, np.inf])  # FL 0.35 m past (own reach 0.3), FR 0.25 m


def test_events_are_capped_in_number_and_open_rows_follow() -> None:
    """Beyond MAX_EVENTS the oldest event falls off; a foot's ongoing event keeps pointing at its own row."""
    from estimators.slip_bound import MAX_EVENTS

    est = SlipBoundEstimator(FixedEstimator(0.8))
    est._add(1, np.zeros(2), 0.0)
    for k in range(MAX_EVENTS):
        est._add(0, np.array([float(k), 0.0]), 0.01 * k)
    assert len(est._t) == MAX_EVENTS and est._open[1] == -1  # FR's event fell off
    assert est._xy[est._open[0], 0] == MAX_EVENTS - 1


def test_gate_lets_slips_at_the_assumed_friction_pass() -> None:
    """With gate_margin, a slip whose force ratio (x ratio_scale) is not below the foot's estimate opens no
    event; one well below it opens an event capped at that evidence."""
    est = SlipBoundEstimator(FixedEstimator(0.3), ratio_scale=0.8, gate_margin=0.05)
    est._last_mu = np.full(4, 0.3)
    assert est._gated(0, 0.35) and est._onset_cap(0.35) == pytest.approx(0.28)  # 0.28 >= 0.3 - 0.05
    assert not est._gated(0, 0.25) and est._onset_cap(0.25) == pytest.approx(0.2)
    assert est._onset_cap(float("nan")) == est.floor_mu
    plain = SlipBoundEstimator(FixedEstimator(0.3), ratio_scale=0.8)
    assert not plain._gated(0, 0.35) and plain._onset_cap(0.35) == plain.floor_mu  # no gate: the floor


def test_caps_relax_no_higher_than_the_slip_proves() -> None:
    """With ceiling_scale, an event's cap relaxes up to ceiling_scale x the median force ratio of its slip."""
    est = SlipBoundEstimator(FixedEstimator(0.8), floor_mu=0.1, rise_per_s=1.0, ratio_scale=0.0, ceiling_scale=0.9)
    est._add(0, np.zeros(2), 0.0)
    est._ratios[0] = [0.15, 0.2, 0.25]
    est._settle(0)
    feet = _feet([[0.0, 0.05], [0.0, -0.05], [-0.36, 0.05], [-0.36, -0.05]])
    assert est._caps(0.05, feet)[0] == pytest.approx(0.15)  # relaxing: 0.1 + 0.05
    assert est._caps(5.0, feet)[0] == pytest.approx(0.18)  # the ceiling: 0.9 x 0.2
