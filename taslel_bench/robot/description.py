"""A robot is a value: :class:`RobotDescription`, built from ``conf/robot/<name>.yaml`` and the robot's URDF.

The YAML names the robot's parts (its URDF, trunk link, leg prefixes, joint and foot names, in the core's leg
order of :mod:`taslel_bench.robot.quadruped`) and the values a URDF does not carry well (stand height, fall rule,
shin capsule, torque limits where the URDF's are not the motors'). Everything geometric is read from the URDF with
Pinocchio at the zero configuration: hip positions, the leg chain's offsets and lengths, joint axis signs, the foot
spheres, the mass. So adding a quadruped from ``example-robot-data`` is one YAML file.

Frames and units: positions in the trunk frame [m] (the trunk link's frame, the free flyer's), angles [rad],
torques [N·m], velocities [rad/s], mass [kg].
"""

from __future__ import annotations

import importlib.metadata
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.fields import ConfigError, plain_dict

if TYPE_CHECKING:
    from xml.etree.ElementTree import Element

ROBOT_CONFIG_DIR = Path(__file__).resolve().parents[2] / "conf" / "robot"
AXIS_TOL = 1e-6  # [-] a joint axis must be +-x (hip) or +-y (thigh, calf) of the trunk to this tolerance


@dataclass(frozen=True)
class LegGeometry:
    """One leg as a roll-pitch-pitch chain, read from the URDF at the zero configuration (trunk axes [m]).

    foot centre (hip frame) = Rx(s_hip q_hip) [d_hip_thigh + Ry(s_thigh q_thigh) (d_thigh_calf + Ry(s_calf q_calf)
    d_calf_foot)]; in the x-z plane the two pitch links are written as lengths and angles from straight down:
    d = Ry(angle) (0, 0, -length) for ``thigh`` (thigh joint -> calf joint) and ``calf`` (calf joint -> foot
    centre). ``lateral_m`` is the sum of the three offsets' y: the foot's distance from the hip's roll plane."""

    hip_in_trunk_m: tuple[float, float, float]  # hip (abduction) joint position
    hip_to_thigh_m: tuple[float, float, float]  # hip joint -> thigh joint
    lateral_m: float  # [m] y of hip->thigh + thigh->calf + calf->foot (signed: + left)
    thigh_length_m: float
    thigh_angle_rad: float  # angle of thigh joint -> calf joint from straight down, about +y
    calf_length_m: float
    calf_angle_rad: float  # angle of calf joint -> foot centre from straight down, about +y
    axis_signs: tuple[float, float, float]  # each joint's axis: +-x (hip), +-y (thigh, calf)
    knee_sign: float  # -1: the knee bends backwards (calf angle negative at the stand, A1, Go1); +1 forwards


@dataclass(frozen=True)
class RobotDescription:
    """Everything the core knows about one robot; see the module doc and ``conf/robot/<name>.yaml``."""

    name: str
    urdf_path: Path
    trunk_link: str  # the URDF link carrying the free joint
    joint_names: tuple[str, ...]  # the robot's 12 joint names, core order (FL, FR, RL, RR; hip, thigh, calf)
    foot_frames: tuple[str, ...]  # the robot's 4 foot links (URDF), core leg order
    foot_radius_m: float  # [m] radius of the foot collision sphere
    foot_centre_in_foot_m: tuple[tuple[float, float, float], ...]  # [m] sphere centre in each foot link's frame
    foot_from_urdf: bool  # True: the URDF has the sphere; False: the plant adds it (the URDF's is a mesh)
    torque_limit_nm: tuple[float, ...]  # [N·m] per joint, core order
    velocity_limit_radps: tuple[float, ...]  # [rad/s] per joint, core order
    shin_radius_m: float  # [m] radius of the calf capsule the leg barriers and foothold checks guard
    shin_axis_fraction: float  # [-] the guarded shin: knee -> this fraction of the way to the foot centre
    stand_height_m: float  # [m] hip joint -> foot centre height in the stand and in stance
    fall_height_m: float  # [m] trunk origin below this ends an episode as a fall
    fall_tilt_deg: float  # [deg] trunk tilt beyond this ends an episode as a fall
    init_joint_noise_rad: float  # [rad] std of the seeded initial joint perturbation
    init_base_vel_noise_mps: float  # [m/s] std of the seeded initial trunk velocity
    mass_kg: float  # [kg] the URDF's total mass
    legs: tuple[LegGeometry, ...]  # core leg order

    @property
    def leg_length_m(self) -> float:
        """[m] mean thigh + calf length: the scale of steps, swing heights and gains."""
        return float(np.mean([g.thigh_length_m + g.calf_length_m for g in self.legs]))

    @property
    def torque_limits(self) -> np.ndarray:
        """(12,) [N·m] per joint, core order (a fresh array)."""
        return np.array(self.torque_limit_nm, dtype=float)

    @property
    def hip_positions_in_trunk(self) -> np.ndarray:
        """(4, 3) [m] hip (abduction) joints in the trunk frame, core leg order."""
        return np.array([g.hip_in_trunk_m for g in self.legs], dtype=float)


