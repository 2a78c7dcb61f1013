"""Foothold choice of the terrain-following trot (``controller.foothold_search``): touchdowns moved along the
heading away from edges and from footholds whose shin would rest on one; the gait's own footholds where the
ground has no edge."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from taslel_bench.control.footholds import STANCE_POSES, FootholdPlanner
from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import PDGains
from taslel_bench.control.terrain_following import TerrainFollowingController
from taslel_bench.interfaces import OBSTACLE, Box, Log, Plane, Ramp, Terrain
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.robot.model import RobotModel
from tests.conftest import compose_cfg

HEADING = (1.0, 0.0)
A1 = load_robot("a1")
KIN = LegKinematics(A1)
STAND_M = GaitParams().stand_height_m
HALF = 0.5 * GaitParams().speed_mps * GaitParams().period_s * GaitParams().duty  # half the stance stroke [m]
LOG = Log(x_m=0.6, z_m=-0.04, radius_m=0.1, half_width_m=0.5, friction=1.0)  # the logs world's first log
FL = quad.LEGS.index("FL")


def _target(leg: int) -> list[float]:
    return [HALF, A1.legs[leg].lateral_m, -STAND_M]


def test_knee_and_foot_match_pinocchio():
    """The planner's knee (calf joint) and foot in the hip frame against Pinocchio's joint placements."""
    model = RobotModel()
    rng = np.random.default_rng(7)
    knees = [model.model.getJointId(f"{leg}_calf_joint") for leg in quad.LEGS]
    for _ in range(20):
        targets = [np.array([rng.uniform(-0.1, 0.1), A1.legs[i].lateral_m + rng.uniform(-0.03, 0.03),
                             rng.uniform(-0.32, -0.2)]) for i in range(4)]
        q = pin.neutral(model.model)
        q[7:] = np.concatenate([KIN.leg_ik(i, t) for i, t in enumerate(targets)])
        model.update(q, np.zeros(quad.NV))
        for i, t in enumerate(targets):
            knee, foot = KIN.knee_and_foot(i, *t)
            hip = A1.hip_positions_in_trunk[i]
            np.testing.assert_allclose(np.array(knee) + hip, model.data.oMi[knees[i]].translation, atol=1e-9)
            np.testing.assert_allclose(np.array(foot) + hip, model.foot_pos_in_world[i], atol=1e-9)
            np.testing.assert_allclose(foot, t, atol=1e-9)


def test_flat_ground_and_a_plane_slope_keep_the_gaits_footholds():
    ramp = Ramp(start_x_m=-5.0, run_m=10.0, angle_deg=10.0, half_width_m=1.0, role=OBSTACLE)  # 10 deg, no edge
    for terrain in (Terrain((Plane(),)), Terrain((Plane(), ramp))):
        planner = FootholdPlanner(terrain, 0.05)
        for x in np.linspace(-1.0, 1.0, 9):
            ground = terrain.height_at(float(x), 0.13)
            assert planner.offset(FL, (float(x), 0.13), HEADING, _target(FL), 2 * HALF, ground) == 0.0


def _shin_clearance(terrain: Terrain, foot_xy: tuple[float, float], leg: int, delta: float) -> float:
    """Smallest distance [m] of the shin capsule to the terrain over the planned stance, by the slow reference
    query (Terrain.capsule_distance, every part in Python) -- an independent path from the planner's."""
    h = terrain.height_at(*foot_xy)
    foot_w = np.array([*foot_xy, h + A1.foot_radius_m])
    out = np.inf
    for progress in STANCE_POSES:
        knee, foot = KIN.knee_and_foot(leg, HALF + delta - progress * 2 * HALF, _target(leg)[1], -STAND_M + h)
        knee_w = foot_w + np.subtract(knee, foot)
        end = knee_w + A1.shin_axis_fraction * (foot_w - knee_w)
        out = min(out, terrain.capsule_distance(knee_w, end, A1.shin_radius_m)[0])
    return out


