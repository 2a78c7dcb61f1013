"""The terrain-aware filter's parts (``filter=terrain``): per-foot cones about the terrain normal, the terrain,
shin and knee barriers, the contact estimate, the priority relaxation, the packed distance kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from taslel_bench.control.contact_estimate import ContactEstimate, ContactEstimateSettings
from taslel_bench.filter.barriers.leg_clearance import LegClearance
from taslel_bench.filter.barriers.leg_points import LegPoints
from taslel_bench.filter.barriers.terrain_clearance import TerrainClearance
from taslel_bench.filter.layout import LAM, NV, TickInputs
from taslel_bench.filter.safety_filter import FilterSettings, SafetyFilter
from taslel_bench.filter.terrain_cone import TerrainFrictionCone, downhill_edge_basis, tangent_basis
from taslel_bench.interfaces import OBSTACLE, Box, Log, Plane, QPSolution, Ramp, Terrain
from taslel_bench.robot.description import load_robot
from taslel_bench.terrain.packed import PackedTerrain
from tests.conftest import compose_cfg
from tests.test_filter import TightReference, inputs_for, walking_states, world


@pytest.fixture(scope="module")
def states():
    return walking_states(8)


def test_terrain_cone_on_flat_ground_is_the_papers_pyramid(states):
    st, pm = states
    paper = SafetyFilter(FilterSettings(), TightReference())
    ours = SafetyFilter(FilterSettings(friction_cone="terrain"), TightReference(), terrain=Terrain((Plane(0.6),)))
    for state in st[:4]:
        a, b = paper.build(inputs_for(pm, state, 0.6), state[3]), ours.build(inputs_for(pm, state, 0.6), state[3])
        assert np.array_equal(a.G, b.G) and np.array_equal(a.h, b.h)


def test_terrain_cone_follows_the_normal_and_each_feet_mu(states):
    st, pm = states
    angle = math.radians(2.0)
    ramp = Ramp(start_x_m=-1.0, run_m=3.0, angle_deg=2.0)  # every foot on the incline (within its top 5 cm)
    assert isinstance(SafetyFilter(FilterSettings(friction_cone="terrain"), TightReference(),
                                   terrain=Terrain((ramp,))).friction, TerrainFrictionCone)
    f = SafetyFilter(FilterSettings(friction_cone="terrain"), TightReference(), terrain=Terrain((ramp,)))
    cone = f.friction
    q, v, gs, u = st[2]
    pm.update(q, v)
    mu = np.array([0.2, 0.4, 0.6, 0.8])
    x = TickInputs(pm, v, gs.in_stance, 1.0, gs.swing_phase, gs.swing_phase_rate, mu)
    qp = f.build(x, u)
    n = np.array([-math.sin(angle), 0.0, math.cos(angle)])
    t1, t2 = tangent_basis(n)
    assert np.allclose(t1, [math.cos(angle), 0, math.sin(angle)]) and np.allclose(t2, [0, 1, 0])
    for i in np.flatnonzero(gs.in_stance):
        rows = qp.G[cone.start + 5 * i : cone.start + 5 * i + 5, LAM][:, 3 * i : 3 * i + 3]
        mt = mu[i] / math.sqrt(2)
        assert np.allclose(rows, [-n, t1 - mt * n, -t1 - mt * n, t2 - mt * n, -t2 - mt * n])
    # a force on the cone's edge about n satisfies the rows, the same force about world z would not
    i = int(np.flatnonzero(gs.in_stance)[0])
    rows = qp.G[cone.start + 5 * i : cone.start + 5 * i + 5, LAM][:, 3 * i : 3 * i + 3]
    force = 50.0 * n + 0.99 * mu[i] / math.sqrt(2) * 50.0 * t1
    assert np.all(rows @ force <= qp.h[cone.start + 5 * i : cone.start + 5 * i + 5])
    sol = f.filter(x, u)
    lam = sol.lam.reshape(4, 3)
    for i in np.flatnonzero(gs.in_stance):  # the solution's forces lie in each foot's own cone about n
        fn = lam[i] @ n
        assert fn >= 1.0 - 1e-6
        assert abs(lam[i] @ t1) <= mu[i] / math.sqrt(2) * fn + 1e-6


def test_packed_distance_equals_the_parts():
    rng = np.random.default_rng(3)
    terrain = Terrain((Plane(1.0), Log(1.0, -0.04, 0.1), Box((2.0, 0.0, 0.03), (0.3, 0.5, 0.03)),
                       Ramp(start_x_m=2.5, run_m=1.0, angle_deg=12.0)))  # fmt: skip
    c = np.column_stack([rng.uniform(0, 4, 400), rng.uniform(-0.8, 0.8, 400), rng.uniform(-0.05, 0.3, 400)])
    for a, b in zip(
        terrain.sphere_distance(c, 0.02), PackedTerrain(terrain.parts).sphere_distance(c, 0.02), strict=True
    ):
        assert np.max(np.abs(a - b)) < 1e-12


def test_leg_point_terms_are_the_models_foot_terms_at_the_foot(states):
    st, pm = states
    q, v, _, _ = st[1]
    pm.update(q, v)
    points = LegPoints(pm)
    for i in range(4):
        jac, vel, jdotv = points.point_terms(i, pm.foot_pos_in_world[i], v)
        assert np.allclose(jac, pm.foot_jac_in_world[i], atol=1e-12)
        assert np.allclose(vel, pm.foot_vel_in_world[i], atol=1e-12)
        assert np.allclose(jdotv, pm.foot_jdotv_in_world[i], atol=1e-12)
        knee_to_foot = np.linalg.norm(pm.foot_pos_in_world[i] - points.knee(i))
        assert knee_to_foot == pytest.approx(0.2, abs=1e-3)  # the calf: 0.2 m


def test_friction_margin_shrinks_each_feet_cone_too(states):
    """robust.friction_margin scales the per-foot values as it scales the single mu (it did not before commit
    076b4de)."""
    from taslel_bench.filter.robust import RobustSettings

    st, pm = states
    q, v, gs, u = st[2]
    pm.update(q, v)
    mu = np.array([0.2, 0.4, 0.6, 0.8])
    plane = Terrain((Plane(1.0),))
    margin = SafetyFilter(FilterSettings(friction_cone="terrain", robust=RobustSettings(friction_margin=0.1)),
                          TightReference(), terrain=plane)
    exact = SafetyFilter(FilterSettings(friction_cone="terrain"), TightReference(), terrain=plane)
    margin.filter(TickInputs(pm, v, gs.in_stance, 1.0, gs.swing_phase, gs.swing_phase_rate, mu), u)
    exact.filter(TickInputs(pm, v, gs.in_stance, 0.9, gs.swing_phase, gs.swing_phase_rate, 0.9 * mu), u)
    rows = slice(margin.friction.start, margin.friction.start + 20)
    assert np.array_equal(margin.problem.G[rows], exact.problem.G[rows])
    assert not np.array_equal(margin.problem.G[rows], SafetyFilter(
        FilterSettings(friction_cone="terrain"), TightReference(), terrain=plane).build(
        TickInputs(pm, v, gs.in_stance, 1.0, gs.swing_phase, gs.swing_phase_rate, mu), u).G[rows])


def test_terrain_and_leg_barriers_hold_at_the_solution(states):
    st, pm = states
    terrain = Terrain((Plane(1.0), Log(0.25, 0.0, 0.06)))  # a log under the front legs
    w = world(terrain=terrain)
    barriers = [TerrainClearance(w), LegClearance(w, "shin"), LegClearance(w, "knee", part="knee", radius_m=0.02)]
    f = SafetyFilter(FilterSettings(), TightReference(), barriers)
    active = 0
    for state in st:
        x = inputs_for(pm, state, 1.0)
        res = f.filter(x, state[3])
        assert not res.used_fallback
        for b in barriers:
            rows = slice(b.start, b.start + 4)
            lhs = f.problem.G[rows, :NV] @ res.vdot
            assert np.all(lhs <= f.problem.h[rows] + 1e-6)
            active += int(np.isfinite(b.h).sum())
    assert active > 0
    # the terrain clearance's h on flat ground is the foot's height above it minus the lift profile
    tc = TerrainClearance(world(terrain=Terrain((Plane(1.0),))), lift_m=0.0, touchdown_allowance_m=0.0, role=None)
    f2 = SafetyFilter(FilterSettings(), TightReference(), [tc])
    for state in st:
        x = inputs_for(pm, state, 1.0)
        f2.build(x, state[3])
        swing = ~x.in_stance
        assert np.allclose(tc.h[swing], pm.foot_pos_in_world[swing, 2] - 0.02)
        assert np.all(np.isnan(tc.h[~swing]))


def test_contact_estimate_takes_early_touchdown_and_scheduled_lift_off():
    est = ContactEstimate(ContactEstimateSettings(force_threshold_n=20.0, min_swing_phase=0.5))
    loaded, free = np.tile([0, 0, 60.0], (4, 1)), np.zeros((4, 3))
    sched = np.array([True, False, False, True])
    # early in the swing a force is a scuff: swing
    assert list(est.update(sched, np.array([0, 0.3, 0.3, 0]), loaded)) == [True, False, False, True]
    # late swing and loaded: stance (early touchdown), latched through an unloaded tick
    assert list(est.update(sched, np.array([0, 0.8, 0.8, 0]), loaded)) == [True, True, True, True]
    assert list(est.update(sched, np.array([0, 0.81, 0.81, 0]), free)) == [True, True, True, True]
    assert est.early_touchdowns == 2
    # a late-swing foot pushed back (a toe stubbed on a riser), not up, stays in swing
    est2 = ContactEstimate()
    assert not est2.update(sched, np.array([0, 0.8, 0.8, 0]), np.tile([-60.0, 0, 10.0], (4, 1)))[1]
    # the schedule's stance takes over, then its lift-off is swing although the foot is loaded: no stall
    est.update(np.ones(4, bool), np.zeros(4), loaded)
    assert list(est.update(~sched, np.array([0.0, 0, 0, 0.0]), loaded)) == [False, True, True, False]


class FailsWithBarriers(TightReference):
    """Reports infeasible while any barrier row is active (to exercise the relaxation)."""

    def __init__(self, start):
        self.start = start

    def solve(self, p):
        if np.any(p.h[self.start :] < 1e5):
            return QPSolution(None, "infeasible", 0.0)
        return super().solve(p)


def test_priority_relaxation_drops_the_last_family_first_and_counts(states):
    st, pm = states
    w = world(terrain=Terrain((Plane(1.0),)))
    barriers = [TerrainClearance(w, "first", role=None), TerrainClearance(w, "second", role=None)]
    f = SafetyFilter(FilterSettings(relaxation="priority"), TightReference(), barriers)
    f.backend = FailsWithBarriers(barriers[0].start)
    state = next(s for s in st if (~s[2].in_stance).any())
    res = f.filter(inputs_for(pm, state, 1.0), state[3])
    assert not res.used_fallback and res.relaxed == ("second", "first")
    assert f.relaxed_ticks == 1 and f.relaxed_by_family == {"second": 1, "first": 1}
    plain = SafetyFilter(FilterSettings(), FailsWithBarriers(barriers[0].start), barriers)
    assert plain.filter(inputs_for(pm, state, 1.0), state[3]).used_fallback  # relaxation none: fallback


def test_terrain_barriers_measure_obstacles_only_by_default(states):
    st, pm = states
    terrain = Terrain((Plane(1.0),))  # no obstacle: no rows (the floor is where a foot lands)
    tc, shin = TerrainClearance(world(terrain=terrain)), LegClearance(world(terrain=terrain), "shin")
    f = SafetyFilter(FilterSettings(), TightReference(), [tc, shin])
    f.build(inputs_for(pm, st[0], 1.0), st[0][3])
    assert np.all(np.isnan(tc.h)) and np.all(np.isnan(shin.h))
    assert np.all(f.problem.h[tc.start : tc.start + 8] == 1e6)


def test_packed_heightfield_distance_equals_the_part():
    from taslel_bench.interfaces import HeightField, rough_heights

    field = HeightField(rough_heights(np.random.default_rng(5), 21, 31, 0.03, 1, 3, 4), centre_x_m=1.5,
                        centre_y_m=0.0, half_x_m=0.75, half_y_m=0.5)  # fmt: skip
    rng = np.random.default_rng(6)
    c = np.column_stack([rng.uniform(0.6, 2.4, 300), rng.uniform(-0.6, 0.6, 300), rng.uniform(-0.04, 0.2, 300)])
    ours = PackedTerrain((field,)).sphere_distance(c, 0.02)
    for a, b in zip(field.sphere_distance_reference(c, 0.02), ours, strict=True):
        finite = np.isfinite(a) if a.ndim == 1 else np.isfinite(a).all(axis=1)
        assert np.array_equal(np.isfinite(a), np.isfinite(b))
        assert np.max(np.abs(a[finite] - b[finite])) < 1e-12


def test_contact_estimate_late_touchdown_stays_swing_until_loaded_or_timeout():
    est = ContactEstimate(ContactEstimateSettings(late_touchdown_max_s=0.003, control_dt_s=0.001))
    swing, stance = np.zeros(4, bool), np.ones(4, bool)
    free, loaded = np.zeros((4, 3)), np.tile([0, 0, 60.0], (4, 1))
    est.update(swing, np.full(4, 0.9), free)  # swing, nothing touched
    assert not est.update(stance, np.zeros(4), free).any()  # scheduled stance, not landed: swing
    assert np.all(est.swing_phase(np.zeros(4)) == 1.0)  # ... at the end of its swing for the barriers
    assert est.update(stance, np.zeros(4), loaded).all()  # loaded: stance
    est.update(swing, np.full(4, 0.2), free)
    flags = [est.update(stance, np.zeros(4), free)[0] for _ in range(5)]
    assert flags == [False, False, False, True, True]  # stance anyway after 3 ticks
    assert est.late_touchdown_ticks == 4 * 1 + 4 * 3


def test_downhill_edge_pyramid_holds_a_vertical_force_on_a_40_deg_log_side_inside_the_true_cone():
    """A surface tilted 40 deg along world x, mu = 1: the vertical force's tangential share is tan 40 = 0.84 of its
    normal one, inside the true cone (1) but outside the world-x pyramid's mu/sqrt 2 = 0.71 along t1; the
    pyramid turned so an edge lies down the slope holds it. Every force the turned rows admit lies inside the
    true cone; on a level plane the turned basis is the paper's."""
    tilt = math.radians(40.0)
    n = np.array([-math.sin(tilt), 0.0, math.cos(tilt)])
    mu_t = 1.0 / math.sqrt(2.0)

    def admits(basis, f):
        t1, t2 = basis(n)
        return f @ n > 0 and abs(f @ t1) <= mu_t * (f @ n) + 1e-12 and abs(f @ t2) <= mu_t * (f @ n) + 1e-12

    up = np.array([0.0, 0.0, 1.0])
    assert not admits(tangent_basis, up) and admits(downhill_edge_basis, up)
    t1, t2 = downhill_edge_basis(n)
    assert abs(t1 @ n) < 1e-12 and abs(t2 @ n) < 1e-12 and abs(t1 @ t2) < 1e-12
    rng = np.random.default_rng(0)
    for f in rng.normal(size=(2000, 3)):
        if admits(downhill_edge_basis, f):
            f_n = f @ n
            assert np.linalg.norm(f - f_n * n) <= 1.0 * f_n + 1e-9  # inside the true cone, mu = 1
    for level in (np.array([0.0, 0.0, 1.0]),):
        assert all(np.allclose(a, b) for a, b in zip(downhill_edge_basis(level), tangent_basis(level), strict=True))