# ----------------------------------------------------------------------------------------------- loading


def robot_config_path(name: str) -> Path:
    """``conf/robot/<name>.yaml``; a clear error listing the shipped robots."""
    path = ROBOT_CONFIG_DIR / f"{name}.yaml"
    if not path.is_file():
        shipped = sorted(p.stem for p in ROBOT_CONFIG_DIR.glob("*.yaml"))
        raise ConfigError(f"robot={name!r}: no {path}; shipped robots: {', '.join(shipped)}")
    return path


# the keys a robot file may leave out, with the values they then take (most quadrupeds' names and noise levels)
ROBOT_DEFAULTS: dict[str, Any] = {
    "joint_roles": list(quad.JOINT_ROLES),  # hip, thigh, calf
    "knee_forward": [False] * quad.N_LEGS,  # every knee bends backwards
    "foot_radius_m": None,  # [m] the foot link's collision sphere in the URDF
    "torque_limit_nm": None,  # [N·m] the URDF's effort limits
    "velocity_limit_radps": None,  # [rad/s] the URDF's velocity limits
    "shin_axis_fraction": 0.7,  # [-] guarded shin: knee -> this fraction of the way to the foot centre
    "fall_tilt_deg": 57.0,  # [deg]
    "init_joint_noise_rad": 0.02,  # [rad]
    "init_base_vel_noise_mps": 0.05,  # [m/s]
}
DEFAULT_ROBOT = "a1"  # conf/config.yaml's default robot, for objects built without a config (tests, studies)


def default_robot() -> RobotDescription:
    """The default robot's description (:data:`DEFAULT_ROBOT`)."""
    return load_robot(DEFAULT_ROBOT)


@lru_cache(maxsize=16)
def load_robot(name: str) -> RobotDescription:
    """The description of a shipped robot by name (``conf/robot/<name>.yaml``)."""
    from omegaconf import OmegaConf

    path = robot_config_path(name)
    return describe_robot(plain_dict(OmegaConf.load(path), str(path)))


def complete_robot_node(node: Mapping[str, Any]) -> dict[str, Any]:
    """A run folder's ``robot`` node as :func:`describe_robot` reads it: a config written before robots were
    described (no ``name``) was an A1 run, so the A1's file completes it under the run's own values."""
    if "name" in node:
        return dict(node)
    from omegaconf import OmegaConf

    a1_path = robot_config_path("a1")
    a1 = plain_dict(OmegaConf.load(a1_path), str(a1_path))
    return {**a1, **node}


def describe_robot(node: Mapping[str, Any], where: str = "robot") -> RobotDescription:
    """The :class:`RobotDescription` of a ``robot`` config node (a mapping; see ``conf/robot/a1.yaml``).

    Raises :class:`ConfigError` naming the field, the value and what is valid."""
    node = {**ROBOT_DEFAULTS, **node}
    return _describe(_hashable(node), where)


def _hashable(node: Any) -> Any:
    if isinstance(node, Mapping):
        return tuple(sorted((str(k), _hashable(v)) for k, v in node.items()))
    if isinstance(node, (list, tuple)):
        return tuple(_hashable(v) for v in node)
    return node


