"""The MuJoCo plant: the A1 URDF turned into an ``MjSpec`` with a free joint, a floor and torque motors.

Frames: MuJoCo world is z-up, the floor is the plane z = 0. ``qpos[:3]`` is the trunk-frame origin in
world [m], ``qpos[3:7]`` its orientation as a wxyz quaternion; ``qvel[:3]`` is the trunk linear velocity
in **world** axes [m/s], ``qvel[3:6]`` the angular velocity in the **trunk** frame [rad/s].

Friction: terrain geoms get ``priority=1`` so a contact uses the terrain's friction, not MuJoCo's
max(foot, floor); the cone is elliptic, so the friction configured is the friction the feet get (checked
from contact data by :func:`measure_contact_friction`). Robot geoms collide only with terrain geoms
(``contype=1, conaffinity=0`` on the robot, ``contype=0, conaffinity=1`` on terrain).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from taslel_bench import robot
from taslel_bench.fields import ConfigError
from taslel_bench.interfaces import RoundObstacle
from taslel_bench.plant_adapter import PlantNames, PlantOverrides, adapt, apply_overrides, store_record

TERRAIN_PRIORITY = 1


@dataclass(frozen=True)
class PlantOptions:
    """What the plant builder needs; validated by :mod:`taslel_bench.config` before use."""

    timestep_s: float = 0.001  # [s] physics step
    floor_friction: float = 1.0  # [-] Coulomb coefficient the feet get on the floor
    torque_limit_nm: float = robot.TORQUE_LIMIT_NM  # [N·m] motor ctrlrange
    names: PlantNames = field(default_factory=PlantNames)  # robot.plant_mjcf: its names where not the core's
    overrides: PlantOverrides = field(default_factory=PlantOverrides)  # contact/integrator settings


def _strip_visuals(spec: mujoco.MjSpec) -> None:
    """Delete mesh geoms (the URDF visuals; MuJoCo cannot read the .dae files) and their mesh assets."""
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)


def a1_spec(options: PlantOptions = PlantOptions()) -> mujoco.MjSpec:
    """Uncompiled A1 plant: URDF collision geometry, free joint on the trunk, floor, 12 motors.

    Scenarios edit the returned spec (terrain, obstacles, perturbations) before :func:`compile_plant`.
    """
    # Parse from a string with visuals removed: the URDF's package:// .dae meshes are not loadable.
    import re

    urdf_text = robot.a1_urdf_path().read_text()
    urdf_text = re.sub(r"<visual>.*?</visual>", "", urdf_text, flags=re.DOTALL)
    spec = mujoco.MjSpec.from_string(urdf_text)
    _strip_visuals(spec)
    spec.compiler.fusestatic = True  # the massless `base` root and fixed links are fused away
    spec.option.timestep = options.timestep_s
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST

    trunk = spec.body(robot.TRUNK_BODY)
    trunk.add_freejoint(name="root")
    for geom in spec.geoms:
        geom.contype, geom.conaffinity = 1, 0
        geom.condim = 3
    for leg in robot.LEGS:
        foot_body = spec.body(f"{leg}_foot")
        for geom in foot_body.geoms:
            if geom.type == mujoco.mjtGeom.mjGEOM_SPHERE:
                geom.name = f"{leg}_foot"
        foot_body.add_site(name=f"{leg}_foot", pos=[0, 0, 0])
    spec.body(robot.TRUNK_BODY).add_site(name="imu", pos=[0, 0, 0])

    add_terrain_geom(
        spec,
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 0.05],
        friction=options.floor_friction,
    )
    add_foot_contact_sensors(spec)
    for name in robot.JOINT_NAMES:
        act = spec.add_actuator(name=name, target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_motor()
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-options.torque_limit_nm, options.torque_limit_nm]
    changes = apply_overrides(spec, options.overrides, options.timestep_s)  # the defaults change nothing here
    store_record(spec, {"overrides": changes} if changes else {})
    return spec


# MuJoCo contact-sensor parameters (as the MJCF <contact data="found force torque pos" reduce="netforce"
# num="1">): intprm = (data bits, reduction: netforce, num). netforce merges a foot's contacts into one at
# the force-weighted centroid of the contact points, with the net force and torque (world axes).
_CONTACT_SENSOR_INTPRM = (1 | 2 | 4 | 16, 3, 1)  # data: found, force, torque, pos
_CONTACT_SENSOR_OBSTACLE_INTPRM = (1 | 2, 3, 1)  # found, force (obstacle contacts only need a count)


def add_foot_contact_sensors(spec: mujoco.MjSpec) -> None:
    """Per foot: a contact sensor (number of contacts; net force and torque in world axes exerted *by* the
    foot on what it touches, at the centroid of its contact points, which it also gives) and the foot site's
    position, linear and angular velocity in world axes — read in one slice of ``sensordata`` instead of
    looping over ``data.contact``. The force, torque and point give the generalised contact force exactly
    (J(point)' f + J_rot' torque = MuJoCo's qfrc_constraint of the contacts). Requires a site named like the
    foot."""
    for foot in robot.FOOT_FRAMES:
        sensor = spec.add_sensor(name=f"{foot}_contact", type=mujoco.mjtSensor.mjSENS_CONTACT,
                                 objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=foot)
        sensor.intprm[:3] = _CONTACT_SENSOR_INTPRM
        for kind, typ in (("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),
                          ("linvel", mujoco.mjtSensor.mjSENS_FRAMELINVEL),
                          ("angvel", mujoco.mjtSensor.mjSENS_FRAMEANGVEL)):
            spec.add_sensor(name=f"{foot}_{kind}", type=typ, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=foot)


def mjcf_spec(path: Path, options: PlantOptions = PlantOptions()) -> mujoco.MjSpec:
    """Plant from another A1 MJCF: a free joint, 12 leg joints, one torque motor or servo per joint, sphere
    foot geoms; names as the core's or mapped by ``options.names`` (:mod:`taslel_bench.plant_adapter`
    renames them to the core's, converts servos to torque motors, finds the file's floor).

    Adds what the harness needs if absent (foot sites, foot sensors, a floor if the file has no plane on its
    world body), sets the time step and ``options.overrides``, and makes terrain friction win (the floor
    gets terrain priority and condim 3; the feet priority 0). What was changed is kept in the model
    (:func:`taslel_bench.plant_adapter.read_record`). Raises :class:`ConfigError` naming the field and what
    is missing (joints, actuators, feet, trunk, floor).
    """
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
    for foot in robot.FOOT_FRAMES:
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
    if f"{robot.FOOT_FRAMES[0]}_contact" not in sensors:
        add_foot_contact_sensors(spec)
    store_record(spec, record)
    return spec


def _check_feet_touch(spec: mujoco.MjSpec, floor: mujoco.MjsGeom, where: str) -> None:
    """Raise naming *feet* if a foot geom's contype/conaffinity bits exclude collisions with ``floor``."""
    blind = [f for f in robot.FOOT_FRAMES if not ((spec.geom(f).contype & floor.conaffinity)
                                                 or (floor.contype & spec.geom(f).conaffinity))]
    if blind:
        raise ConfigError(f"{where} does not fit the A1 controller: feet: {', '.join(blind)} cannot collide "
                          f"with the floor (contype/conaffinity: foot {spec.geom(blind[0]).contype}/"
                          f"{spec.geom(blind[0]).conaffinity}, floor {floor.contype}/{floor.conaffinity})")