def test_a_touchdown_just_past_a_log_moves_off_it_and_the_shin_clears_it():
    """Log 0 spans x = 0.51-0.69 m on the floor. A gait touchdown at x = 0.72 m leaves the shin 6 mm from the
    log in stance (level trunk; falls traced before had stance feet at 0.74-0.77 m and the trunk pitched, the
    shin barrier at -11 mm); the planned one keeps the planner's clearance."""
    terrain = Terrain((Plane(), LOG))
    planner = FootholdPlanner(terrain, 0.05)
    td = (0.72, 0.13)
    assert _shin_clearance(terrain, td, FL, 0.0) < 0.01  # the gait's foothold
    delta = planner.offset(FL, td, HEADING, _target(FL), 2 * HALF, 0.0)
    assert delta != 0.0
    chosen = (td[0] + delta, td[1])
    assert _shin_clearance(terrain, chosen, FL, 0.0) >= planner.shin_clearance_m - 0.003  # 9 vs 7 axis points
    assert abs(terrain.height_at(*chosen) - terrain.height_at(chosen[0] - 0.03, td[1])) < planner.edge_rise_m


@pytest.mark.parametrize("td_x", [0.785, 0.80, 0.815])
def test_a_touchdown_at_a_step_edge_moves_to_where_the_ground_is_even(td_x):
    """A 5 cm step whose riser is at x = 0.8 m: touchdowns within 2 cm of its edge move to where the ground is level
    within the planner's probes (3 cm ahead, behind and to the sides)."""
    box = Box(centre_m=(1.1, 0.0, 0.025), half_size_m=(0.3, 1.0, 0.025), friction=1.0, role=OBSTACLE)
    terrain = Terrain((Plane(), box))
    planner = FootholdPlanner(terrain, 0.05)
    delta = planner.offset(FL, (td_x, 0.13), HEADING, _target(FL), 2 * HALF, 0.0)
    x = td_x + delta
    heights = [terrain.height_at(x + dx, 0.13) for dx in (-0.029, 0.0, 0.029)]  # within the probes
    assert max(heights) - min(heights) < 1e-9, (delta, heights)
    violations = planner.violations(FL, (td_x, 0.13), HEADING, _target(FL), 2 * HALF, 0.0)
    assert violations[0] > violations.min()  # the gait's own foothold was worse


@pytest.mark.parametrize("td_x", [0.76, 0.765])
def test_a_touchdown_just_before_a_riser_moves_away_from_its_face(td_x):
    """A foot centre 3.5-4 cm before a 5 cm riser would start its next swing against the riser's face: the
    chosen touchdown has no ground more than 1 cm above it within the face probes' reach (4.5 cm)."""
    box = Box(centre_m=(1.1, 0.0, 0.025), half_size_m=(0.3, 1.0, 0.025), friction=1.0, role=OBSTACLE)
    terrain = Terrain((Plane(), box))
    planner = FootholdPlanner(terrain, 0.05)
    x = td_x + planner.offset(FL, (td_x, 0.13), HEADING, _target(FL), 2 * HALF, 0.0)
    h = terrain.height_at(x, 0.13)
    ahead = [terrain.height_at(x + dx, 0.13) for dx in np.linspace(0.0, planner.riser_ahead_m, 13)]
    assert max(ahead) - h <= planner.edge_rise_m, (x, h, ahead)
    assert FootholdPlanner(terrain, 0.05, riser_ahead_m=0.03).offset(FL, (td_x, 0.13), HEADING, _target(FL),
                                                                      2 * HALF, 0.0) == 0.0  # 3 cm probes only


def _q_des(ctl, times, pose):
    out = []
    for t in times:
        ctl.compute(float(t), np.zeros(12), np.zeros(12), pose)
        out.append(ctl.q_des.copy())
    return np.array(out)