def test_cone_edge_downhill_is_an_option_of_the_terrain_cone():
    f = SafetyFilter(FilterSettings(friction_cone="terrain", cone_edge_downhill=True), TightReference(),
                     terrain=Terrain((Ramp(start_x_m=-1.0, run_m=3.0, angle_deg=10.0),)))
    assert f.friction.basis is downhill_edge_basis
    from taslel_bench.config.settings import filter_settings

    assert compose_cfg(["filter=terrain"]).filter.cone_edge_downhill is True  # the preset turns it
    # the paper's filter does not have it
    assert filter_settings(compose_cfg([]), load_robot("a1")).cone_edge_downhill is False
    with pytest.raises(Exception, match="cone_edge_downhill"):
        from taslel_bench.config.validate import validate
        validate(compose_cfg(["filter=terrain", "filter.cone_edge_downhill=maybe"]))


def test_ablation_study_switches_exactly_the_named_parts_of_the_terrain_filter():
    from studies.terrain_filter_ablation import PARTS_OFF, overrides_for

    every_off = [o for off in PARTS_OFF.values() for o in off]
    assert overrides_for("all") == ["filter=terrain"]
    assert overrides_for("none") == ["filter=terrain", *every_off]
    kept = overrides_for("terrclear+estimate")
    assert "filter.barriers.terrain_clearance=null" not in kept and "filter.stance_source=schedule" not in kept
    assert "filter.friction_cone=pyramid" in kept and "filter.barriers.shin=null" in kept
    swing = overrides_for("legsswing")
    assert "filter.barriers.shin=null" not in swing and "filter.barriers.shin.swing_only=true" in swing
    for bad in ("cone+wings", "legs+legsswing"):
        with pytest.raises(ValueError, match="parts"):
            overrides_for(bad)
    composed = compose_cfg(overrides_for("terrclear+estimate+legsswing"))  # every override exists in the tree
    assert composed.filter.barriers.shin.swing_only and composed.filter.barriers.knee.swing_only
    assert composed.filter.friction_cone == "pyramid" and composed.filter.stance_source == "estimate"


