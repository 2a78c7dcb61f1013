"""The filter options that read the force the nominal torques would produce (``filter.release_lifted_feet``,
``filter.cone_edge_along_nominal``), checked against an independent solve of the equality rows and against the
contact physics they stand for: a foot the nominal pulls off the ground (negative normal force under the stance
model) accelerates away from the ground once it is let go; a pyramid turned along the nominal's force holds it
exactly when the true cone does."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from taslel_bench.filter.layout import TickInputs
from taslel_bench.filter.safety_filter import FilterSettings, SafetyFilter
from taslel_bench.filter.terrain_cone import EDGE_MIN_TANGENTIAL_N, nominal_edge_basis, tangent_basis
from taslel_bench.interfaces import Plane, Terrain
from tests.test_filter import TightReference, inputs_for, unfiltered_prediction, walking_states

UP = np.array([0.0, 0.0, 1.0])
FLAT = Terrain((Plane(1.0),))


@pytest.fixture(scope="module")
def states():
    return walking_states(6)


def all_stance(x: TickInputs) -> TickInputs:
    return replace(x, in_stance=np.ones(4, bool))


def test_lifted_feet_are_those_the_nominal_pulls_off_the_ground(states):
    """The candidates are exactly the stance feet whose normal force, from numpy's own solve of the equality rows
    under u_nom, is below lambda_min; of those, the feet released are the ones that, let go, accelerate away
    from the ground (J vdot + J̇v from numpy's solve with them swing); the QP has no contact force on them."""
    st, pm = states
    rng = np.random.default_rng(0)
    seen = {"released": 0, "kept_sliding": 0, "stance": 0}
    for state in st:
        for _ in range(8):
            x = all_stance(inputs_for(pm, state, 1.0))
            u_nom = state[3] + rng.normal(0.0, 6.0, 12)
            f = SafetyFilter(FilterSettings(release_lifted_feet=True, friction_cone="terrain"), TightReference(),
                             terrain=FLAT)
            f._write_equalities(f.problem, x)
            sticking = unfiltered_prediction(f, u_nom)[-12:].reshape(4, 3)
            lifted = f.lifted_feet(f.problem, x, u_nom)
            assert np.array_equal(lifted, sticking[:, 2] < f.settings.lambda_min_n)
            f._write_equalities(f.problem, replace(x, in_stance=~lifted))
            vdot = unfiltered_prediction(f, u_nom)[:18]
            away = np.array([(pm.foot_jac_in_world[i] @ vdot + pm.foot_jdotv_in_world[i])[2] > 0.0 for i in range(4)])
            expected = lifted & away
            res = f.filter(x, u_nom)
            assert res.status == "solved"
            lam = res.lam.reshape(4, 3)
            assert np.all(lam[expected] == 0.0) and np.all(lam[~expected, 2] >= f.settings.lambda_min_n - 1e-6)
            assert f.released_ticks == int(expected.any())
            seen["released"] += int(expected.sum())
            seen["kept_sliding"] += int((lifted & ~away).sum())
            seen["stance"] += int((~lifted).sum())
    assert all(v > 0 for v in seen.values()), seen  # the draws exercise every branch


def test_pyramid_along_the_nominal_holds_it_exactly_when_the_true_cone_does():
    rng = np.random.default_rng(2)
    mu = 0.8
    mu_t = mu / np.sqrt(2.0)
    for _ in range(500):
        n = rng.normal(size=3) * np.array([0.3, 0.3, 1.0]) + UP
        n /= np.linalg.norm(n)
        force = rng.normal(size=3) * 20.0 + 30.0 * n
        t1, t2 = nominal_edge_basis(n, force, tangent_basis)
        assert abs(t1 @ n) < 1e-12 and abs(t2 @ n) < 1e-12 and abs(t1 @ t2) < 1e-12
        f_n = force @ n
        tangential = np.linalg.norm(force - f_n * n)
        if tangential < EDGE_MIN_TANGENTIAL_N:
            continue
        in_pyramid = f_n > 0 and abs(force @ t1) <= mu_t * f_n + 1e-9 and abs(force @ t2) <= mu_t * f_n + 1e-9
        in_cone = f_n > 0 and tangential <= mu * f_n
        if abs(tangential - mu * f_n) > 1e-6:  # off the boundary: the two agree
            assert in_pyramid == in_cone
    small = UP * 10.0 + np.array([0.1, 0.2, 0.0])  # below the threshold: the fallback basis
    assert all(np.array_equal(a, b) for a, b in zip(nominal_edge_basis(UP, small, tangent_basis), tangent_basis(UP),
                                                     strict=True))


def test_the_options_are_the_terrain_cones_and_off_by_default():
    from taslel_bench.config.compose import compose
    from taslel_bench.config.settings import filter_settings
    from taslel_bench.robot.description import load_robot

    default = filter_settings(compose([]), load_robot("a1"))
    assert not default.release_lifted_feet and not default.cone_edge_along_nominal  # the paper's filter
    with pytest.raises(ValueError, match="cone_edge_along_nominal"):
        SafetyFilter(FilterSettings(cone_edge_along_nominal=True), TightReference())


def test_the_preset_turns_both_on_and_validation_names_a_wrong_pairing():
    from taslel_bench.config.compose import compose
    from taslel_bench.config.validate import validate
    from taslel_bench.util.fields import ConfigError

    cfg = compose(["filter=terrain_release"])
    validate(cfg)
    assert cfg.filter.release_lifted_feet and cfg.filter.cone_edge_along_nominal
    assert cfg.filter.friction_cone == "terrain" and cfg.filter.stance_source == "estimate"  # the rest is terrain's
    # swing rows only against surfaces steeper than 45 deg: the trip rule's walkable bound
    assert cfg.filter.barriers.terrain_clearance.max_normal_z == pytest.approx(np.cos(np.radians(45.0)), abs=1e-3)
    with pytest.raises(ConfigError, match="filter.cone_edge_along_nominal.*friction_cone=pyramid"):
        validate(compose(["filter.cone_edge_along_nominal=true"]))


def test_with_the_preset_a_shipped_policy_walks_on_flat_ground_barely_touched():
    """The learned policy with ``filter=terrain_release`` on flat ground, 3 s: no fall, mean intervention under
    1 N·m, feet let go on some ticks (without the release the terrain filter holds lifting feet down and the
    policy falls: docs/decisions/filter-terrain.md)."""
    from taslel_bench.config.compose import compose
    from taslel_bench.sim.build import Built

    cfg = compose(["controller=policy", "policy=a1_walk", "filter=terrain_release", "duration=3", "progress=false"])
    built = Built(cfg)
    result = built.episode.run()
    assert result.status == "ok" and not result.fell
    trace = result.traced()
    n = trace.n
    intervention = np.linalg.norm(trace.u[:n] - trace.u_nom[:n], axis=1)  # [N·m] as the summary's
    assert intervention.mean() < 1.0, intervention.mean()
    assert built.filter.released_ticks > 0


@pytest.mark.parametrize("ratio_max", [None, 0.5])
def test_the_stance_limit_lifts_only_for_the_legs_whose_nominal_force_would_slide(states, ratio_max):
    """``correction_limit_stance_unless_sliding``: a stance leg keeps the nominal's torques unless numpy's own
    solve of the equality rows under u_nom puts its foot's force outside the true cone (or below lambda_min);
    the legs it marks are the ones the filter may move, and on mu = 0.3 it moves some of them. With
    ``sliding_ratio_max`` only forces between the cone and that ratio of tangential to normal mark a leg; a foot
    beyond it (or with a normal part below lambda_min) keeps its leg's nominal torques and gets no planned force;
    0.5 on mu = 0.3 so that both kinds occur in these states."""
    st, pm = states
    mu = 0.3
    settings = FilterSettings(friction_cone="terrain", cone_edge_along_nominal=True, correction_limit_stance_nm=0.0,
                              correction_limit_stance_unless_sliding=True,
                              sliding_ratio_max=math.inf if ratio_max is None else ratio_max)
    moved, kept, beyond_ratio = 0, 0, 0
    for state in st:
        x = inputs_for(pm, state, mu)
        f = SafetyFilter(settings, TightReference(), terrain=Terrain((Plane(mu),)))
        f._write_equalities(f.problem, x)
        force = unfiltered_prediction(f, state[3])[-12:].reshape(4, 3)  # on the robot, world axes
        tangential, normal = np.linalg.norm(force[:, :2], axis=1), force[:, 2]
        stance = np.asarray(x.in_stance, bool)
        if ratio_max is None:
            sliding = stance & ((normal < f.settings.lambda_min_n) | (tangential > mu * normal))
        else:
            over = stance & ((normal < f.settings.lambda_min_n) | (tangential > ratio_max * normal))
            sliding = stance & ~over & (tangential > mu * normal)
            beyond_ratio += int(over.sum())
        res = f.filter(x, state[3])
        assert res.status == "solved"
        du = np.abs(res.u - state[3]).reshape(4, 3).max(axis=1)
        fixed = stance & ~sliding
        assert np.all(du[fixed] <= 1e-6), (du, sliding)
        if ratio_max is not None:  # the feet beyond the ratio are out of the contact model: no force planned
            assert np.all(res.lam.reshape(4, 3)[over] == 0.0)
        moved += int((du[sliding] > 0.1).sum())
        kept += int(fixed.sum())
    assert moved > 0 and kept > 0  # both branches seen
    assert ratio_max is None or beyond_ratio > 0  # and legs kept because their force is beyond the ratio


def test_the_guarded_preset_is_release_with_bounded_corrections_lifted_for_sliding_feet():
    from taslel_bench.config.compose import compose
    from taslel_bench.config.settings import filter_settings
    from taslel_bench.config.validate import validate
    from taslel_bench.robot.description import load_robot

    cfg = compose(["filter=terrain_guarded"])
    validate(cfg)
    release = compose(["filter=terrain_release"]).filter
    for key in ("release_lifted_feet", "cone_edge_along_nominal", "friction_cone", "stance_source"):
        assert cfg.filter[key] == release[key]  # the rest is terrain_release's
    s = filter_settings(cfg, load_robot("a1"))
    assert s.correction_limit_stance_nm == 0.0 and s.correction_limit_swing_nm == 1.0
    assert s.correction_limit_stance_unless_sliding and s.sliding_ratio_max == 2.0
    assert not filter_settings(compose([]), load_robot("a1")).correction_limit_stance_unless_sliding  # the paper's