def test_the_planner_changes_nothing_on_flat_ground_and_moves_a_touchdown_off_a_step_edge():
    pose = np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0])
    times = np.arange(0.0, 1.5, 1e-3)
    flat = Terrain((Plane(),))
    plain = TerrainFollowingController(GaitParams(), PDGains(), terrain=flat)
    planned = TerrainFollowingController(GaitParams(), PDGains(), terrain=flat, footholds=FootholdPlanner(flat, 0.05))
    np.testing.assert_array_equal(_q_des(planned, times, pose), _q_des(plain, times, pose))
    # FR lifts off first, at the end of the stand (0.5 s), for a gait touchdown at x = 0.18 + 0.12 m: a step up
    # whose riser is 5 mm behind that point (the feet standing at x = 0.18 m are on the floor)
    riser_x = 0.295
    step = Box(centre_m=(riser_x + 1.0, 0.0, 0.025), half_size_m=(1.0, 1.0, 0.025), friction=1.0, role=OBSTACLE)
    terrain = Terrain((Plane(), step))
    ctl = TerrainFollowingController(GaitParams(), PDGains(), terrain=terrain,
                                     footholds=FootholdPlanner(terrain, 0.05))
    _q_des(ctl, times[times < 0.51], pose)
    fr = quad.LEGS.index("FR")
    assert abs(ctl._offset_plan_m[fr]) >= 0.02  # off the edge: 3 cm probes
    assert ctl._offset_plan_m[FL] == 0.0  # FL still stands


def test_foothold_search_is_checked_and_needs_terrain_following():
    from taslel_bench.api import build_controller
    from taslel_bench.config.validate import validate
    from taslel_bench.util.fields import ConfigError

    cfg = compose_cfg(["controller.terrain_following=true", "controller.foothold_search=0.05"])
    ctl = build_controller(cfg, Terrain((Plane(),)))
    assert isinstance(ctl.footholds, FootholdPlanner)
    assert build_controller(compose_cfg(["controller.terrain_following=true"]), Terrain((Plane(),))).footholds is None
    with pytest.raises(ConfigError, match="controller.foothold_search=0.05: foothold choice is part of"):
        validate(compose_cfg(["controller.foothold_search=0.05"]))
    with pytest.raises(ConfigError, match=r"controller.foothold_search=0.5.*\[0, 0.08\]"):
        validate(compose_cfg(["controller.terrain_following=true", "controller.foothold_search=0.5"]))



def test_a_replan_at_mid_swing_plans_from_the_hip_then_and_the_offset_stays_continuous():
    """FR lifts off at 0.5 s with the trunk held still (slower than commanded): the lift-off plan predicts the
    touchdown at x = 0.30 m (level step top: offset 0), the plan at swing phase 0.5 from the hip then at
    x = 0.26 m, 5 mm before a riser at 0.265 m, and moves it off the edge. The offset eases from its value at the
    re-plan to the new plan without a jump (< 1 mm per 1 ms tick) and reaches it at touchdown."""
    pose = np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0])
    step = Box(centre_m=(1.265, 0.0, 0.025), half_size_m=(1.0, 1.0, 0.025), friction=1.0, role=OBSTACLE)
    terrain = Terrain((Plane(), step))
    fr = quad.LEGS.index("FR")
    ctl = TerrainFollowingController(GaitParams(), PDGains(), terrain=terrain,
                                     footholds=FootholdPlanner(terrain, 0.05), replan_phase=0.5)
    offsets, plans = [], []
    for t in np.arange(0.0, 0.7, 1e-3):
        ctl.compute(float(t), np.zeros(12), np.zeros(12), pose)
        offsets.append(ctl.foothold_offset_m[fr])
        plans.append(ctl._offset_plan_m[fr])
    assert plans[550] == 0.0  # lift-off plan (touchdown predicted on the step's level top)
    assert abs(plans[650]) >= 0.02  # re-planned off the riser
    assert np.abs(np.diff(offsets)).max() < 1e-3
    assert abs(offsets[-1] - plans[650]) < 1e-3  # FR is back in stance at 0.7 s, on the re-planned offset
    without = TerrainFollowingController(GaitParams(), PDGains(), terrain=terrain,
                                         footholds=FootholdPlanner(terrain, 0.05))
    _q_des(without, np.arange(0.0, 0.7, 1e-3), pose)
    assert without._offset_plan_m[fr] == 0.0  # without the re-plan the lift-off plan stands