def add_terrain_geom(
    spec: mujoco.MjSpec,
    *,
    name: str,
    type: mujoco.mjtGeom,
    size: list[float],
    friction: float,
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0),
    rgba: tuple[float, float, float, float] = (0.5, 0.55, 0.6, 1.0),
) -> mujoco.MjsGeom:
    """Add a static terrain geom on the world body whose friction wins every foot contact."""
    geom = spec.worldbody.add_geom(name=name, type=type, size=size, pos=list(pos), rgba=list(rgba))
    geom.friction = [friction, 0.005, 0.0001]
    geom.priority = TERRAIN_PRIORITY
    geom.contype, geom.conaffinity = 0, 1
    geom.condim = 3
    return geom


OBSTACLE_BODY = "obstacles"  # static (mocap) body holding every physical obstacle geom
OBSTACLE_SENSOR_SUFFIX = "obstacle"  # per foot: contacts of the foot sphere with the obstacles body


def add_round_obstacles(spec: mujoco.MjSpec, obstacles: Sequence[RoundObstacle], friction: float) -> None:
    """Put each :class:`RoundObstacle` in the plant as a capsule along world y (exact sphere-capsule
    collision, so the contact geometry is the barrier's geometry), on one static body
    :data:`OBSTACLE_BODY` (mocap: not fused into the world, so contact sensors can name it), plus one
    contact sensor per foot counting that foot's contacts with the obstacles (:class:`FootContactReader`).
    Obstacle geoms are terrain (their friction wins, robot geoms collide with them)."""
    if not obstacles:
        return
    body = spec.worldbody.add_body(name=OBSTACLE_BODY, mocap=True)
    axis_along_y = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # capsule axis: local z -> world y
    for i, ob in enumerate(obstacles):
        geom = body.add_geom(name=f"{OBSTACLE_BODY}_{i}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                             size=[ob.radius_m, ob.half_width_m, 0.0], pos=[ob.x_m, 0.0, ob.z_m],
                             quat=axis_along_y, rgba=[0.55, 0.4, 0.25, 1.0])  # fmt: skip
        geom.friction = [friction, 0.005, 0.0001]
        geom.priority = TERRAIN_PRIORITY
        geom.contype, geom.conaffinity = 0, 1
        geom.condim = 3
    for foot in robot.FOOT_FRAMES:
        sensor = spec.add_sensor(name=f"{foot}_{OBSTACLE_SENSOR_SUFFIX}", type=mujoco.mjtSensor.mjSENS_CONTACT,
                                 objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=foot, reftype=mujoco.mjtObj.mjOBJ_BODY,
                                 refname=OBSTACLE_BODY)  # fmt: skip
        sensor.intprm[:3] = _CONTACT_SENSOR_OBSTACLE_INTPRM