def test_terrain_clearance_max_normal_z_keeps_rows_at_risers_only(states):
    """``max_normal_z`` drops the rows of feet over a top (normal up) and keeps those beside a riser face."""
    st, pm = states
    q, v, gs, u = st[2]
    pm.update(q, v)
    swing = np.flatnonzero(~gs.in_stance)
    assert swing.size
    foot = pm.foot_pos_in_world[swing[0]]
    over_top = Box(centre_m=(foot[0], foot[1], -0.5), half_size_m=(0.3, 0.3, 0.5), role=OBSTACLE)  # top z = 0
    beside = Box(centre_m=(foot[0] + 0.25, foot[1], 0.0), half_size_m=(0.2, 0.3, 0.5), role=OBSTACLE)  # face ahead
    for box, rows_left in ((over_top, False), (beside, True)):
        w = world(terrain=Terrain((Plane(1.0), box)))
        every, riser = TerrainClearance(w), TerrainClearance(w, max_normal_z=0.7)
        f = SafetyFilter(FilterSettings(), TightReference(), [every, riser])
        f.build(inputs_for(pm, st[2], 1.0), u)
        assert np.isfinite(every.h[swing[0]])
        assert np.isfinite(riser.h[swing[0]]) == rows_left
    with pytest.raises(ValueError, match="max_normal_z"):
        TerrainClearance(w, max_normal_z=1.5)


