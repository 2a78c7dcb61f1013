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

from dataclasses import dataclass

import mujoco
import numpy as np

from taslel_bench import robot

TERRAIN_PRIORITY = 1
_XYZ = np.arange(3)
_LEG_IDS = np.arange(robot.N_LEGS)


@dataclass(frozen=True)
class PlantOptions:
    """What the plant builder needs; validated by :mod:`taslel_bench.config` before use."""

    timestep_s: float = 0.001  # [s] physics step
    floor_friction: float = 1.0  # [-] Coulomb coefficient the feet get on the floor
    torque_limit_nm: float = robot.TORQUE_LIMIT_NM  # [N·m] motor ctrlrange


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
    urdf_text = re.sub(r"<visual>.*?</visual>", "", urdf_text, flags=re.S)
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
    for name in robot.JOINT_NAMES:
        act = spec.add_actuator(name=name, target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_motor()
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-options.torque_limit_nm, options.torque_limit_nm]
    return spec


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
    """Plant-side contact quantities of the four feet, read from ``data.contact`` after a step.

    ``forces_in_world`` (4, 3): total contact force **on** each foot [N], world axes (0 without contact).
    ``in_contact`` (4,) bool. ``non_foot_contact``: True if any robot geom other than a foot touches terrain.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.foot_geoms = foot_geom_ids(model)
        self._leg_of_geom = np.full(model.ngeom, -1)
        self._leg_of_geom[self.foot_geoms] = np.arange(len(self.foot_geoms))
        robot_root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot.TRUNK_BODY)
        self._is_robot_geom = model.body_rootid[model.geom_bodyid] == model.body_rootid[robot_root]
        self.forces_in_world = np.zeros((robot.N_LEGS, 3))
        self.in_contact = np.zeros(robot.N_LEGS, bool)
        self.non_foot_contact = False
        self._f6 = np.zeros(6)
        self._elliptic = model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC

    def read(self, data: mujoco.MjData) -> None:
        self.forces_in_world[:] = 0.0
        self.in_contact[:] = False
        self.non_foot_contact = False
        n = data.ncon
        if n == 0:
            return
        con = data.contact
        geom = con.geom
        leg2 = self._leg_of_geom[geom[:, 1]]
        leg1 = self._leg_of_geom[geom[:, 0]]
        is_foot = (leg1 >= 0) | (leg2 >= 0)
        if not is_foot.all():
            other = ~is_foot
            robot_side = self._is_robot_geom[geom[other]]
            self.non_foot_contact = bool(np.any(robot_side[:, 0] != robot_side[:, 1]))
        if self._elliptic and np.all(con.dim == 3):
            # elliptic cone: efc_force rows of a contact are its (normal, t1, t2) force in the contact frame
            f_con = data.efc_force[con.efc_address[:, None] + _XYZ]
        else:
            f_con = np.zeros((n, 3))
            for i in range(n):
                mujoco.mj_contactForce(self.model, data, i, self._f6)
                f_con[i] = self._f6[:3]
        # MuJoCo's contact force acts from geom1 on geom2; rows of `frame` are the contact axes in world
        f_world = np.einsum("nij,ni->nj", con.frame.reshape(n, 3, 3), f_con)
        on2 = leg2[:, None] == _LEG_IDS  # (n, 4): foot is geom2 -> force acts on it
        on1 = leg1[:, None] == _LEG_IDS  # foot is geom1 -> reaction
        self.forces_in_world[:] = on2.T @ f_world - on1.T @ f_world
        self.in_contact[:] = on2.any(axis=0) | on1.any(axis=0)