def obstacle_geom_mask(model: mujoco.MjModel) -> np.ndarray:
    """(ngeom,) bool: geoms of the :data:`OBSTACLE_BODY` (all False when the plant has none)."""
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBSTACLE_BODY)
    return model.geom_bodyid == body if body >= 0 else np.zeros(model.ngeom, bool)


def compile_plant(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """Compile with a clear error if the spec lost what the harness relies on."""
    model = spec.compile()
    missing = [
        n for n in robot.JOINT_NAMES if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) < 0
    ]
    missing += [
        f"geom {f}" for f in robot.FOOT_FRAMES if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f) < 0
    ]
    if missing:
        raise ValueError(f"plant model is missing {', '.join(missing)}")
    return model


def build_plant(options: PlantOptions = PlantOptions()) -> mujoco.MjModel:
    """The default flat-floor plant."""
    return compile_plant(a1_spec(options))


def foot_geom_ids(model: mujoco.MjModel) -> np.ndarray:
    """MuJoCo geom ids of the four foot spheres, in :data:`robot.LEGS` order."""
    return np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f) for f in robot.FOOT_FRAMES])


def measure_contact_friction(model: mujoco.MjModel, data: mujoco.MjData) -> list[tuple[str, float]]:
    """(foot name, sliding friction coefficient) of every active foot contact, read from ``data.contact``."""
    feet = {int(g): name for g, name in zip(foot_geom_ids(model), robot.FOOT_FRAMES)}
    out = []
    for i in range(data.ncon):
        c = data.contact[i]
        for g in (int(c.geom1), int(c.geom2)):
            if g in feet:
                out.append((feet[g], float(c.friction[0])))
    return out


