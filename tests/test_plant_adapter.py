"""Plant adapters (``robot.plant_mjcf`` with ``robot.plant_names`` / ``robot.plant_overrides``) and the
plant-vs-model report, on MJCF files generated from the harness's own plant spec (no third-party files):
renamed elements, position servos, the file's own floor, joint losses in the file."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from taslel_bench.config.settings import plant_options
from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.interfaces import PlantPerturbation
from taslel_bench.plant.adapter import read_record
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.build import build_plant, compile_plant, robot_spec
from taslel_bench.plant.comparison import plant_vs_model
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.model import RobotModel
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from taslel_bench.terrain.geoms import TERRAIN_PRIORITY
from taslel_bench.util.fields import ConfigError
from tests.conftest import compose_cfg

MENAGERIE_LIKE = [  # Menagerie-style names as robot.plant_names overrides (Hydra: quote a {pattern})
    "robot.plant_names.joints='{leg}_{joint}'",
    "robot.plant_names.actuators='{leg}_{joint}_servo'",
    "robot.plant_names.feet='{leg}'",
    "robot.plant_names.trunk=torso",
]
STAND = NominalController(GaitParams(), PDGains()).stand_configuration()
A1 = load_robot("a1")


def third_party_a1(
    path: Path,
    *,
    servos: bool = True,
    floor: bool = True,
    losses: bool = True,
    drop_actuator: str | None = None,
) -> Path:
    """An A1 MJCF as another project would ship it: the harness's plant with its sites, sensors and floor
    removed, elements renamed (joints ``FL_hip``, actuators ``FL_hip_servo``, feet ``FL``, trunk ``torso``),
    optionally position servos (kp 60, kv 2), a plane ``ground`` of its own (priority 0, friction 0.8) and
    joint losses (damping 1.5, armature 0.01, frictionloss 0.2); a joint sensor refers to a renamed joint."""
    spec = robot_spec()
    for element in list(spec.sensors) + list(spec.sites):
        spec.delete(element)
    for act in spec.actuators:
        leg, part = act.name.split("_")[:2]
        act.target, act.name = f"{leg}_{part}", f"{leg}_{part}_servo"
        if servos:
            act.set_to_position(kp=60.0, kv=2.0)
            act.ctrlrange = [-1.5, 1.5]  # [rad] position targets
    for j in spec.joints:
        if j.name in quad.JOINT_NAMES:
            j.name = "_".join(j.name.split("_")[:2])
            if losses:
                j.damping, j.armature, j.frictionloss = [1.5, 0.0, 0.0], 0.01, 0.2
    for foot in quad.FOOT_FRAMES:
        spec.geom(foot).name = foot.split("_")[0]
    spec.body(quad.TRUNK_BODY).name = "torso"
    ground = spec.geom("floor")
    if floor:
        ground.name, ground.priority, ground.friction[0] = "ground", 0, 0.8
        ground.contype = ground.conaffinity = 1
    else:
        spec.delete(ground)
    if drop_actuator:
        spec.delete(spec.actuator(drop_actuator))
    spec.add_sensor(
        name="fl_hip_angle",
        type=mujoco.mjtSensor.mjSENS_JOINTPOS,
        objtype=mujoco.mjtObj.mjOBJ_JOINT,
        objname="FL_hip",
    )
    path.write_text(spec.to_xml())
    return path


def build(xml: Path, extra: list[str] | None = None) -> Built:
    return Built(
        compose_cfg([f"robot.plant_mjcf={xml}", *MENAGERIE_LIKE, "filter.enabled=false", *(extra or [])])
    )


def test_renamed_servo_plant_with_its_own_floor_runs(tmp_path):
    xml = third_party_a1(tmp_path / "a1_other.xml")
    summary = run(
        compose_cfg(
            [
                f"robot.plant_mjcf={xml}",
                *MENAGERIE_LIKE,
                "duration=0.3",
                "progress=false",
                "record.mcap=false",
                "scenario.friction=0.6",
            ]
        ),
        tmp_path / "run",
    )
    # it ran to its end; the file's joint losses (damping 1.5, armature 0.01, frictionloss 0.2) are not in
    # the controller's model, and the model error (the residual alarm) says so
    assert summary["status"] == "ok" and not summary["fell"]  # the filter's guarantee held: no check degraded it
    assert "residual_alarm_rate" in summary["model_error_reasons"] and summary["residual_joint_nm_rms"] > 2.0
    built = build(xml, ["scenario.friction=0.6"])
    m = built.mj_model
    # the file's floor is the floor (no second plane), with the scenario's friction on every foot contact
    planes = [g for g in range(m.ngeom) if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE]
    assert [m.geom(g).name for g in planes] == ["floor"]
    assert built.friction_checked and all(mu == 0.6 for _, mu, _ in built.friction_checked)
    # servos became torque motors: ctrl is joint torque [N·m] within the URDF effort limit
    assert np.all(m.actuator_biastype == mujoco.mjtBias.mjBIAS_NONE)
    assert np.all(m.actuator_gainprm[:, 0] == 1.0) and np.allclose(m.actuator_ctrlrange, [[-33.5, 33.5]] * 12)
    record = read_record(m)
    assert len(record["actuators_converted"]) == 12 and record["actuators_converted"][0] == [
        "FL_hip_joint",
        "servo kp=60 kv=2 -> motor +-33.5 N·m",
    ]
    assert record["renamed"]["joints"]["FL_hip_joint"] == "FL_hip" and record["renamed"]["floor"] == "ground"
    assert (
        mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "fl_hip_angle") >= 0
    )  # reference followed the rename


def test_bridge_maps_the_renamed_plant_like_the_default_one(tmp_path):
    """Same Pinocchio state in both plants -> same foot positions and the same state read back."""
    adapted = build(third_party_a1(tmp_path / "a1.xml", losses=False)).mj_model
    default = build_plant()
    rng = np.random.default_rng(0)
    for m in (adapted, default):
        m.opt.gravity[:] = 0.0
    for _ in range(3):
        q = np.concatenate([[0.1, -0.2, 0.4], [0.1, 0.0, 0.0, 0.995], rng.uniform(-0.6, 0.6, 12)])
        q[3:7] /= np.linalg.norm(q[3:7])
        v = rng.normal(0.0, 1.0, quad.NV)
        feet, states = [], []
        for m in (adapted, default):
            d, br = mujoco.MjData(m), StateBridge(m)
            br.qpos_mj(q, d.qpos)
            br.qvel_mj(q, v, d.qvel)
            mujoco.mj_forward(m, d)
            feet.append(
                d.geom_xpos[[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f) for f in quad.FOOT_FRAMES]]
            )
            states.append(np.concatenate([br.q_pin(d.qpos), br.v_pin(d.qpos, d.qvel)]))
        np.testing.assert_allclose(feet[0], feet[1], atol=1e-12)
        np.testing.assert_allclose(states[0], np.concatenate([q, v]), atol=1e-12)
        np.testing.assert_allclose(states[1], states[0], atol=1e-12)


def test_missing_names_are_reported_by_kind(tmp_path):
    xml = third_party_a1(tmp_path / "a1.xml")
    with pytest.raises(ConfigError) as err:  # no mapping: every kind is missing, each named
        Built(compose_cfg([f"robot.plant_mjcf={xml}", "filter.enabled=false"]))
    message = str(err.value)
    assert message.startswith(f"robot.plant_mjcf={str(xml)!r} does not fit the controller")
    for line in ("joints: no joint FL_hip_joint", "feet: no sphere geom FL_foot", "trunk: no body 'trunk'"):
        assert line in message, message
    assert "joints in the file: FL_calf, FL_hip" in message and "sphere geoms in the file: FL, FR" in message
    # joints mapped, actuators found by the joint they drive; only the feet are missing
    with pytest.raises(ConfigError, match=r"feet: no sphere geom FL_foot \(as 'FL_toe'\)") as err:
        build(xml, ["robot.plant_names.feet='{leg}_toe'"])
    assert "joints:" not in str(err.value) and "actuators:" not in str(err.value)
    # an actuator missing for one joint, by name and by target
    dropped = third_party_a1(tmp_path / "dropped.xml", drop_actuator="RR_calf_servo")
    with pytest.raises(ConfigError, match=r"actuators: none for RR_calf_joint \(as 'RR_calf_servo'\)"):
        build(dropped)
    with pytest.raises(ConfigError, match=r"actuators: none for RR_calf_joint \(joint 'RR_calf'\)"):
        build(dropped, ["robot.plant_names.actuators=null"])


def test_names_without_a_plant_file_and_bad_patterns_are_refused():
    with pytest.raises(
        ConfigError, match=r"robot.plant_names.feet='\{leg\}': is only used with robot.plant_mjcf"
    ):
        Built(compose_cfg(["robot.plant_names.feet='{leg}'"]))
    with pytest.raises(ConfigError, match=r"robot.plant_names.joints='\{leg\}': a pattern must give 12"):
        Built(compose_cfg(["robot.plant_mjcf=x.xml", "robot.plant_names.joints='{leg}'"]))
    with pytest.raises(ConfigError, match=r"robot.plant_overrides.integrator='RK5': valid: Euler, RK4"):
        Built(compose_cfg(["robot.plant_overrides.integrator=RK5"]))
    with pytest.raises(ConfigError, match=r"robot.plant_overrides.contact_solref\[0\]=-0.02"):
        Built(compose_cfg(["robot.plant_overrides.contact_solref=[-0.02,1]"]))


def test_no_floor_in_the_file_gets_the_harness_floor(tmp_path):
    m = build(third_party_a1(tmp_path / "a1.xml", floor=False)).mj_model
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert floor >= 0 and m.geom_priority[floor] == TERRAIN_PRIORITY
    assert "added" in read_record(m)["floor"]


def test_overrides_are_applied_and_reported(tmp_path):
    overrides = [
        "robot.plant_overrides.integrator=Euler",
        "robot.plant_overrides.cone=pyramidal",
        "robot.plant_overrides.noslip_iterations=3",
        "robot.plant_overrides.contact_solref=[0.01,1.2]",
        "robot.plant_overrides.contact_solimp=[0.8,0.9,0.002,0.5,2]",
        "robot.plant_overrides.foot_margin_m=0.001",
    ]
    built = build(third_party_a1(tmp_path / "a1.xml"), overrides)
    m = built.mj_model
    assert (
        m.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER and m.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    )
    assert m.opt.noslip_iterations == 3
    report = plant_vs_model(m, built.episode.model, STAND)
    assert report["plant_integrator"] == "euler" and report["plant_cone"] == "pyramidal"
    assert (
        report["plant_contact_solref"] == "0.01 1.2"
        and report["plant_contact_solimp"] == "0.8 0.9 0.002 0.5 2"
    )
    assert report["plant_foot_margin_m"] == "0.001" and report["plant_contact_feet_at_stand"] == 4
    for text in (
        "integrator: mjINT_IMPLICITFAST -> mjINT_EULER",
        "cone: mjCONE_ELLIPTIC -> mjCONE_PYRAMIDAL",
        "noslip_iterations: 0 -> 3",
        "FL_foot.solref: 0.02 1 -> 0.01 1.2",
        "floor.solref: 0.02 1 -> 0.01 1.2",
        "FL_foot.margin: 0 -> 0.001",
    ):
        assert text in report["plant_overrides"], report["plant_overrides"]
    # the URDF plant takes the same overrides; with the defaults nothing changes and nothing is recorded
    urdf_plant = build_plant(plant_options(compose_cfg(overrides), A1))
    assert (
        urdf_plant.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
        and "cone" in read_record(urdf_plant)["overrides"]
    )
    default = build_plant(plant_options(compose_cfg(), A1))
    assert default.ntext == 0 and default.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def test_report_default_plant_agrees_with_the_model():
    r = plant_vs_model(build_plant(), RobotModel(), STAND)
    assert r["plant_total_mass_kg"] == pytest.approx(13.741, abs=1e-9) == r["model_total_mass_kg"]
    assert r["plant_trunk_mass_kg"] == pytest.approx(6.001, abs=1e-12) == r["model_trunk_mass_kg"]
    assert r["model_minus_plant_com_stand_m"] < 1e-12 and r["model_minus_plant_foot_pos_stand_max_m"] < 1e-12
    for side in ("plant", "model"):
        for key in ("damping_nms_per_rad", "armature_kgm2", "frictionloss_nm"):
            assert r[f"{side}_joint_{key}_max"] == 0.0
    assert (r["plant_integrator"], r["plant_timestep_s"], r["plant_cone"]) == (
        "implicitfast",
        0.001,
        "elliptic",
    )
    assert r["plant_torque_limit_nm_min"] == r["plant_torque_limit_nm_max"] == 33.5
    assert r["plant_foot_priority"] == "0" and r["plant_floor_priority"] == "1"
    assert r["plant_contact_solref"] == "0.02 1" and r["plant_contact_feet_at_stand"] == 4
    assert r["plant_overrides"] == "" and r["plant_actuators_converted"] == "" and r["plant_renamed"] == ""
    assert all(k.startswith(("plant_", "model_")) for k in r)


def test_report_shows_a_perturbed_plant_and_a_matching_model():
    kw = {
        "joint_damping": 1.5,
        "armature": 0.01,
        "joint_frictionloss": 0.2,
        "trunk_mass_scale": 0.8,
        "payload_mass_kg": 1.0,
        "payload_pos_m": (0.1, 0.0, 0.0),
    }
    spec = robot_spec()
    PlantPerturbation.checked("scenario", **kw).apply(spec)  # the one implementation of the plant edits
    m = compile_plant(spec)
    nominal = plant_vs_model(m, RobotModel(), STAND)
    assert (
        nominal["plant_joint_damping_nms_per_rad_min"] == 1.5
        and nominal["model_joint_damping_nms_per_rad_max"] == 0
    )
    assert (
        nominal["plant_joint_armature_kgm2_max"] == 0.01 and nominal["plant_joint_frictionloss_nm_max"] == 0.2
    )
    assert nominal["model_minus_plant_total_mass_kg"] == pytest.approx(6.0 * 0.2 - 1.0, abs=1e-12)
    assert nominal["model_minus_plant_com_stand_m"] > 1e-3
    from taslel_bench.robot.model_options import ModelOptions

    matched = plant_vs_model(m, RobotModel(options=ModelOptions(**kw)), STAND)
    assert (
        matched["model_joint_damping_nms_per_rad_min"] == 1.5
        and matched["model_joint_armature_kgm2_max"] == 0.01
    )
    assert matched["model_joint_frictionloss_nm_max"] == 0.2
    assert (
        abs(matched["model_minus_plant_total_mass_kg"]) < 1e-12
        and matched["model_minus_plant_com_stand_m"] < 1e-12
    )


def test_a_second_actuator_on_a_joint_must_be_chosen_and_is_removed(tmp_path):
    """Two actuators on FL_hip (a motor with gear 2 and a velocity servo): ambiguous without a name; named,
    the other is removed and the geared motor becomes gear 1 with the same torque range."""
    xml = third_party_a1(tmp_path / "a1.xml", servos=False)
    spec = mujoco.MjSpec.from_file(str(xml))
    motor = spec.actuator("FL_hip_servo")
    motor.gear, motor.ctrlrange = [2.0, 0, 0, 0, 0, 0], [-16.75, 16.75]  # [N·m / 2]
    damper = spec.add_actuator(name="FL_hip_damper", target="FL_hip", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    damper.set_to_velocity(kv=1.0)
    xml.write_text(spec.to_xml())
    with pytest.raises(
        ConfigError,
        match=r"actuators: several drive FL_hip_joint \(joint 'FL_hip'\): "
        r"'FL_hip_servo', 'FL_hip_damper': name the one",
    ):
        build(xml, ["robot.plant_names.actuators=null"])
    m = build(xml).mj_model
    assert m.nu == 12 and mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "FL_hip_damper") < 0
    fl_hip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "FL_hip_joint")
    assert m.actuator_gear[fl_hip, 0] == 1.0 and np.allclose(m.actuator_ctrlrange[fl_hip], [-33.5, 33.5])
    record = read_record(m)
    assert record["actuators_removed"] == ["FL_hip_damper"]
    assert record["actuators_converted"] == [["FL_hip_joint", "motor gear x gain 2 -> 1 (ctrlrange scaled)"]]


def test_a_changed_plant_file_reruns_instead_of_being_skipped(tmp_path):
    """Same config, same path, other content: the folder's run is not "complete"; it is put aside."""
    xml = third_party_a1(tmp_path / "a1_other.xml", losses=False)
    overrides = [f"robot.plant_mjcf={xml}", *MENAGERIE_LIKE, "duration=0.2", "progress=false", "record.mcap=false"]
    first = run(compose_cfg(overrides), tmp_path / "run")
    assert run(compose_cfg(overrides), tmp_path / "run").get("skipped") is True
    third_party_a1(xml, losses=True)  # the file now has joint losses
    second = run(compose_cfg(overrides), tmp_path / "run")
    assert "skipped" not in second and second["plant_sha256"] != first["plant_sha256"]
    assert second["superseded"].endswith(f"config-{first['config_sha256'][:8]}")
    assert second["plant_joint_damping_nms_per_rad_max"] == 1.5 and first["plant_joint_damping_nms_per_rad_max"] == 0.0
