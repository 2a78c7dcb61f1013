"""Every shipped robot: plant (MuJoCo) and controller's model (Pinocchio) from one URDF agree; the leg kinematics
built from the description agree with Pinocchio; a robot added from a test module needs no core edit."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.build import build_plant
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import ROBOT_CONFIG_DIR, describe_robot, load_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.robot.model import RobotModel
from taslel_bench.util.fields import ConfigError
from tests.test_model import plant_model_errors

SHIPPED = ("a1", "go1", "anymal_c", "solo12")
TOL = 1e-10


@pytest.fixture(scope="module", params=SHIPPED)
def robot_setup(request):
    robot = load_robot(request.param)
    m = build_plant(robot=robot)
    return robot, m, mujoco.MjData(m), StateBridge(m), RobotModel(robot)


def _random_state(robot, pm: RobotModel, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    q = pin.randomConfiguration(pm.model, -np.ones(quad.NQ), np.ones(quad.NQ))
    q[7:] = rng.uniform(-0.8, 0.8, 12)
    for leg, g in enumerate(robot.legs):  # knees bent the robot's way
        q[7 + 3 * leg + 2] = g.knee_sign * g.axis_signs[2] * rng.uniform(1.0, 2.4)
    return q, rng.normal(0.0, 2.0, quad.NV)


def test_shipped_robots_are_the_conf_files():
    assert sorted(p.stem for p in ROBOT_CONFIG_DIR.glob("*.yaml")) == sorted(SHIPPED)


def test_plant_and_model_agree(robot_setup):
    """Mass matrix, bias forces, foot-sphere centres and their Jacobians at random states, to 1e-10."""
    robot, m, d, br, pm = robot_setup
    rng = np.random.default_rng(0)
    worst = {"M": 0.0, "h": 0.0, "pos": 0.0, "jac": 0.0}
    for _ in range(10):
        q, v = _random_state(robot, pm, rng)
        br.qpos_mj(q, d.qpos)
        br.qvel_mj(q, v, d.qvel)
        mujoco.mj_forward(m, d)
        pm.update(q, v)
        worst = {k: max(worst[k], e) for k, e in plant_model_errors(m, d, br, pm, q, v).items()}
    assert max(worst.values()) < TOL, (robot.name, worst)
    # the same joint losses in the plant (MuJoCo reads the URDF's <dynamics> into damping and frictionloss)
    assert np.array_equal(br.joint_vector(m.dof_damping), pm.joint_damping)
    assert np.array_equal(br.joint_vector(m.dof_frictionloss), pm.joint_frictionloss)
    assert pm.total_mass_kg == pytest.approx(float(m.body_mass.sum()), abs=1e-9)


def test_plant_limits_and_names(robot_setup):
    robot, m, _, br, _ = robot_setup
    assert np.allclose(m.actuator_ctrlrange[br.actuator_ids, 1], robot.torque_limit_nm, atol=0)
    for foot in quad.FOOT_FRAMES:
        gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, foot)
        assert m.geom_type[gid] == mujoco.mjtGeom.mjGEOM_SPHERE
        assert m.geom_size[gid, 0] == pytest.approx(robot.foot_radius_m)


def test_leg_kinematics_match_pinocchio(robot_setup):
    """Foot centres from the description's chain (hip frame + hip position) equal Pinocchio's at random joint
    angles, and the inverse returns angles whose forward image is the target."""
    robot, _, _, _, pm = robot_setup
    kin = LegKinematics(robot)
    rng = np.random.default_rng(1)
    worst_fk = worst_ik = 0.0
    for _ in range(10):
        q, _ = _random_state(robot, pm, rng)
        q[:7] = [0, 0, 0, 0, 0, 0, 1]
        pm.update(q, np.zeros(quad.NV))
        for leg in range(quad.N_LEGS):
            q_leg = q[7 + 3 * leg: 10 + 3 * leg]
            foot = kin.leg_fk(leg, q_leg)
            worst_fk = max(worst_fk, np.abs(foot + robot.hip_positions_in_trunk[leg] - pm.foot_pos_in_world[leg]).max())
            worst_ik = max(worst_ik, np.abs(kin.leg_fk(leg, kin.leg_ik(leg, foot)) - foot).max())
    assert worst_fk < TOL and worst_ik < 1e-9, (robot.name, worst_fk, worst_ik)


def test_a_robot_added_from_a_yaml_file_needs_no_core_edit(tmp_path: Path):
    """Another example-robot-data quadruped (the Go2) as a config node written here: described, planted and
    modelled by the core as it is."""
    node = {**_yaml("go1"), "name": "go2", "urdf": "example-robot-data:robots/go2_description/urdf/go2.urdf",
            "trunk_link": "base", "foot_radius_m": 0.022, "torque_limit_nm": None}
    robot = describe_robot(node)
    m = build_plant(robot=robot)
    pm = RobotModel(robot)
    assert pm.total_mass_kg == pytest.approx(float(m.body_mass.sum()), abs=1e-9)
    assert robot.leg_length_m > 0.3


def test_bad_robot_values_name_the_field():
    node = _yaml("a1")
    with pytest.raises(ConfigError, match=r"robot\.legs"):
        describe_robot({**node, "legs": ["FL", "FR"]})
    with pytest.raises(ConfigError, match=r"robot\.joints: .* has no joint"):
        describe_robot({**node, "joints": "{leg}_{joint}_jnt"})
    with pytest.raises(ConfigError, match=r"robot\.torque_limit_nm"):
        describe_robot({**node, "torque_limit_nm": -1})
    with pytest.raises(ConfigError, match="robot=.nope.: no .*shipped robots: a1"):
        load_robot("nope")


def _yaml(name: str) -> dict:
    from omegaconf import OmegaConf

    node = OmegaConf.to_container(OmegaConf.load(ROBOT_CONFIG_DIR / f"{name}.yaml"))
    node.pop("defaults", None)
    return node


def test_the_trot_scaled_to_the_a1_is_the_tuned_trot():
    """The trot's values from the robot (controller.scaling's defaults) are the A1's tuned values exactly, and
    follow each robot's mass and leg length."""
    from taslel_bench.api import build_controller
    from tests.conftest import compose_cfg

    ctl = build_controller(compose_cfg([]))
    p = ctl.gait.p
    assert (p.speed_mps, p.swing_height_m, p.stand_height_m, ctl.gains.kp, ctl.gains.kd) == (
        0.4,
        0.06,
        0.27,
        100.0,
        3.0,
    )
    heavy = build_controller(compose_cfg(["robot=anymal_c"]))
    assert heavy.gains.kp > 500 and heavy.gait.p.speed_mps > 0.45 and heavy.robot.name == "anymal_c"