class FootContactReader:
    """Plant-side contact quantities of the four feet after a step, from the foot sensors.

    ``forces_in_world`` (4, 3): net contact force **on** each foot [N], world axes (0 without contact) —
    the constraint forces MuJoCo applied in the last physics step. ``in_contact`` (4,) bool.
    Robot geoms other than the feet, touching terrain (checked through ``data.contact`` only when the
    contact count exceeds the feet's; a contact counts only at distance <= 0, a contact inside a geom margin
    is not a touch; ``data.contact`` after ``mj_step`` holds the contacts of the step's *starting* state):
    ``body_contact``: the trunk, a hip or a thigh (anything above the knee) touches any terrain: a fall;
    ``shin_contact``: a lower leg (the other geoms of the body that carries a foot sphere) touches the
    floor; ``non_foot_obstacle_contact``: a lower leg touches a physical obstacle (:data:`OBSTACLE_BODY`):
    a trip. ``non_foot_contact_name``: the body of the first such geom.
    ``slip_velocity_in_world`` (4, 2): horizontal velocity [m/s] of the sphere's lowest point (the contact
    point on flat ground): v_centre + omega x (-r z) — the centre of a rolling, non-slipping foot moves.
    ``foot_pos_in_world`` (4, 3): foot-sphere centres [m].
    Positions and velocities are the sensors' values, i.e. at the start of the last physics step.

    :meth:`read` fills these from one ``data``; :meth:`from_sensor_log` computes the same quantities for a
    whole log of ``sensordata`` rows at once (the episode trace records raw rows in the control loop).
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.foot_geoms = foot_geom_ids(model)

        def sensor_adr(kind: str) -> np.ndarray:
            ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{f}_{kind}") for f in robot.FOOT_FRAMES]
            if min(ids) < 0:
                raise ValueError(
                    f"plant model has no foot {kind} sensors; build it with plant.add_foot_contact_sensors"
                )
            return model.sensor_adr[ids]

        adr = sensor_adr("contact")
        self._found_rows = adr.copy()  # number of contacts per foot
        self._found_rows_list = [int(r) for r in adr]
        self._force_rows = adr[:, None] + np.arange(1, 4)  # fx, fy, fz (by the foot), world axes
        self._torque_rows = adr[:, None] + np.arange(4, 7)  # net torque about the contact point, world axes
        self._point_rows = adr[:, None] + np.arange(7, 10)  # force-weighted centroid of the contact points
        self._pos_rows = sensor_adr("pos")[:, None] + np.arange(3)
        self._lin_rows = sensor_adr("linvel")[:, None] + np.arange(2)  # vx, vy
        self._ang_rows = sensor_adr("angvel")[:, None] + np.array([1, 0])  # wy, wx
        self._radius_sign = robot.FOOT_RADIUS_M * np.array([-1.0, 1.0])  # v_x - r w_y, v_y + r w_x
        self._is_foot = np.zeros(model.ngeom, bool)
        self._is_foot[self.foot_geoms] = True
        robot_root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot.TRUNK_BODY)
        self._is_robot_geom = model.body_rootid[model.geom_bodyid] == model.body_rootid[robot_root]
        foot_bodies = model.geom_bodyid[self.foot_geoms]
        self._is_lower_leg = np.isin(model.geom_bodyid, foot_bodies) & ~self._is_foot  # calves (knee to foot)
        self._is_obstacle = obstacle_geom_mask(model)
        self.has_obstacles = bool(self._is_obstacle.any())
        if self.has_obstacles:  # per foot: number of contacts with the obstacles body
            self._obstacle_rows = sensor_adr(OBSTACLE_SENSOR_SUFFIX)
        self.body_contact = self.shin_contact = self.non_foot_obstacle_contact = False
        self.non_foot_contact_name = ""
        self.forces_in_world = np.zeros((robot.N_LEGS, 3))
        self.in_contact = np.zeros(robot.N_LEGS, bool)
        self.slip_velocity_in_world = np.zeros((robot.N_LEGS, 2))
        self.foot_pos_in_world = np.zeros((robot.N_LEGS, 3))
        self._data: mujoco.MjData | None = None
        self._sensordata = np.zeros(0)

    def read(self, data: mujoco.MjData) -> None:
        """All quantities from ``data`` after a step."""
        sd = data.sensordata
        found = sd[self._found_rows]
        np.negative(sd[self._force_rows], out=self.forces_in_world)  # sensor: force by the foot; we want on it
        np.greater(found, 0.0, out=self.in_contact)
        np.multiply(sd[self._ang_rows], self._radius_sign, out=self.slip_velocity_in_world)
        self.slip_velocity_in_world += sd[self._lin_rows]
        self.foot_pos_in_world[:] = sd[self._pos_rows]
        self.check_non_foot_contact(data)

    def check_non_foot_contact(self, data: mujoco.MjData) -> bool:
        """Only ``body_contact``, ``shin_contact`` and ``non_foot_obstacle_contact`` (cheap unless there are
        more contacts than foot contacts). Returns ``body_contact`` (a fall)."""
        if data is not self._data:  # keep the sensordata view of this data (a new wrapper per attribute read)
            self._data, self._sensordata = data, data.sensordata
        sd, (r0, r1, r2, r3) = self._sensordata, self._found_rows_list
        n_found = sd[r0] + sd[r1] + sd[r2] + sd[r3]  # 4 scalar reads: cheaper than a fancy index + sum
        if data.ncon > n_found:
            self._classify_other_contacts(data)
        else:
            self.body_contact = self.shin_contact = self.non_foot_obstacle_contact = False
        return self.body_contact

    def from_sensor_log(self, sensors: np.ndarray) -> dict[str, np.ndarray]:
        """(n, nsensordata) rows -> ``forces_in_world`` (n, 4, 3), ``in_contact`` (n, 4),
        ``slip_velocity_in_world`` (n, 4, 2), ``foot_pos_in_world`` (n, 4, 3); same definitions as :meth:`read`."""
        n = sensors.shape[0]
        return {
            "forces_in_world": -sensors[:, self._force_rows],
            "torques_in_world": -sensors[:, self._torque_rows],
            "contact_point_in_world": sensors[:, self._point_rows],
            "in_contact": sensors[:, self._found_rows] > 0.0,
            "slip_velocity_in_world": sensors[:, self._lin_rows] + sensors[:, self._ang_rows] * self._radius_sign,
            "foot_pos_in_world": sensors[:, self._pos_rows],
            "obstacle_contact": (sensors[:, self._obstacle_rows] > 0.0 if self.has_obstacles
                                 else np.zeros((n, robot.N_LEGS), bool)),
        }

    def _classify_other_contacts(self, data: mujoco.MjData) -> None:
        """Non-foot robot geoms touching terrain at distance <= 0 (see the class doc)."""
        con = data.contact
        geom = con.geom
        robot_side = self._is_robot_geom[geom]
        other = (con.dist <= 0.0) & ~(self._is_foot[geom[:, 0]] | self._is_foot[geom[:, 1]])
        other &= robot_side[:, 0] != robot_side[:, 1]
        if not other.any():
            self.body_contact = self.shin_contact = self.non_foot_obstacle_contact = False
            return
        pairs = geom[other]
        robot_geom = np.where(robot_side[other, 0], pairs[:, 0], pairs[:, 1])
        on_obstacle = self._is_obstacle[np.where(robot_side[other, 0], pairs[:, 1], pairs[:, 0])]
        lower = self._is_lower_leg[robot_geom]
        body, shin, trip = ~lower, lower & ~on_obstacle, lower & on_obstacle
        self.body_contact, self.shin_contact, self.non_foot_obstacle_contact = bool(body.any()), bool(shin.any()), bool(trip.any())
        first = robot_geom[np.argmax(body)] if self.body_contact else robot_geom[0]
        self.non_foot_contact_name = self.model.body(self.model.geom_bodyid[first]).name
