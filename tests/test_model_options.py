"""The controller's model options (``model`` group) against a MuJoCo plant perturbed the same way
(``scenarios.perturbed.PerturbedPlant``): same M and h to ~1e-13 when they describe the same physics, a
clear difference when they do not; the default model is bit-identical to the plain URDF model."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from taslel_bench.config.settings import model_options
from taslel_bench.interfaces import PlantPerturbation
from taslel_bench.plant.bridge import StateBridge, quat_wxyz_to_matrix
from taslel_bench.plant.build import compile_plant, robot_spec
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.model import RobotModel
from taslel_bench.robot.model_options import ModelOptions
from taslel_bench.sim.build import Built
from taslel_bench.util.fields import ConfigError
from tests.conftest import compose_cfg
from tests.test_faults import assert_refused, no_episode  # noqa: F401 - fixture
from tests.test_model import random_state, velocity_map

AGREE = 1e-9  # [kg·m², N·m] the bound; measured ~1e-13


def perturbed_plant(**kw) -> mujoco.MjModel:
    spec = robot_spec()
    PlantPerturbation.checked("scenario", **kw).apply(spec)  # the one implementation of the plant edits
    return compile_plant(spec)


def worst_difference(m: mujoco.MjModel, pm: RobotModel, n: int = 8, seed: int = 0) -> tuple[float, float]:
    """max |M_model - M_plant|, max |h_model - h_plant| over ``n`` random states (trunk 2 m up: no contact),
    both in Pinocchio's coordinates. Plant: M from mj_fullM; h = qfrc_bias - qfrc_passive (MuJoCo's passive
    damping force is -d qdot, the model's h carries +d qdot) + M Tdot v (the frame change of the trunk's
    linear velocity, see tests/test_model.py)."""
    d, br, rng = mujoco.MjData(m), StateBridge(m), np.random.default_rng(seed)
    worst_m = worst_h = 0.0
    for _ in range(n):
        q, v = random_state(pm, rng)
        q[2] = 2.0
        br.qpos_mj(q, d.qpos)
        br.qvel_mj(q, v, d.qvel)
        mujoco.mj_forward(m, d)
        pm.update(q, v)
        T = velocity_map(br, q)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        tdot_v = np.zeros(quad.NV)
        tdot_v[:3] = quat_wxyz_to_matrix(d.qpos[3:7]) @ np.cross(v[3:6], v[:3])
        worst_m = max(worst_m, float(np.abs(T.T @ M @ T - pm.M).max()))
        worst_h = max(worst_h, float(np.abs(T.T @ (d.qfrc_bias - d.qfrc_passive + M @ tdot_v) - pm.h).max()))
    return worst_m, worst_h


def test_default_model_is_bit_identical_to_the_plain_urdf_model():
    """Default options (in code, from the default config) give exactly Pinocchio's M and nle of the URDF."""
    ref = pin.buildModelFromUrdf(str(load_robot("a1").urdf_path), pin.JointModelFreeFlyer())
    ref_data = ref.createData()
    models = [RobotModel(), RobotModel(options=ModelOptions()), RobotModel(options=model_options(compose_cfg()))]
    rng = np.random.default_rng(5)
    for _ in range(5):
        q, v = random_state(models[0], rng)
        pin.computeAllTerms(ref, ref_data, q, v)
        M_ref = np.triu(ref_data.M) + np.triu(ref_data.M, 1).T
        for pm in models:
            pm.update(q, v)
            assert np.array_equal(pm.M, M_ref) and np.array_equal(pm.h, ref_data.nle)
    assert all(pm.total_mass_kg == pin.computeTotalMass(ref) for pm in models)


MATCHED = {
    "joint_damping": {"joint_damping": 1.5},
    "joint_damping per joint": {"joint_damping": tuple(np.linspace(0.0, 2.0, 12))},
    "armature": {"armature": 0.01},
    "armature per joint": {"armature": tuple(np.linspace(0.005, 0.05, 12))},
    "trunk_mass_scale": {"trunk_mass_scale": 0.8},
    "trunk_com_shift_m": {"trunk_com_shift_m": (0.02, -0.01, 0.01)},
    "payload": {"payload_mass_kg": 2.0, "payload_pos_m": (0.1, 0.02, 0.05)},
    "all at once": {
        "trunk_mass_scale": 1.3,
        "trunk_com_shift_m": (0.02, 0.0, 0.01),
        "payload_mass_kg": 1.0,
        "payload_pos_m": (-0.1, 0.0, 0.05),
        "joint_damping": 1.0,
        "armature": 0.02,
    },
}


@pytest.mark.parametrize("options", MATCHED.values(), ids=MATCHED.keys())
def test_model_matches_a_plant_perturbed_the_same_way(options):
    m = perturbed_plant(**options)
    pm = RobotModel(options=ModelOptions(**options))
    worst_m, worst_h = worst_difference(m, pm)
    assert worst_m < AGREE and worst_h < AGREE, (worst_m, worst_h)
    assert pm.total_mass_kg == pytest.approx(float(m.body_mass.sum()), abs=1e-12)