def test_replan_phase_is_checked_and_needs_foothold_choice():
    from taslel_bench.config.validate import validate
    from taslel_bench.util.fields import ConfigError

    on = ["controller.terrain_following=true", "controller.foothold_search=0.05"]
    validate(compose_cfg([*on, "controller.foothold_replan_phase=0.5"]))
    with pytest.raises(ConfigError, match=r"controller.foothold_replan_phase=1.0.*\[0, 1\)"):
        validate(compose_cfg([*on, "controller.foothold_replan_phase=1.0"]))
    with pytest.raises(ConfigError, match="controller.foothold_replan_phase=0.5: re-planning needs foothold choice"):
        validate(compose_cfg(["controller.terrain_following=true", "controller.foothold_replan_phase=0.5"]))


def test_swing_heights_from_measured_hips_lift_a_sagging_trunks_swing_feet_by_the_sag():
    """A trunk at the gait's height (hip = foot radius + stand height above the ground) gives the gait's q_des;
    one held 2 cm lower gives a sag estimate of 2 cm (low-passed) and swing feet aimed that much higher in the
    hip frame once the correction has eased in (they land at swing phase 1, not where the gait's half-sine lift
    is 2 cm: phase ~0.9), stance feet unchanged."""
    flat = Terrain((Plane(),))
    at_height = np.array([0.0, 0.0, A1.foot_radius_m + STAND_M, 0.0, 0.0, 0.0, 1.0])
    times = np.arange(0.0, 1.0, 1e-3)
    plain = TerrainFollowingController(GaitParams(), PDGains(), terrain=flat)
    measured = TerrainFollowingController(GaitParams(), PDGains(), terrain=flat, swing_from_measured_hips=True)
    np.testing.assert_allclose(_q_des(measured, times, at_height), _q_des(plain, times, at_height), atol=1e-12)
    low = at_height.copy()
    low[2] -= 0.02
    fresh = TerrainFollowingController(GaitParams(), PDGains(), terrain=flat, swing_from_measured_hips=True)
    _q_des(fresh, np.arange(0.0, 0.6, 1e-3), low)  # 0.6 s at 2 cm low: 6 time constants of the low-pass
    t = 0.6  # FR and RL mid-swing (swing phase 0.5), FL and RR in stance
    fresh.compute(t, np.zeros(12), np.zeros(12), low)
    assert abs(fresh.sag_m - 0.02) < 1e-4
    gs = fresh.contact_plan(t)
    rows = fresh.gait.foot_targets_list(fresh.gait_time(t))
    for i in range(4):
        lifted = rows[i][2] + (0.0 if gs.in_stance[i] else fresh.sag_m)
        expected = KIN.leg_ik(i, [rows[i][0], rows[i][1], lifted])
        np.testing.assert_allclose(fresh.q_des[3 * i:3 * i + 3], expected, atol=1e-9)
    assert not gs.in_stance[quad.LEGS.index("FR")] and gs.in_stance[FL]


def test_swing_from_measured_hips_needs_terrain_following():
    from taslel_bench.config.validate import validate
    from taslel_bench.util.fields import ConfigError

    validate(compose_cfg(["controller.terrain_following=true", "controller.swing_from_measured_hips=true"]))
    with pytest.raises(ConfigError, match="controller.swing_from_measured_hips=True: swing heights"):
        validate(compose_cfg(["controller.swing_from_measured_hips=true"]))
