"""What Foxglove's 3D panel draws of a run, as ``foxglove-sdk`` messages (protobuf well-known schemas):

* :func:`body_transforms` -> ``foxglove.FrameTransforms``: world -> ``trunk`` -> every link body of the plant
  (parent -> child, the MuJoCo body tree), from the recorded plant state (``qpos`` rows) by ``mj_kinematics``;
* :func:`robot_scene` -> ``foxglove.SceneUpdate``: the plant's collision geometry (MuJoCo geoms of the robot
  bodies: boxes, spheres, cylinders; a capsule = a cylinder and two spheres) as entities locked to their
  body frames;
* :func:`terrain_scene` -> ``foxglove.SceneUpdate``: the world as the scenario's
  :class:`taslel_bench.terrain.terrain.Terrain` describes it (floor, friction strips coloured by mu, logs,
  boxes; a part of another kind is drawn from the MuJoCo geoms it added);
* :func:`contact_scene` -> ``foxglove.SceneUpdate`` per tick: the plant's contact force (MuJoCo) and the
  filter's lambda at each foot as arrows, and the swing feet's barrier state (a sphere coloured by the
  smallest barrier value h, a line of length h below the foot; the values in the entity's metadata).

Frames: ``world`` (z up) and the MuJoCo body names; units m, N.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np
from foxglove import messages as fm

from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.parts import Box, FrictionStrips, Log, Plane
from taslel_bench.terrain.terrain import Terrain

WORLD_FRAME = "world"
FORCE_SCALE_M_PER_N = 0.004  # [m/N] arrow length per newton (60 N of a stance foot -> 0.24 m)
FLOOR_EXTENT_X_M = (-3.0, 15.0)  # [m] the drawn part of an infinite floor (the path of a 10 s run)
FLOOR_HALF_WIDTH_M = 3.0  # [m]
FLOOR_THICKNESS_M = 0.01  # [m] drawn below z = 0
PLANT_FORCE_RGBA = (0.15, 0.45, 0.95, 1.0)  # MuJoCo contact force
FILTER_FORCE_RGBA = (1.0, 0.55, 0.1, 0.9)  # the filter's lambda
LOG_RGBA = (0.55, 0.4, 0.25, 1.0)
ROBOT_RGBA = (0.75, 0.75, 0.78, 1.0)
FOOT_RGBA = (0.2, 0.2, 0.2, 1.0)
BARRIER_MARGIN_M = 0.01  # [m] h below this: amber; below 0: red


# ------------------------------------------------------------------------------------------ quaternions
def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw],
                    axis=-1)  # fmt: skip


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions (w, x, y, z)."""
    qv = np.concatenate([np.zeros((*v.shape[:-1], 1)), v], axis=-1)
    return quat_multiply(quat_multiply(q, qv), quat_conjugate(q))[..., 1:]


