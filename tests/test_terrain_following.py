"""The terrain-following nominal (``controller.terrain_following=true``): the paper's trot on flat ground, foot
targets shifted by the ground under each foot elsewhere."""

from __future__ import annotations

import numpy as np
import pytest

from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.control.terrain_following import TerrainFollowingController
from taslel_bench.interfaces import OBSTACLE, Box, Plane, Terrain
from taslel_bench.robot import a1
from taslel_bench.robot.kinematics import leg_fk
from tests.conftest import compose_cfg

LEVEL_POSE = np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0])  # trunk at the origin, level, heading +x
STEP_M = 0.05


def _feet_z(q_des: np.ndarray) -> np.ndarray:
    """Foot-centre z [m] in each hip frame of joint angles ``q_des`` (12,)."""
    return np.array([leg_fk(q_des[3 * i : 3 * i + 3], a1.LEG_SIDE[i])[2] for i in range(4)])


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
    fl = a1.LEGS.index("FL")
    assert follow.ground_ref_m[fl] == pytest.approx(STEP_M, abs=1e-6)  # at mid swing: the step's top
    _q_des_over(follow, times[times >= start + 0.5 * swing_s + 5e-4], LEVEL_POSE)
    assert follow._latched_m[fl] == pytest.approx(STEP_M)  # touched down on the top


def test_terrain_following_is_a_config_switch_refused_unless_boolean():
    from taslel_bench.config.settings import build_controller
    from taslel_bench.config.validate import validate
    from taslel_bench.util.fields import ConfigError

    cfg = compose_cfg(["controller.terrain_following=true"])
    assert isinstance(build_controller(cfg, Terrain((Plane(),))), TerrainFollowingController)
    assert type(build_controller(compose_cfg([]))) is NominalController
    with pytest.raises(ConfigError, match="controller.terrain_following"):
        validate(compose_cfg(["controller.terrain_following=maybe"]))
