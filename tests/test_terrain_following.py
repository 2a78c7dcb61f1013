"""The terrain-following nominal (``controller.terrain_following=true``): the paper's trot on flat ground, foot
targets shifted by the ground under each foot elsewhere."""

from __future__ import annotations

import numpy as np
import pytest

from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.control.terrain_following import TerrainFollowingController
from taslel_bench.interfaces import OBSTACLE, Box, Plane, Terrain
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.kinematics import LegKinematics
from tests.conftest import compose_cfg

KIN = LegKinematics(load_robot("a1"))

LEVEL_POSE = np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0])  # trunk at the origin, level, heading +x
STEP_M = 0.05


def _feet_z(q_des: np.ndarray) -> np.ndarray:
    """Foot-centre z [m] in each hip frame of joint angles ``q_des`` (12,)."""
    return np.array([KIN.leg_fk(i, q_des[3 * i : 3 * i + 3])[2] for i in range(4)])


def _controllers(terrain: Terrain) -> tuple[NominalController, TerrainFollowingController]:
    return (NominalController(GaitParams(), PDGains()),
            TerrainFollowingController(GaitParams(), PDGains(), terrain=terrain))


def _q_des_over(ctl: NominalController, times: np.ndarray, pose: np.ndarray) -> np.ndarray:
    q, qd = np.zeros(12), np.zeros(12)
    out = []
    for t in times:
        ctl.compute(float(t), q, qd, pose)
        out.append(ctl.q_des.copy())
    return np.array(out)


def test_on_flat_ground_the_terrain_following_trot_is_the_papers():
    flat, follow = _controllers(Terrain((Plane(),)))
    times = np.arange(0.0, 2.0, 1e-3)
    np.testing.assert_allclose(_q_des_over(follow, times, LEVEL_POSE), _q_des_over(flat, times, LEVEL_POSE),
                               atol=1e-12)


def test_front_feet_on_a_step_are_planned_higher_and_the_rear_feet_lower():
    """A 5 cm box from x = 0.1 m: the front feet (hips at x = 0.18 m) stand on it, the rear ones on the floor.
    Standing, each foot's target moves by its ground height minus the mean of the four: +2.5 / -2.5 cm."""
    box = Box(centre_m=(1.1, 0.0, STEP_M / 2), half_size_m=(1.0, 1.0, STEP_M / 2), friction=1.0, role=OBSTACLE)
    flat, follow = _controllers(Terrain((Plane(), box)))
    t = 0.1  # standing
    z_flat = _feet_z(_q_des_over(flat, np.array([t]), LEVEL_POSE)[0])
    z_follow = _feet_z(_q_des_over(follow, np.array([t]), LEVEL_POSE)[0])
    np.testing.assert_allclose(z_follow - z_flat, [STEP_M / 2, STEP_M / 2, -STEP_M / 2, -STEP_M / 2], atol=1e-9)


def test_a_swing_toward_a_step_rises_to_its_top_by_mid_swing_and_lands_on_it():
    """The box's riser is at x = 0.2 m, between the front feet's lift-off and touchdown points."""
    box = Box(centre_m=(1.2, 0.0, STEP_M / 2), half_size_m=(1.0, 1.0, STEP_M / 2), friction=1.0, role=OBSTACLE)
    _, follow = _controllers(Terrain((Plane(), box)))
    stand = follow.stand_duration_s
    swing_s = GaitParams().period_s * (1 - GaitParams().duty)
    start = stand + 0.5 * GaitParams().period_s  # FR and RL swing first (offset 0.5), FL at this time
    times = np.arange(0.0, start + swing_s + 1e-3, 1e-3)
    _q_des_over(follow, times[times < start + 0.5 * swing_s + 5e-4], LEVEL_POSE)
    fl = quad.LEGS.index("FL")
    assert follow.ground_ref_m[fl] == pytest.approx(STEP_M, abs=1e-6)  # at mid swing: the step's top
    _q_des_over(follow, times[times >= start + 0.5 * swing_s + 5e-4], LEVEL_POSE)
    assert follow._latched_m[fl] == pytest.approx(STEP_M)  # touched down on the top


