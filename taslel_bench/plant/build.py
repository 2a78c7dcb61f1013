"""The MuJoCo plant: a robot's URDF turned into an ``MjSpec`` with a free joint, a floor and torque motors.

The robot's joints, foot spheres and trunk body are renamed to the core's names
(:mod:`taslel_bench.robot.quadruped`: ``FL_hip_joint`` .. ``RR_calf_joint``, ``FL_foot`` .., ``trunk``), so the state
bridge, the contact reader and the scenarios read every robot alike.

Frames: MuJoCo world is z-up, the floor is the plane z = 0. ``qpos[:3]`` is the trunk-frame origin in
world [m], ``qpos[3:7]`` its orientation as a wxyz quaternion; ``qvel[:3]`` is the trunk linear velocity
in **world** axes [m/s], ``qvel[3:6]`` the angular velocity in the **trunk** frame [rad/s].

Friction: terrain geoms get ``priority=1`` so a contact uses the terrain's friction, not MuJoCo's
max(foot, floor); the cone is elliptic, so the friction configured is the friction the feet get (checked
from contact data by :func:`measure_contact_friction`). Robot geoms collide only with terrain geoms
(``contype=1, conaffinity=0`` on the robot, ``contype=0, conaffinity=1`` on terrain).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import mujoco

from taslel_bench.plant.adapter import (
    PlantNames,
    PlantOverrides,
    adapt,
    apply_overrides,
    rename,
    store_record,
)
from taslel_bench.plant.mjcf_files import mjcf_files
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription, default_robot, physical_urdf_text
from taslel_bench.terrain.geoms import TERRAIN_PRIORITY, add_terrain_geom
from taslel_bench.util.fields import ConfigError


@dataclass(frozen=True)
class PlantOptions:
    """What the plant builder needs; validated by :mod:`taslel_bench.config.validate` before use."""

    timestep_s: float = 0.001  # [s] physics step
    floor_friction: float = 1.0  # [-] Coulomb coefficient the feet get on the floor
    # [N·m] motor ctrlrange per joint, core order (the robot's: settings.plant_options)
    torque_limit_nm: tuple[float, ...] = field(default_factory=lambda: default_robot().torque_limit_nm)
    names: PlantNames = field(default_factory=PlantNames)  # robot.plant_mjcf: its names where not the core's
    overrides: PlantOverrides = field(default_factory=PlantOverrides)  # contact/integrator settings


def _strip_unloadable_meshes(spec: mujoco.MjSpec) -> None:
    """Delete mesh geoms whose file MuJoCo cannot read (COLLADA .dae: the URDFs' visuals) and their assets."""
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = spec.mesh(geom.meshname)
            if mesh is None or not mesh.file.lower().endswith((".stl", ".obj", ".msh")):
                spec.delete(geom)
    used = {g.meshname for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for mesh in list(spec.meshes):
        if mesh.name not in used:
            spec.delete(mesh)


def _urdf_text(robot: RobotDescription) -> str:
    """The URDF without ``<visual>`` elements, mesh paths ``package://<pkg>/...`` made absolute (found above the
    URDF's folder), and without the foot links' collisions where the plant puts its own foot sphere."""
    text = re.sub(
        r"<visual>.*?</visual>", "", physical_urdf_text(robot.urdf_path, robot.trunk_link)[0], flags=re.DOTALL
    )
    text = re.sub(r'filename="package://([^/"]+)/([^"]*)"',
                  lambda m: f'filename="{_package_file(robot.urdf_path, m.group(1), m.group(2))}"', text)
    if not robot.foot_from_urdf:
        for foot in robot.foot_frames:
            link = rf'(<link\s+name="{re.escape(foot)}"\s*>(?:(?!</link>).)*?)<collision\b[^>]*>.*?</collision>'
            while re.search(link, text, flags=re.DOTALL):
                text = re.sub(link, r"\1", text, count=1, flags=re.DOTALL)
    return text


def urdf_mesh_files(urdf: Path) -> list[Path]:
    """The mesh files the plant of ``urdf`` loads (collision meshes MuJoCo can read: STL, OBJ, MSH; the run's
    identity hashes them with the URDF)."""
    text = re.sub(r"<visual>.*?</visual>", "", Path(urdf).read_text(), flags=re.DOTALL)
    names = re.findall(r'filename="package://([^/"]+)/([^"]*)"', text)
    files = {Path(_package_file(Path(urdf), pkg, inner)) for pkg, inner in names}
    return sorted(f for f in files if f.suffix.lower() in (".stl", ".obj", ".msh") and f.is_file())


def _package_file(urdf: Path, package: str, inner: str) -> str:
    for folder in urdf.parents:
        if folder.name == package and (folder / inner).is_file():
            return str(folder / inner)
    return f"package://{package}/{inner}"  # left as it was: MuJoCo's compile error names the file


def robot_spec(robot: RobotDescription | None = None, options: PlantOptions | None = None) -> mujoco.MjSpec:
    """Uncompiled plant of ``robot`` (default: the A1): its URDF's collision geometry under the core's names, a
    free joint on the trunk, a floor, 12 torque motors at ``options.torque_limit_nm``, foot sites and sensors
    (``options`` None: the defaults with the robot's torque limits).

    Scenarios edit the returned spec (terrain, obstacles, perturbations) before :func:`compile_plant`.
    """
    robot = robot if robot is not None else default_robot()
    options = options if options is not None else PlantOptions(torque_limit_nm=robot.torque_limit_nm)
    spec = mujoco.MjSpec.from_string(_urdf_text(robot))
    _strip_unloadable_meshes(spec)
    spec.compiler.fusestatic = True  # massless roots and fixed links are fused away
    # masses and inertias from the URDF only, as Pinocchio reads them (MuJoCo's default would give a link with
    # collision shapes but no <inertial> a mass from its geoms' volume)
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.timestep = options.timestep_s
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    _core_names(spec, robot)

    trunk = spec.body(quad.TRUNK_BODY)
    trunk.add_freejoint(name="root")
    for geom in spec.geoms:
        geom.contype, geom.conaffinity = 1, 0
        geom.condim = 3
    for foot in quad.FOOT_FRAMES:
        geom = spec.geom(foot)
        geom.parent.add_site(name=foot, pos=list(geom.pos))
    spec.body(quad.TRUNK_BODY).add_site(name="imu", pos=[0, 0, 0])

    add_terrain_geom(
        spec,
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 0.05],
        friction=options.floor_friction,
    )
    add_foot_contact_sensors(spec)
    for name, limit in zip(quad.JOINT_NAMES, options.torque_limit_nm, strict=True):
        act = spec.add_actuator(name=name, target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_motor()
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-limit, limit]
    changes = apply_overrides(spec, options.overrides, options.timestep_s)  # the defaults change nothing here
    store_record(spec, {"overrides": changes} if changes else {})
    return spec


def _core_names(spec: mujoco.MjSpec, robot: RobotDescription) -> None:
    """Rename the robot's joints, foot spheres and trunk body to the core's names (no-ops where they agree, as
    on the A1); a foot the URDF gives as a mesh gets a sphere of the description's radius at its frame."""
    joints = {j.name: j for j in spec.joints}
    rename(spec, mujoco.mjtObj.mjOBJ_JOINT,
           {old: joints[old] for old, new in zip(robot.joint_names, quad.JOINT_NAMES, strict=True) if old != new},
           dict(zip(robot.joint_names, quad.JOINT_NAMES, strict=True)))
    feet: dict[str, mujoco.MjsGeom] = {}
    for leg, foot in enumerate(robot.foot_frames):
        body = spec.body(foot)
        if not robot.foot_from_urdf:
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[robot.foot_radius_m, 0, 0], pos=[0, 0, 0],
                          name=f"__foot_{leg}")
        spheres = [g for g in body.geoms if g.type == mujoco.mjtGeom.mjGEOM_SPHERE]
        if len(spheres) != 1:
            raise ConfigError(f"robot.feet: the plant's {foot} has {len(spheres)} sphere geoms; the core needs one")
        spheres[0].name = spheres[0].name or f"__foot_{leg}"
        feet[spheres[0].name] = spheres[0]
    rename(spec, mujoco.mjtObj.mjOBJ_GEOM, feet, dict(zip(feet, quad.FOOT_FRAMES, strict=True)))
    if robot.trunk_link != quad.TRUNK_BODY:
        rename(spec, mujoco.mjtObj.mjOBJ_BODY, {robot.trunk_link: spec.body(robot.trunk_link)},
               {robot.trunk_link: quad.TRUNK_BODY})


