"""How terrain enters the MuJoCo plant: static geoms whose friction wins every foot contact.

MuJoCo combines two geoms' friction by the maximum unless one has a higher ``priority``; terrain geoms get
:data:`TERRAIN_PRIORITY`, so a foot gets the terrain's friction (checked from contact data before every run).
Robot geoms collide only with terrain geoms (``contype=1, conaffinity=0`` on the robot, ``contype=0,
conaffinity=1`` on terrain). Obstacles (terrain a foot should step over, e.g. logs) hang on one static body,
:data:`OBSTACLE_BODY`, with one contact sensor per foot counting that foot's contacts with it.
"""

from __future__ import annotations

import mujoco

from taslel_bench.robot import quadruped as quad

TERRAIN_PRIORITY = 1
OBSTACLE_BODY = "obstacles"  # static (mocap) body holding every obstacle geom
OBSTACLE_SENSOR_SUFFIX = "obstacle"  # per foot: contacts of the foot sphere with the obstacles body
# MuJoCo contact sensor intprm = (data bits: found | force, reduction: netforce, num): a count is enough
_OBSTACLE_SENSOR_INTPRM = (1 | 2, 3, 1)
TANGENTIAL_FRICTION = (0.005, 0.0001)  # MuJoCo's torsional and rolling coefficients of every terrain geom


def make_terrain(geom: mujoco.MjsGeom, friction: float) -> mujoco.MjsGeom:
    """Give ``geom`` the terrain's contact settings: friction ``friction`` [-] that wins every foot contact,
    collides with the robot only, condim 3 (Coulomb friction in the tangent plane)."""
    geom.friction = [friction, *TANGENTIAL_FRICTION]
    geom.priority = TERRAIN_PRIORITY
    geom.contype, geom.conaffinity = 0, 1
    geom.condim = 3
    return geom


def add_terrain_geom(
    spec: mujoco.MjSpec,
    *,
    name: str,
    type: mujoco.mjtGeom,
    size: list[float],
    friction: float,
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0),
    rgba: tuple[float, float, float, float] = (0.5, 0.55, 0.6, 1.0),
    body: mujoco.MjsBody | None = None,
    **attributes,
) -> mujoco.MjsGeom:
    """A static terrain geom on ``body`` (default: the world body), world frame [m]."""
    parent = body if body is not None else spec.worldbody
    geom = parent.add_geom(name=name, type=type, size=size, pos=list(pos), rgba=list(rgba), **attributes)
    return make_terrain(geom, friction)


def obstacle_body(spec: mujoco.MjSpec) -> mujoco.MjsBody:
    """The static body that holds the obstacles (created with the feet's obstacle contact sensors on first
    use; mocap, so MuJoCo does not fuse it into the world and the sensors can name it)."""
    existing = {b.name for b in spec.bodies}
    if OBSTACLE_BODY in existing:
        return spec.body(OBSTACLE_BODY)
    return spec.worldbody.add_body(name=OBSTACLE_BODY, mocap=True)


def add_obstacle_sensors(spec: mujoco.MjSpec) -> None:
    """Per foot, a contact sensor counting the foot sphere's contacts with :data:`OBSTACLE_BODY`
    (read by :class:`taslel_bench.plant.contacts.FootContactReader`)."""
    for foot in quad.FOOT_FRAMES:
        sensor = spec.add_sensor(name=f"{foot}_{OBSTACLE_SENSOR_SUFFIX}", type=mujoco.mjtSensor.mjSENS_CONTACT,
                                 objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=foot, reftype=mujoco.mjtObj.mjOBJ_BODY,
                                 refname=OBSTACLE_BODY)  # fmt: skip
        sensor.intprm[:3] = _OBSTACLE_SENSOR_INTPRM