def quat_from_x_to(direction: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of the shortest rotation taking +x to the unit vector ``direction`` (3,)."""
    x = np.array([1.0, 0.0, 0.0])
    c = float(np.dot(x, direction))
    if c < -1.0 + 1e-9:
        return np.array([0.0, 0.0, 0.0, 1.0])  # half turn about z
    axis = np.cross(x, direction)
    q = np.array([1.0 + c, *axis])
    return q / np.linalg.norm(q)


def _pose(pos, quat_wxyz) -> fm.Pose:
    w, x, y, z = (float(v) for v in quat_wxyz)
    return fm.Pose(position=fm.Vector3(x=float(pos[0]), y=float(pos[1]), z=float(pos[2])),
                   orientation=fm.Quaternion(x=x, y=y, z=z, w=w))  # fmt: skip


def _color(rgba) -> fm.Color:
    r, g, b, a = (float(v) for v in rgba)
    return fm.Color(r=r, g=g, b=b, a=a)


def timestamp(ns: int) -> fm.Timestamp:
    return fm.Timestamp(sec=int(ns // 1_000_000_000), nsec=int(ns % 1_000_000_000))


_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
_Z_TO_Y = np.array([math.cos(-math.pi / 4), math.sin(-math.pi / 4), 0.0, 0.0])  # rotation about x by -90 deg


# ------------------------------------------------------------------------------------------- transforms
class BodyTree:
    """The plant's robot bodies (the tree rooted at the trunk) and their parents, and the world poses of a
    recorded state by ``mj_kinematics`` on a private ``MjData``."""

    def __init__(self, m: mujoco.MjModel) -> None:
        self.m, self._d = m, mujoco.MjData(m)
        trunk = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
        self.ids = [b for b in range(1, m.nbody) if m.body_rootid[b] == trunk]
        self.names = [m.body(b).name for b in self.ids]
        self.parents = [m.body_parentid[b] for b in self.ids]
        self.parent_names = [WORLD_FRAME if p == 0 else m.body(p).name for p in self.parents]

    def relative_poses(self, qpos_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, B, 3) positions [m] and (n, B, 4) quaternions (w, x, y, z) of every robot body in its parent's
        frame (the trunk in the world) for each row of ``qpos_rows`` (n, nq)."""
        n, ids = len(qpos_rows), np.asarray(self.ids)
        xpos, xquat = np.empty((n, self.m.nbody, 3)), np.empty((n, self.m.nbody, 4))
        for k, qpos in enumerate(qpos_rows):
            self._d.qpos[:] = qpos
            mujoco.mj_kinematics(self.m, self._d)
            xpos[k], xquat[k] = self._d.xpos, self._d.xquat
        parents = np.asarray(self.parents)
        q_parent_inv = quat_conjugate(xquat[:, parents])
        pos = quat_rotate(q_parent_inv, xpos[:, ids] - xpos[:, parents])
        return pos, quat_multiply(q_parent_inv, xquat[:, ids])


def body_transforms(tree: BodyTree, stamp_ns: int, pos: np.ndarray, quat: np.ndarray) -> fm.FrameTransforms:
    """One tick's ``FrameTransforms`` (B,3)/(B,4) from :meth:`BodyTree.relative_poses`."""
    ts = timestamp(stamp_ns)
    return fm.FrameTransforms(transforms=[
        fm.FrameTransform(timestamp=ts, parent_frame_id=parent, child_frame_id=child,
                          translation=fm.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                          rotation=fm.Quaternion(w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3])))
        for parent, child, p, q in zip(tree.parent_names, tree.names, pos, quat, strict=True)
    ])  # fmt: skip


# ------------------------------------------------------------------------------------------ primitives
class Primitives:
    """The primitive lists of one scene entity."""

    def __init__(self) -> None:
        self.cubes: list = []
        self.spheres: list = []
        self.cylinders: list = []
        self.arrows: list = []
        self.lines: list = []

    def box(self, pos, quat, half_size, rgba) -> None:
        size = fm.Vector3(x=2.0 * half_size[0], y=2.0 * half_size[1], z=2.0 * half_size[2])
        self.cubes.append(fm.CubePrimitive(pose=_pose(pos, quat), size=size, color=_color(rgba)))

    def sphere(self, pos, radius, rgba) -> None:
        d = 2.0 * float(radius)
        self.spheres.append(fm.SpherePrimitive(pose=_pose(pos, _IDENTITY), size=fm.Vector3(x=d, y=d, z=d),
                                               color=_color(rgba)))  # fmt: skip

    def cylinder(self, pos, quat, radius, half_length, rgba) -> None:
        """A cylinder along its local z (MuJoCo's convention, and Foxglove's)."""
        d = 2.0 * float(radius)
        size = fm.Vector3(x=d, y=d, z=2.0 * float(half_length))
        self.cylinders.append(fm.CylinderPrimitive(pose=_pose(pos, quat), size=size, bottom_scale=1.0,
                                                   top_scale=1.0, color=_color(rgba)))  # fmt: skip

    def capsule(self, pos, quat, radius, half_length, rgba) -> None:
        self.cylinder(pos, quat, radius, half_length, rgba)
        axis = quat_rotate(np.asarray(quat, float), np.array([0.0, 0.0, float(half_length)]))
        for end in (np.asarray(pos) + axis, np.asarray(pos) - axis):
            self.sphere(end, radius, rgba)

    def mj_geom(self, m: mujoco.MjModel, g: int, rgba=None) -> bool:
        """Geom ``g`` of the model in its body's frame; False for a type not drawn (planes, meshes, ...)."""
        kind, size = m.geom_type[g], m.geom_size[g]
        pos, quat = m.geom_pos[g], m.geom_quat[g]
        rgba = m.geom_rgba[g] if rgba is None else rgba
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            self.box(pos, quat, size, rgba)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            self.sphere(pos, size[0], rgba)
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            self.cylinder(pos, quat, size[0], size[1], rgba)
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            self.capsule(pos, quat, size[0], size[1], rgba)
        else:
            return False
        return True

    def entity(self, entity_id: str, frame_id: str, stamp_ns: int, *, frame_locked: bool = False,
               metadata: dict[str, str] | None = None) -> fm.SceneEntity:  # fmt: skip
        return fm.SceneEntity(
            timestamp=timestamp(stamp_ns), frame_id=frame_id, id=entity_id, frame_locked=frame_locked,
            metadata=[fm.KeyValuePair(key=k, value=v) for k, v in (metadata or {}).items()],
            cubes=self.cubes, spheres=self.spheres, cylinders=self.cylinders, arrows=self.arrows, lines=self.lines,
        )  # fmt: skip