# MuJoCo contact-sensor parameters (as the MJCF <contact data="found force torque pos" reduce="netforce"
# num="1">): intprm = (data bits, reduction: netforce, num). netforce merges a foot's contacts into one at
# the force-weighted centroid of the contact points, with the net force and torque (world axes).
_CONTACT_SENSOR_INTPRM = (1 | 2 | 4 | 16, 3, 1)  # data: found, force, torque, pos


def add_foot_contact_sensors(spec: mujoco.MjSpec) -> None:
    """Per foot: a contact sensor (number of contacts; net force and torque in world axes exerted *by* the
    foot on what it touches, at the centroid of its contact points, which it also gives) and the foot site's
    position, linear and angular velocity in world axes — read in one slice of ``sensordata`` instead of
    looping over ``data.contact``. The force, torque and point give the generalised contact force exactly
    (J(point)' f + J_rot' torque = MuJoCo's qfrc_constraint of the contacts). Requires a site named like the
    foot."""
    for foot in quad.FOOT_FRAMES:
        sensor = spec.add_sensor(name=f"{foot}_contact", type=mujoco.mjtSensor.mjSENS_CONTACT,
                                 objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=foot)
        sensor.intprm[:3] = _CONTACT_SENSOR_INTPRM
        for kind, typ in (("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),
                          ("linvel", mujoco.mjtSensor.mjSENS_FRAMELINVEL),
                          ("angvel", mujoco.mjtSensor.mjSENS_FRAMEANGVEL)):
            spec.add_sensor(name=f"{foot}_{kind}", type=typ, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=foot)


def mjcf_spec(path: Path, options: PlantOptions | None = None) -> mujoco.MjSpec:
    """Plant from another MJCF of the robot: a free joint, 12 leg joints, one torque motor or servo per joint, sphere
    foot geoms; names as the core's or mapped by ``options.names`` (:mod:`taslel_bench.plant.adapter`
    renames them to the core's, converts servos to torque motors, finds the file's floor).

    Adds what the harness needs if absent (foot sites, foot sensors, a floor if the file has no plane on its
    world body), sets the time step and ``options.overrides``, and makes terrain friction win (the floor
    gets terrain priority and condim 3; the feet priority 0). What was changed is kept in the model
    (:func:`taslel_bench.plant.adapter.read_record`). Raises :class:`ConfigError` naming the field and what
    is missing (joints, actuators, feet, trunk, floor). ``options`` None: the defaults (the default robot's limits).
    """
    options = options if options is not None else PlantOptions()
    path = Path(path)
    where = f"robot.plant_mjcf={str(path)!r}"
    if not path.is_file():
        raise ConfigError(f"{where}: no such file")
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:  # MuJoCo's parse error names neither the file nor the config field
        reason = " ".join(str(exc).split())
        raise ConfigError(f"{where}: MuJoCo cannot read this file as MJCF: {reason}") from exc
    try:
        floor, record = adapt(spec, options.names, options.torque_limit_nm, where)
    except ValueError as exc:
        raise ConfigError(str(exc) if str(exc).startswith(where) else f"{where}: {exc}") from exc
    sites = {s.name for s in spec.sites}
    for foot in quad.FOOT_FRAMES:
        g = spec.geom(foot)
        if foot not in sites:
            g.parent.add_site(name=foot, pos=list(g.pos))
        g.priority = 0
    if floor is None:
        add_terrain_geom(spec, name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05],
                         friction=options.floor_friction)
        record["floor"] = "added (the file has no plane on its world body)"
    else:
        before = f"priority {floor.priority}, condim {floor.condim}, friction {floor.friction[0]:g}"
        floor.priority, floor.condim, floor.friction[0] = TERRAIN_PRIORITY, 3, options.floor_friction
        record["floor"] = f"the file's ({before} -> terrain priority {TERRAIN_PRIORITY}, condim 3)"
        _check_feet_touch(spec, floor, where)
    changes = apply_overrides(spec, options.overrides, options.timestep_s)
    if changes:
        record["overrides"] = changes
    sensors = {s.name for s in spec.sensors}
    if f"{quad.FOOT_FRAMES[0]}_contact" not in sensors:
        add_foot_contact_sensors(spec)
    store_record(spec, record)
    return spec