def test_scalar_cross_and_compiled_merge_give_numpys_bits():
    """The tick's replacements of numpy calls give the same bits: cross3 = np.cross; _take_closer = the masks it
    replaced (with and without the upward tolerance)."""
    from taslel_bench.filter.terrain_cone import cross3
    from taslel_bench.terrain.packed import _take_closer

    rng = np.random.default_rng(11)
    for a, b in rng.normal(size=(2000, 2, 3)):
        assert np.array_equal(cross3(a, b), np.cross(a, b))
    for tol in (0.0, 0.005):
        d, dp = rng.uniform(0, 0.05, 24), rng.uniform(0, 0.05, 24)
        normal, n_p = rng.normal(size=(24, 3)), rng.normal(size=(24, 3))
        point, p_p = rng.normal(size=(24, 3)), rng.normal(size=(24, 3))
        closer = (dp < d - tol) | ((dp < d + tol) & (n_p[:, 2] > normal[:, 2])) if tol else dp < d
        want = [x.copy() for x in (d, normal, point)]
        for w, o in zip(want, (dp, n_p, p_p), strict=True):
            w[closer] = o[closer]
        _take_closer(d, normal, point, dp, n_p, p_p, tol)
        assert all(np.array_equal(w, g) for w, g in zip(want, (d, normal, point), strict=True))
        assert 0 < closer.sum() < 24