def test_terrain_following_is_a_config_switch_refused_unless_boolean():
    from taslel_bench.api import build_controller
    from taslel_bench.cli_checks import CliError, check_overrides

    cfg = compose_cfg(["controller.terrain_following=true"])
    assert isinstance(build_controller(cfg, Terrain((Plane(),))), TerrainFollowingController)
    assert type(build_controller(compose_cfg([]))) is NominalController
    with pytest.raises(CliError, match="controller.terrain_following='maybe': must be true or false"):
        check_overrides(["controller.terrain_following=maybe"])


def test_touchdown_aim_ends_the_swing_above_the_ground_and_descends_early_in_the_stance():
    """``touchdown_height_m``: a leg's foot target (hip frame) is that much above the plain terrain-following
    target at the swing's end, back on it :data:`TOUCHDOWN_DESCENT_S` into the stance, unchanged in the first
    half of the swing, in the stance the walk starts in, and moves by no more than the eased descent's steepest step
    per tick (continuous)."""
    from taslel_bench.control.terrain_following import TOUCHDOWN_DESCENT_S

    aim = 0.02  # [m]
    plain = TerrainFollowingController(GaitParams(), PDGains(), terrain=Terrain((Plane(),)))
    aimed = TerrainFollowingController(GaitParams(), PDGains(), terrain=Terrain((Plane(),)), touchdown_height_m=aim)
    p = GaitParams()
    stand = plain.stand_duration_s
    times = np.arange(0.0, stand + 2 * p.period_s, 1e-3)
    dz = np.array([_feet_z(q) for q in _q_des_over(aimed, times, LEVEL_POSE)]) - np.array(
        [_feet_z(q) for q in _q_des_over(plain, times, LEVEL_POSE)])  # (ticks, 4) [m]
    assert np.abs(dz[times < stand]).max() < 1e-12  # standing: no aim
    steepest = 0.5 * np.pi * aim / TOUCHDOWN_DESCENT_S * 1e-3  # [m per tick] the eased descent's largest step
    assert np.abs(np.diff(dz, axis=0)).max() < 1.01 * steepest
    fl = quad.LEGS.index("FL")  # offset 0: stance first, swing from phase duty
    swing_start = stand + p.duty * p.period_s
    touchdown = stand + p.period_s
    first_stance = times < swing_start - 1e-6
    assert np.abs(dz[first_stance, fl]).max() < 1e-12  # the stance the walk starts in follows no swing
    early_swing = (times > swing_start) & (times < swing_start + 0.5 * (touchdown - swing_start) - 1e-6)
    assert np.abs(dz[early_swing, fl]).max() < 1e-12
    k_td = int(np.argmin(np.abs(times - touchdown)))
    assert dz[k_td - 1, fl] == pytest.approx(aim, abs=5e-4)  # the swing ends ~aim above the ground
    after = (times > touchdown + TOUCHDOWN_DESCENT_S + 1e-6) & (times < touchdown + 0.1)
    assert np.abs(dz[after, fl]).max() < 1e-12  # back on the ground once the descent is over


@pytest.mark.parametrize("overrides, match", [
    (["controller.touchdown_height=0.01"], "controller.touchdown_height.*terrain_following=true"),
    (["controller.terrain_following=true", "controller.touchdown_height=0.05"], r"controller.touchdown_height=0.05"),
    (["controller.terrain_following=true", "controller.touchdown_height=-0.01"], r"controller.touchdown_height=-0.01"),
])
def test_touchdown_aim_is_refused_without_terrain_following_or_out_of_range(overrides, match):
    from taslel_bench.config.validate import validate
    from taslel_bench.util.fields import ConfigError

    with pytest.raises(ConfigError, match=match):
        validate(compose_cfg(overrides))
    validate(compose_cfg(["controller.terrain_following=true", "controller.touchdown_height=0.02"]))