@lru_cache(maxsize=32)
def _describe(frozen: tuple, where: str) -> RobotDescription:
    node = {k: _thaw(v) for k, v in frozen}
    name = str(node.get("name") or "")
    if not name:
        raise ConfigError(f"{where}.name: missing; the robot's short name (e.g. a1)")
    urdf = resolve_urdf(node.get("urdf"), f"{where}.urdf")
    legs = _names(node.get("legs"), 4, f"{where}.legs", "the robot's 4 leg prefixes, core order (FL, FR, RL, RR)")
    roles = _names(node["joint_roles"], 3, f"{where}.joint_roles",
                   "the robot's words for the hip (abduction), thigh (hip flexion) and calf (knee) joints")
    joints = tuple(_pattern(node.get("joints"), f"{where}.joints", leg=leg, joint=role)
                   for leg in legs for role in roles)
    feet = tuple(_pattern(node.get("feet"), f"{where}.feet", leg=leg, joint="") for leg in legs)
    model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    _check_names(model, joints, feet, str(node.get("trunk_link")), urdf, where)
    foot_radius, centres, from_urdf = _feet(urdf, feet, node.get("foot_radius_m"), where)
    knees = node["knee_forward"]
    if not isinstance(knees, list) or len(knees) != quad.N_LEGS or not all(isinstance(k, bool) for k in knees):
        raise ConfigError(f"{where}.knee_forward={knees!r}: 4 booleans, core leg order (true: the knee points "
                          "forwards, as ANYmal's hind legs)")
    geometry = tuple(
        replace(_leg_geometry(model, joints[3 * i: 3 * i + 3], feet[i], centres[i], f"{where}.legs[{i}]"),
                knee_sign=1.0 if knees[i] else -1.0)
        for i in range(quad.N_LEGS))
    return RobotDescription(
        name=name,
        urdf_path=urdf,
        trunk_link=str(node["trunk_link"]),
        joint_names=joints,
        foot_frames=feet,
        foot_radius_m=foot_radius,
        foot_centre_in_foot_m=centres,
        foot_from_urdf=from_urdf,
        torque_limit_nm=_per_joint(node.get("torque_limit_nm"), model, joints, "effortLimit",
                                   f"{where}.torque_limit_nm"),
        velocity_limit_radps=_per_joint(node.get("velocity_limit_radps"), model, joints, "velocityLimit",
                                        f"{where}.velocity_limit_radps"),
        shin_radius_m=_positive(node, "shin_radius_m", where),
        shin_axis_fraction=_positive(node, "shin_axis_fraction", where),
        stand_height_m=_positive(node, "stand_height_m", where),
        fall_height_m=_positive(node, "fall_height_m", where),
        fall_tilt_deg=_positive(node, "fall_tilt_deg", where),
        init_joint_noise_rad=float(node["init_joint_noise_rad"]),
        init_base_vel_noise_mps=float(node["init_base_vel_noise_mps"]),
        mass_kg=float(pin.computeTotalMass(model)),
        legs=geometry,
    )


def _thaw(v: Any) -> Any:
    if isinstance(v, tuple) and v and all(isinstance(x, tuple) and len(x) == 2 and isinstance(x[0], str)
                                          for x in v):
        return {k: _thaw(x) for k, x in v}
    if isinstance(v, tuple):
        return [_thaw(x) for x in v]
    return v


def resolve_urdf(value: Any, field: str) -> Path:
    """A URDF given as a file path or as ``<distribution>:<path inside it>`` (``example-robot-data:robots/...``;
    data-only wheels such as example-robot-data have no module to import, so the file is found through the
    distribution's file list)."""
    if not value:
        raise ConfigError(f"{field}: missing; a URDF path or example-robot-data:robots/<robot>/.../<file>.urdf")
    text = str(value)
    dist_name, sep, inner = text.partition(":")
    if sep and not Path(text).is_file() and "/" not in dist_name:
        return _distribution_file(dist_name, inner, field)
    path = Path(text).expanduser()
    if not path.is_file():
        raise ConfigError(f"{field}={text!r}: no such file")
    return path.resolve()


@lru_cache(maxsize=16)
def _distribution_file(dist_name: str, inner: str, field: str) -> Path:
    try:
        dist = importlib.metadata.distribution(dist_name)
    except importlib.metadata.PackageNotFoundError:
        raise ConfigError(f"{field}: the distribution {dist_name!r} is not installed (pip install {dist_name})") \
            from None
    for f in dist.files or ():
        if str(f).endswith(inner):
            path = Path(str(dist.locate_file(f)))  # typed as the abstract SimplePath; a pathlib.Path here
            if path.is_file():
                return path.resolve()
    raise ConfigError(f"{field}: {dist_name} is installed but has no file ending in {inner!r}")