def _check_feet_touch(spec: mujoco.MjSpec, floor: mujoco.MjsGeom, where: str) -> None:
    """Raise naming *feet* if a foot geom's contype/conaffinity bits exclude collisions with ``floor``."""
    blind = [f for f in quad.FOOT_FRAMES if not ((spec.geom(f).contype & floor.conaffinity)
                                                 or (floor.contype & spec.geom(f).conaffinity))]
    if blind:
        raise ConfigError(f"{where} does not fit the controller: feet: {', '.join(blind)} cannot collide "
                          f"with the floor (contype/conaffinity: foot {spec.geom(blind[0]).contype}/"
                          f"{spec.geom(blind[0]).conaffinity}, floor {floor.contype}/{floor.conaffinity})")


def compile_plant(spec: mujoco.MjSpec, source: Path | None = None) -> mujoco.MjModel:
    """Compile with a clear error if the spec lost what the harness relies on. ``source``: the
    ``robot.plant_mjcf`` file the spec came from; MuJoCo's compile errors (a mass below mjMINVAL, a mesh
    file it cannot open) become a :class:`ConfigError` naming the field, the file and any missing file."""
    try:
        model = spec.compile()
    except ValueError as exc:
        if source is None:
            raise
        raise ConfigError(compile_error_message(Path(source), exc)) from exc
    missing = [
        n for n in quad.JOINT_NAMES if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) < 0
    ]
    missing += [
        f"geom {f}" for f in quad.FOOT_FRAMES if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f) < 0
    ]
    if missing:
        raise ValueError(f"plant model is missing {', '.join(missing)}")
    return model


def compile_error_message(source: Path, exc: BaseException) -> str:
    """``robot.plant_mjcf=<path>: MuJoCo cannot compile the plant: <its message>`` with the files the MJCF
    names that do not exist (resolved as MuJoCo resolves them: includes, meshdir/texturedir/assetdir)."""
    reason = " ".join(str(exc).split())
    message = f"robot.plant_mjcf={str(source)!r}: MuJoCo cannot compile the plant: {reason}"
    missing = [str(p) for p in mjcf_files(source) if not p.is_file()]
    if missing:
        message += f"; files it names that do not exist: {', '.join(missing[:8])}" + (
            " ..." if len(missing) > 8 else ""
        )
    if "mjMINVAL" in reason:
        message += ("; every moving body needs mass and inertia: give it an <inertial> or geoms with density "
                    "(compiler inertiafromgeom)")
    return message


def build_plant(options: PlantOptions | None = None, robot: RobotDescription | None = None) -> mujoco.MjModel:
    """The flat-floor plant of ``robot`` (default: the A1)."""
    return compile_plant(robot_spec(robot, options))