def test_a_barrier_family_declares_its_rows(tmp_path):
    """The trunk-attitude family has two rows (pitch, roll), not four leg slots: two QP rows, its own trace columns,
    and no part in the per-leg readings."""
    from taslel_bench.filter.barriers.attitude import TrunkAttitude
    from taslel_bench.sim.build import Built

    over = ["filter=terrain",
            "+filter.barriers.attitude={_target_:taslel_bench.filter.barriers.attitude.TrunkAttitude}",
            "duration=0.3", "progress=false"]
    built = Built(compose_cfg(over))
    att = next(b for b in built.filter.barriers if isinstance(b, TrunkAttitude))
    assert att.rows == ("pitch", "roll") and att.n_rows == 2 and not att.per_leg
    labels = built.filter.problem.row_labels
    assert [lbl for lbl in labels if lbl.endswith("_attitude")] == ["pitch_attitude", "roll_attitude"]
    frame = built.episode.run().trace.to_frame()
    assert {"pitch_barrier_attitude_h_m", "roll_barrier_attitude_h_m"} <= set(frame.columns)
    assert not any(c.startswith(("FL_", "FR_", "RL_", "RR_")) and "_attitude_" in c for c in frame.columns)


def test_the_public_api_builds_the_terrain_filter_with_its_terrain():
    """``api.build_safety_filter`` hands the terrain to the filter itself (its per-foot cones read it), not only to
    the barrier families: ``filter=terrain`` builds through the public API."""
    from taslel_bench import api
    from taslel_bench.filter.terrain_cone import TerrainFrictionCone
    from taslel_bench.interfaces import Plane, Terrain

    terrain = Terrain((Plane(0.4),))
    built = api.build_safety_filter(compose_cfg(["filter=terrain"]), terrain=terrain)
    assert isinstance(built.friction, TerrainFrictionCone) and built.friction.terrain is terrain