MISMATCHED = {  # plant perturbation the nominal model does not know -> (min M difference, min h difference)
    "joint_damping": ({"joint_damping": 1.5}, 0.0, 1.0),  # [N·m] at joint speeds of ~2 rad/s
    "armature": ({"armature": 0.01}, 0.0099, 0.0),
    "trunk_mass_scale": ({"trunk_mass_scale": 0.8}, 1.0, 1.0),  # 1.2 kg less trunk: > 1 kg in M, > 1 N in h
    "payload": ({"payload_mass_kg": 2.0, "payload_pos_m": (0.1, 0.0, 0.05)}, 1.9, 19.0),  # ~2 kg x 9.81
}


@pytest.mark.parametrize(("plant_kw", "dm", "dh"), MISMATCHED.values(), ids=MISMATCHED.keys())
def test_a_mismatched_model_differs_clearly(plant_kw, dm, dh):
    worst_m, worst_h = worst_difference(perturbed_plant(**plant_kw), RobotModel())
    assert worst_m >= dm and worst_h >= dh, (worst_m, worst_h)
    assert worst_m > 1e-3 or worst_h > 1e-3  # many orders above the matched agreement


def test_coulomb_frictionloss_disturbance_against_mujoco():
    """MuJoCo resolves friction loss as a constraint (force in [-F, F] opposing the motion); the model's
    known disturbance F tanh(qdot / v_eps) in h has the same sign and, where MuJoCo's force is saturated,
    the same magnitude (tanh(|qdot| / v_eps) ~ 1 at the random speeds)."""
    F = 0.2  # [N·m]
    m = perturbed_plant(joint_frictionloss=F)
    d, br = mujoco.MjData(m), StateBridge(m)
    pm, nominal = RobotModel(options=ModelOptions(joint_frictionloss=F)), RobotModel()
    rng = np.random.default_rng(3)
    saturated = 0
    for _ in range(10):
        q, v = random_state(pm, rng)
        q[2] = 2.0  # no contact: the only constraint forces are the joints' friction loss
        br.qpos_mj(q, d.qpos)
        br.qvel_mj(q, v, d.qvel)
        mujoco.mj_forward(m, d)
        pm.update(q, v)
        nominal.update(q, v)
        term = (pm.h - nominal.h)[6:]  # [N·m] the friction term the model adds to h (motors must supply it)
        plant_friction = br.joint_vector(d.qfrc_constraint)  # [N·m] force MuJoCo applies to the joints
        assert np.all(np.abs(term) <= F + 1e-12)
        moving = np.abs(v[6:]) > 0.3  # [rad/s] > 6 v_eps: tanh > 0.99999
        assert np.all(np.sign(term[moving]) == np.sign(v[6:][moving]))
        full = moving & (np.abs(plant_friction) > 0.999 * F)
        saturated += int(full.sum())
        np.testing.assert_allclose(term[full], -plant_friction[full], atol=1e-3 * F)
    assert saturated > 50  # most of the 120 joint samples


def test_model_group_reaches_the_episode_and_is_validated(tmp_path, no_episode):  # noqa: F811 - the fixture imported above
    built = Built(
        compose_cfg(
            [
                "model.joint_damping=1.5",
                "model.armature=[0.01,0,0,0,0,0,0,0,0,0,0,0.02]",
                "model.payload_mass_kg=1",
                "filter.enabled=false",
            ]
        )
    )
    pm = built.episode.model
    assert np.allclose(pm.joint_damping, 1.5)
    assert pm.model.armature[6] == 0.01 and pm.model.armature[17] == 0.02
    assert pm.total_mass_kg == pytest.approx(14.741)
    for overrides, field, value in (
        (["model.joint_damping=-1"], "model.joint_damping", "-1"),
        (["model.armature=[0.01,0.02]"], "model.armature", "[0.01, 0.02]"),
        (["model.trunk_mass_scale=0"], "model.trunk_mass_scale", "0"),
        (["model.payload_pos_m=[0,0,9]"], "model.payload_pos_m[2]", "9"),
        (["model.frictionloss_smoothing_radps=0"], "model.frictionloss_smoothing_radps", "0"),
        ([f"model.urdf={tmp_path / 'none.urdf'}"], "model.urdf", "none.urdf"),
        (["+model.joint_stiffness=1"], "model.joint_stiffness", "1"),
        (["+robot.plant_overrides.timestep=0.002"], "robot.plant_overrides.timestep", "0.002"),
    ):
        assert_refused(overrides, tmp_path / field, f"{field}=", value)
    not_a1 = tmp_path / "box.urdf"
    not_a1.write_text(
        '<robot name="box"><link name="trunk"><inertial><mass value="1"/>'
        '<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link></robot>'
    )
    with pytest.raises(ConfigError, match="model.urdf=.*box.urdf.*joint order"):
        Built(compose_cfg([f"model.urdf={not_a1}", "filter.enabled=false"]))