# --------------------------------------------------------------------------------------------- scenes
def robot_scene(m: mujoco.MjModel, tree: BodyTree, stamp_ns: int) -> fm.SceneUpdate:
    """The robot's collision geometry: one entity per body (id = body name), locked to the body frame."""
    entities = []
    for body, name in zip(tree.ids, tree.names, strict=True):
        prims = Primitives()
        for g in range(m.body_geomadr[body], m.body_geomadr[body] + m.body_geomnum[body]):
            is_foot = m.geom(g).name in quad.FOOT_FRAMES
            prims.mj_geom(m, g, FOOT_RGBA if is_foot else ROBOT_RGBA)
        entities.append(prims.entity(name, name, stamp_ns, frame_locked=True))
    return fm.SceneUpdate(entities=entities)


def friction_rgba(mu: float) -> tuple[float, float, float, float]:
    """Floor colour by friction: grey at mu >= 1, icy blue towards mu = 0."""
    s = min(max(float(mu), 0.0), 1.0)
    return (0.45 + 0.2 * s, 0.6 + 0.05 * s, 0.9 - 0.3 * s, 1.0)


def _floor(prims: Primitives, x0: float, x1: float, mu: float) -> None:
    centre = ((x0 + x1) / 2.0, 0.0, -FLOOR_THICKNESS_M / 2.0)
    prims.box(centre, _IDENTITY, ((x1 - x0) / 2.0, FLOOR_HALF_WIDTH_M, FLOOR_THICKNESS_M / 2.0), friction_rgba(mu))


def _part_primitives(part, prims: Primitives) -> bool:
    """The primitives of a terrain part of a known kind (world frame); False for another kind."""
    if isinstance(part, Plane):
        _floor(prims, *FLOOR_EXTENT_X_M, part.friction)
    elif isinstance(part, FrictionStrips):
        edges = [FLOOR_EXTENT_X_M[0], *part.edges_x_m, FLOOR_EXTENT_X_M[1]]
        for x0, x1, mu in zip(edges[:-1], edges[1:], part.frictions, strict=True):
            _floor(prims, x0, x1, mu)
    elif isinstance(part, Log):
        prims.capsule((part.x_m, part.y_m, part.z_m), _Z_TO_Y, part.radius_m, part.half_width_m, LOG_RGBA)
    elif isinstance(part, Box):
        prims.box(part.centre_m, _IDENTITY, part.half_size_m, friction_rgba(part.friction))
    else:
        return False
    return True


def terrain_scene(terrain: Terrain, m: mujoco.MjModel, stamp_ns: int) -> fm.SceneUpdate:
    """The terrain, one entity per part (id ``terrain_<i>``, world frame; metadata: kind, friction). A part
    of another kind is drawn from the plant's geoms named as :meth:`Terrain.build` names it."""
    entities, n_ground, n_obstacle = [], 0, 0
    for i, part in enumerate(terrain.parts):
        prims = Primitives()
        if part.role == "obstacle":
            geom_name, n_obstacle = f"obstacles_{n_obstacle}", n_obstacle + 1
        else:
            geom_name, n_ground = f"terrain_{n_ground}", n_ground + 1
        if not _part_primitives(part, prims):
            _mj_static_geoms(m, geom_name, prims)
        meta = {"kind": type(part).__name__, "role": str(part.role),
                "friction": str(getattr(part, "friction", getattr(part, "frictions", "")))}  # fmt: skip
        entities.append(prims.entity(f"terrain_{i}", WORLD_FRAME, stamp_ns, metadata=meta))
    return fm.SceneUpdate(entities=entities)