def test_correction_limits_bound_u_minus_u_nom_per_leg_and_default_to_the_papers_bounds(states):
    """``correction_limit_stance_nm`` / ``_swing_nm`` bound |u - u_nom| on each joint of a stance / swing leg (the
    torque limits still hold); unset, the bounds are the torque limits only (the paper's QP)."""
    st, pm = states
    terrain = Terrain((Plane(1.0), Log(0.25, 0.0, 0.06)))  # a log under the front legs: barrier rows bind
    w = world(terrain=terrain)
    make = lambda s: [TerrainClearance(w, lift_m=0.05), LegClearance(w, "shin")]  # noqa: E731
    paper = SafetyFilter(FilterSettings(), TightReference(), make(None))
    assert np.array_equal(paper.condensed.lb, -paper.torque_limit_nm)
    limited = SafetyFilter(FilterSettings(correction_limit_stance_nm=0.5, correction_limit_swing_nm=2.0),
                           TightReference(), make(None))  # fmt: skip
    moved = 0.0
    for state in st:
        x = inputs_for(pm, state, 1.0)
        free = paper.filter(x, state[3])
        res = limited.filter(x, state[3])
        moved = max(moved, float(np.abs(free.u - state[3]).max()))
        if res.used_fallback:
            assert np.array_equal(res.u, state[3])
            continue
        legs = np.repeat(np.asarray(x.in_stance, bool), 3)
        du = np.abs(res.u - state[3])
        assert np.all(du[legs] <= 0.5 + 1e-6) and np.all(du[~legs] <= 2.0 + 1e-6)
        assert np.all(np.abs(res.u) <= limited.torque_limit_nm + 1e-9)
    assert moved > 2.0  # without the limits the filter moved some joint further
    with pytest.raises(ValueError, match="correction_limit"):
        SafetyFilter(FilterSettings(correction_limit_swing_nm=-1.0), TightReference())


def test_support_min_normal_z_takes_a_stance_toe_on_a_riser_face_out_of_the_contact_rows(states):
    """A stance foot against a steep face (normal n_z below ``support_min_normal_z``) gets no contact rows or cone
    (lambda = 0); on flat ground the option changes nothing (the same QP)."""
    st, pm = states
    state = next(s for s in st if np.asarray(s[2].in_stance).any())
    x = inputs_for(pm, state, 1.0)
    flat = Terrain((Plane(1.0),))
    plain = SafetyFilter(FilterSettings(friction_cone="terrain"), TightReference(), terrain=flat)
    checked = SafetyFilter(FilterSettings(friction_cone="terrain", support_min_normal_z=0.7), TightReference(),
                           terrain=flat)  # fmt: skip
    a, b = plain.build(x, state[3]), checked.build(x, state[3])
    assert np.array_equal(a.A, b.A) and np.array_equal(a.G, b.G) and checked.unsupported_ticks == 0
    leg = int(np.flatnonzero(x.in_stance)[0])
    foot = pm.foot_pos_in_world[leg]
    r = pm.robot.foot_radius_m
    # a riser face 12 mm into the toe (closer than the floor under it by more than the corner tolerance)
    riser = Box(centre_m=(foot[0] + r - 0.012 + 0.2, foot[1], 0.0), half_size_m=(0.2, 0.3, 0.1), role=OBSTACLE)
    steps = Terrain((Plane(1.0), riser))
    f = SafetyFilter(FilterSettings(friction_cone="terrain", support_min_normal_z=0.7), TightReference(),
                     terrain=steps)  # fmt: skip
    res = f.filter(x, state[3])
    assert f.unsupported_ticks == 1 and not res.used_fallback
    assert np.allclose(res.lam.reshape(4, 3)[leg], 0.0, atol=1e-6)
    others = [i for i in np.flatnonzero(x.in_stance) if i != leg]
    assert all(res.lam.reshape(4, 3)[i, 2] > 0.5 for i in others)
    with pytest.raises(ValueError, match="support_min_normal_z"):
        SafetyFilter(FilterSettings(support_min_normal_z=0.7), TightReference())