def _names(value: Any, n: int, field: str, meaning: str) -> tuple[str, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n or not all(isinstance(v, str) and v for v in value):
        raise ConfigError(f"{field}={value!r}: must be a list of {n} names: {meaning}")
    return tuple(value)


def _pattern(value: Any, field: str, leg: str, joint: str) -> str:
    if not isinstance(value, str) or "{leg}" not in value:
        raise ConfigError(f"{field}={value!r}: must be a name pattern with {{leg}} (and {{joint}} for joints), "
                          "e.g. '{leg}_{joint}_joint'")
    return value.format(leg=leg, joint=joint)


def _check_names(model: pin.Model, joints: tuple[str, ...], feet: tuple[str, ...], trunk: str, urdf: Path,
                 where: str) -> None:
    have = set(model.names)
    missing = [j for j in joints if j not in have]
    if missing:
        raise ConfigError(f"{where}.joints: {urdf} has no joint {', '.join(missing)}; its joints: "
                          f"{', '.join(list(model.names)[2:])}")
    frames = {f.name for f in model.frames}
    for field, names in ((f"{where}.feet", feet), (f"{where}.trunk_link", (trunk,))):
        absent = [f for f in names if f not in frames]
        if absent:
            raise ConfigError(f"{field}: {urdf} has no link {', '.join(absent)}")
    if model.nq != quad.NQ or model.nv != quad.NV:
        raise ConfigError(f"{where}.urdf: {urdf} has {model.nv - 6} actuated joints; the core's quadruped has "
                          f"{quad.N_JOINTS} (three per leg)")


def _per_joint(value: Any, model: pin.Model, joints: tuple[str, ...], urdf_attr: str, field: str
               ) -> tuple[float, ...]:
    """null: the URDF's limits; one number: all 12; 12 numbers: core order. Positive, finite."""
    if value is None:
        limits = getattr(model, urdf_attr)
        out = [float(limits[model.joints[model.getJointId(j)].idx_v]) for j in joints]
    elif isinstance(value, (int, float)):
        out = [float(value)] * quad.N_JOINTS
    elif isinstance(value, (list, tuple)) and len(value) == quad.N_JOINTS:
        out = [float(v) for v in value]
    else:
        raise ConfigError(f"{field}={value!r}: null (the URDF's), one number, or {quad.N_JOINTS} numbers in "
                          "core order")
    if not all(math.isfinite(v) and v > 0 for v in out):
        raise ConfigError(f"{field}={out!r}: every value must be positive and finite")
    return tuple(out)


def _positive(node: Mapping[str, Any], key: str, where: str) -> float:
    value = node.get(key)
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{where}.{key}={value!r}: must be a positive number")
    return float(value)


def _feet(urdf: Path, feet: tuple[str, ...], radius: Any, where: str
          ) -> tuple[float, tuple[tuple[float, float, float], ...], bool]:
    """(radius, sphere centre in each foot link's frame, whether the URDF has the sphere). With
    ``foot_radius_m`` null, each foot link must carry one collision sphere; with a number, the plant puts a sphere
    of that radius at the foot link's origin in place of the link's collision geometry."""
    import xml.etree.ElementTree as ET

    links = {link.get("name"): link for link in ET.parse(urdf).getroot().iter("link")}
    if radius is not None:
        if not isinstance(radius, (int, float)) or radius <= 0:
            raise ConfigError(f"{where}.foot_radius_m={radius!r}: null (the URDF's foot sphere) or a positive "
                              "number [m]")
        return float(radius), tuple((0.0, 0.0, 0.0) for _ in feet), False
    radii, centres = [], []
    for foot in feet:
        spheres = [(c, sphere) for c in links[foot].findall("collision")
                   if (sphere := c.find("geometry/sphere")) is not None]
        if len(spheres) != 1:
            raise ConfigError(f"{where}.foot_radius_m: null needs one collision sphere on {foot} in {urdf} "
                              f"(found {len(spheres)}); give the radius to use instead")
        collision, sphere = spheres[0]
        origin = collision.find("origin")
        xyz = [float(x) for x in origin.get("xyz", "0 0 0").split()] if origin is not None else [0.0] * 3
        radius_text = sphere.get("radius")
        if radius_text is None:
            raise ConfigError(f"{where}.foot_radius_m: the collision sphere of {foot} in {urdf} has no radius")
        radii.append(float(radius_text))
        centres.append((xyz[0], xyz[1], xyz[2]))
    if max(radii) - min(radii) > 1e-12:
        raise ConfigError(f"{where}: the foot spheres of {urdf} differ in radius ({radii}); the core needs one")
    return radii[0], tuple(centres), True


def _leg_geometry(model: pin.Model, joints: Sequence[str], foot: str, centre: Sequence[float], where: str
                  ) -> LegGeometry:
    """One leg's chain (:class:`LegGeometry`) from Pinocchio's placements at the neutral configuration."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    trunk = data.oMi[1]  # the free flyer: the trunk frame
    ids = [model.getJointId(j) for j in joints]
    pos = [trunk.actInv(data.oMi[i]).translation for i in ids]
    foot_frame = trunk.actInv(data.oMf[model.getFrameId(foot)])
    foot_centre = foot_frame.act(np.asarray(centre, dtype=float))
    signs = []
    for k, (i, want) in enumerate(zip(ids, (0, 1, 1), strict=True)):
        axis = trunk.rotation.T @ data.oMi[i].rotation @ _joint_axis(model, i, joints[k], where)
        if abs(abs(axis[want]) - 1.0) > AXIS_TOL:
            raise ConfigError(f"{where}: joint {joints[k]} turns about {np.round(axis, 4).tolist()} (trunk axes); "
                              f"the core's leg needs {'x' if want == 0 else 'y'} for its {quad.JOINT_ROLES[k]}")
        signs.append(float(np.sign(axis[want])))
    d1, d2, d3 = pos[1] - pos[0], pos[2] - pos[1], foot_centre - pos[2]
    thigh_len, thigh_ang = math.hypot(d2[0], d2[2]), math.atan2(-d2[0], -d2[2])
    calf_len, calf_ang = math.hypot(d3[0], d3[2]), math.atan2(-d3[0], -d3[2])
    return LegGeometry(
        hip_in_trunk_m=_tuple3(pos[0]),
        hip_to_thigh_m=_tuple3(d1),
        lateral_m=float(d1[1] + d2[1] + d3[1]),
        thigh_length_m=float(thigh_len),
        thigh_angle_rad=float(thigh_ang),
        calf_length_m=float(calf_len),
        calf_angle_rad=float(calf_ang),
        axis_signs=(signs[0], signs[1], signs[2]),
        knee_sign=-1.0,  # replaced from the YAML's knee_forward
    )


def _joint_axis(model: pin.Model, joint_id: int, name: str, where: str) -> np.ndarray:
    """The unit axis of a revolute joint in its own frame."""
    j = model.joints[joint_id]
    short = j.shortname()
    if short.startswith("JointModelR") and short[-1] in "XYZ" and "Unaligned" not in short:
        return np.eye(3)["XYZ".index(short[-1])]
    if "RevoluteUnaligned" in short:
        return np.asarray(j.extract().axis, dtype=float)
    raise ConfigError(f"{where}: joint {name} is a {short}; the core's legs have revolute joints only")


def _tuple3(v: Sequence[float]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


# ------------------------------------------------------------------------------------- Pinocchio model


def pinocchio_model(robot: RobotDescription, urdf: str | Path | None = None) -> pin.Model:
    """The robot's Pinocchio model (free flyer + 12 joints) with its joints in the core order.

    Pinocchio orders a URDF's branches by the name of the joint that starts each one (urdfdom keeps joints in a
    sorted map); where that is not the core's leg order (ANYmal: LF, LH, RF, RH), the branch joints of the
    legs get an ordering prefix in the parsed text (``0_base_LF_HAA``); only those fixed-joint names change.
    ``urdf``: another URDF of the same robot (same names); None: the description's."""
    path = Path(urdf) if urdf is not None else robot.urdf_path
    text, _ = physical_urdf_text(path, robot.trunk_link)
    model = pin.buildModelFromXML(text, pin.JointModelFreeFlyer())
    if tuple(list(model.names)[2:]) != robot.joint_names:
        model = pin.buildModelFromXML(_core_ordered_urdf(text, robot), pin.JointModelFreeFlyer())
    names = tuple(list(model.names)[2:])
    if names != robot.joint_names:
        raise ConfigError(f"robot.urdf: {path}: Pinocchio joint order {list(names)} is not the core order "
                          f"{list(robot.joint_names)}")
    for leg, foot in enumerate(robot.foot_frames):
        centre = np.asarray(robot.foot_centre_in_foot_m[leg], dtype=float)
        if not centre.any():
            continue  # the foot link's frame is the sphere centre (A1, Go1)
        frame = model.frames[model.getFrameId(foot)]
        placement = frame.placement * pin.SE3(np.eye(3), centre)
        model.addFrame(pin.Frame(foot_centre_frame(leg), frame.parentJoint, model.getFrameId(foot), placement,
                                 pin.FrameType.OP_FRAME))
    return model