def _mj_static_geoms(m: mujoco.MjModel, prefix: str, prims: Primitives) -> None:
    """Geoms of static bodies whose name starts with ``prefix`` (in world coordinates: their bodies do not
    move, so the body pose is the model's)."""
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    for g in range(m.ngeom):
        if not m.geom(g).name.startswith(prefix) or m.body_rootid[m.geom_bodyid[g]] != m.geom_bodyid[g]:
            continue
        kind, size, rgba = m.geom_type[g], m.geom_size[g], m.geom_rgba[g]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.geom_xmat[g])
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            prims.box(d.geom_xpos[g], quat, size, rgba)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            prims.sphere(d.geom_xpos[g], size[0], rgba)
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            prims.cylinder(d.geom_xpos[g], quat, size[0], size[1], rgba)
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            prims.capsule(d.geom_xpos[g], quat, size[0], size[1], rgba)


def _force_arrow(prims: Primitives, tail_w: np.ndarray, force_w: np.ndarray, rgba) -> None:
    """An arrow from ``tail_w`` [m] along ``force_w`` [N], FORCE_SCALE_M_PER_N long per newton."""
    norm = float(np.linalg.norm(force_w))
    if not np.isfinite(norm) or norm < 1.0:  # below 1 N: no load (the metrics' loaded threshold)
        return
    length = norm * FORCE_SCALE_M_PER_N
    head = min(0.04, 0.4 * length)
    prims.arrows.append(fm.ArrowPrimitive(pose=_pose(tail_w, quat_from_x_to(force_w / norm)),
                                          shaft_length=length - head, shaft_diameter=0.008, head_length=head,
                                          head_diameter=0.02, color=_color(rgba)))  # fmt: skip


def barrier_rgba(h_m: float) -> tuple[float, float, float, float]:
    if h_m < 0.0:
        return (0.9, 0.1, 0.1, 0.6)
    return (1.0, 0.75, 0.0, 0.5) if h_m < BARRIER_MARGIN_M else (0.1, 0.8, 0.2, 0.35)


def contact_scene(stamp_ns: int, t_s: float, foot_w: np.ndarray, grf_plant_w: np.ndarray,
                  grf_filter_w: np.ndarray, barrier_h: dict[str, np.ndarray], foot_radius_m: float
                  ) -> fm.SceneUpdate:  # fmt: skip
    """One tick: per foot (legs in :data:`quad.LEGS` order) the plant's and the filter's force arrows from the
    sphere's bottom point (``foot_w`` (4, 3) sphere centres [m], forces (4, 3) [N], world axes) and, for a
    swing foot with a barrier row, a sphere coloured by the smallest h [m] over ``barrier_h`` (name -> (4,))
    and a line from the sphere's bottom down by that h (``foot_radius_m`` [m]: the plant's foot spheres). The update
    first deletes the previous tick's entities of the topic."""
    entities = []
    for i, leg in enumerate(quad.LEGS):
        prims = Primitives()
        bottom = foot_w[i] - np.array([0.0, 0.0, foot_radius_m])
        _force_arrow(prims, bottom, grf_plant_w[i], PLANT_FORCE_RGBA)
        _force_arrow(prims, bottom, grf_filter_w[i], FILTER_FORCE_RGBA)
        meta = {"t_s": f"{t_s:.3f}",
                **{f"plant_{ax}_n": f"{grf_plant_w[i, j]:.2f}" for j, ax in enumerate("xyz")},
                **{f"filter_{ax}_n": f"{grf_filter_w[i, j]:.2f}" for j, ax in enumerate("xyz")}}  # fmt: skip
        h = {name: float(v[i]) for name, v in barrier_h.items() if np.isfinite(v[i])}
        if h:
            h_min = min(h.values())
            prims.sphere(foot_w[i], foot_radius_m + 0.01, barrier_rgba(h_min))
            end = bottom - np.array([0.0, 0.0, h_min])
            prims.lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip,
                                                pose=_pose((0, 0, 0), _IDENTITY), thickness=0.004,
                                                scale_invariant=False,
                                                points=[fm.Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))
                                                        for p in (bottom, end)],
                                                color=_color(barrier_rgba(h_min))))  # fmt: skip
            meta.update({f"{name}_h_m": f"{v:.4f}" for name, v in h.items()})
        entities.append(prims.entity(f"foot_{leg}", WORLD_FRAME, stamp_ns, metadata=meta))
    deletion = fm.SceneEntityDeletion(timestamp=timestamp(stamp_ns), type=fm.SceneEntityDeletionType.All, id="")
    return fm.SceneUpdate(deletions=[deletion], entities=entities)


def schema_names(messages: Sequence[type]) -> list[str]:
    """The protobuf schema names (``foxglove.FrameTransforms``, ...) of foxglove message classes."""
    return [cls.get_schema().name for cls in messages]