def foot_centre_frame(leg: int) -> str:
    """Name of the Pinocchio frame :func:`pinocchio_model` adds at leg ``leg``'s foot-sphere centre where the
    foot link's frame is not there (ANYmal: 2.25 cm above it)."""
    return f"{quad.LEGS[leg]}_foot_centre"


def foot_frame(robot: RobotDescription, leg: int) -> str:
    """The Pinocchio frame at leg ``leg``'s foot-sphere centre: the foot link's, or :func:`foot_centre_frame`."""
    return foot_centre_frame(leg) if any(robot.foot_centre_in_foot_m[leg]) else robot.foot_frames[leg]


def physical_urdf_text(path: Path, trunk_link: str) -> tuple[str, list[str]]:
    """The URDF's text as both plant and model use it, and the names of the links it changes:

    * links above ``trunk_link`` (a placeholder root such as Go1's ``base``) lose their inertia: the plant's free
      joint sits on the trunk, so they would be welded to the world there and part of the free body in Pinocchio;
    * a link inertia that is not a physical one (not positive definite, or principal moments A + B < C: Go1's
      placeholder ``base``, ANYmal's camera links; MuJoCo refuses them) becomes isotropic with the same trace."""
    text = Path(path).read_text()
    fixed: list[str] = []
    for link in _links_above(text, trunk_link):
        text, n = re.subn(rf'(<link\s+name="{re.escape(link)}"\s*>(?:(?!</link>).)*?)<inertial>.*?</inertial>',
                          r"\1", text, flags=re.DOTALL)
        fixed += [link] * n

    def fix(match: re.Match) -> str:
        head, inertial = match.group(1), match.group(3)
        values = {k: float(v) for k, v in re.findall(r'(i[xyz]{2})="([^"]+)"', inertial)}
        tensor = np.array([[values.get("ixx", 0), values.get("ixy", 0), values.get("ixz", 0)],
                           [values.get("ixy", 0), values.get("iyy", 0), values.get("iyz", 0)],
                           [values.get("ixz", 0), values.get("iyz", 0), values.get("izz", 0)]])
        moments = np.linalg.eigvalsh(tensor)
        if moments.min() > 0 and moments[0] + moments[1] >= moments[2]:
            return match.group(0)
        fixed.append(match.group(2))
        mean = float(np.trace(tensor)) / 3.0  # isotropic, same trace: a valid inertia of a tiny part
        out = re.sub(r'(i(?:xy|xz|yz))="[^"]+"', r'\1="0"', inertial)
        return head + re.sub(r'(i(?:xx|yy|zz))="[^"]+"', rf'\1="{mean!r}"', out)

    text = re.sub(r'(<link\s+name="([^"]+)"\s*>(?:(?!</link>).)*?)(<inertial>.*?</inertial>)', fix, text,
                  flags=re.DOTALL)
    return text, fixed


def _joint_link(joint: Element, end: str) -> str:
    """The link a URDF joint names in its ``<parent link=...>`` or ``<child link=...>`` (``end``)."""
    element = joint.find(end)
    link = element.get("link") if element is not None else None
    if link is None:
        raise ConfigError(f"URDF joint {joint.get('name')!r}: no <{end} link=...>")
    return link


def _links_above(text: str, link: str) -> list[str]:
    """The links on the path from the URDF's root to ``link`` (exclusive)."""
    import xml.etree.ElementTree as ET

    parent = {_joint_link(j, "child"): _joint_link(j, "parent") for j in ET.fromstring(text).findall("joint")}
    out = []
    while link in parent:
        link = parent[link]
        out.append(link)
    return out


def _core_ordered_urdf(text: str, robot: RobotDescription) -> str:
    """The URDF text with each leg's branch joint (the joint under the trunk link leading to the leg's hip
    joint) renamed ``<core leg index>_<name>``, so Pinocchio visits the legs in the core order."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(text)
    parent_joint = {_joint_link(j, "child"): j for j in root.findall("joint")}
    for leg in range(quad.N_LEGS):
        joint = next((j for j in root.findall("joint") if j.get("name") == robot.joint_names[3 * leg]), None)
        while joint is not None and _joint_link(joint, "parent") != robot.trunk_link:
            joint = parent_joint.get(_joint_link(joint, "parent"))
        if joint is None:  # not the robot's URDF: the caller names the joint order it finds
            return text
        name = joint.get("name")
        text = text.replace(f'name="{name}"', f'name="{leg}_{name}"', 1)
    return text
