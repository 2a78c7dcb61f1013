"""Fitting another MJCF of the robot (``robot.plant_mjcf``) to the harness: names, actuators, floor, overrides.

The harness finds plant elements by the core's names (:mod:`taslel_bench.robot.quadruped`): joints ``FL_hip_joint``
.. ``RR_calf_joint``, one actuator per joint named like the joint, sphere foot geoms ``FL_foot`` ..
``RR_foot``, the ``trunk`` body, a ``floor`` geom. :func:`adapt` renames a file's elements to those names
(and every reference to them: actuator targets, sensors, equalities, contact pairs and excludes), so the
state bridge, the scenarios and the contact reader work unchanged; turns servo actuators into torque
motors; finds the file's own floor. :func:`apply_overrides` sets the contact and integrator options the
config asks for. Both return a record of what they changed, kept in the compiled model as the custom text
:data:`RECORD_TEXT` (JSON) for the build-time report (:mod:`taslel_bench.plant.comparison`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import mujoco
import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.fields import ConfigError

RECORD_TEXT = "taslel_plant_adapter"  # custom text element holding the adapter's record (JSON)
FLOOR = "floor"
INTEGRATORS = {
    "Euler": mujoco.mjtIntegrator.mjINT_EULER,
    "RK4": mujoco.mjtIntegrator.mjINT_RK4,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
}
CONES = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}
NameMap = Mapping[str, str] | str | None  # {core name: file name}, a "{leg}_{joint}" pattern, or None (same)
_KINDS = ("joints", "actuators", "feet")
_CORE_NAMES = {"joints": quad.JOINT_NAMES, "actuators": quad.JOINT_NAMES, "feet": quad.FOOT_FRAMES}


@dataclass(frozen=True)
class PlantNames:
    """Names of the plant file's elements where they differ from the core's.

    ``joints``, ``actuators``, ``feet``: a mapping {core name: name in the file} (core names not listed keep
    their name), or a pattern with ``{leg}`` (FL, FR, RL, RR) and ``{joint}`` (hip, thigh, calf), e.g.
    ``"{leg}_{joint}"`` for MuJoCo Menagerie's actuators and ``"{leg}"`` for its feet, or None (the core
    names). Actuators are keyed by the core joint name; None finds the one actuator driving each joint,
    whatever its name. ``trunk``: the body of the free joint. ``floor``: a geom of the world body to use as
    the floor (None: the only plane geom of the world body, if any; with none, the harness adds one)."""

    joints: NameMap = None
    actuators: NameMap = None
    feet: NameMap = None
    trunk: str | None = None
    floor: str | None = None

    def file_name(self, kind: str, core: str) -> str:
        """The name in the file of the core element ``core`` of ``kind`` (joints, actuators, feet)."""
        rule = getattr(self, kind)
        if rule is None:
            return core
        if isinstance(rule, str):
            leg, _, rest = core.partition("_")
            return rule.format(leg=leg, joint=rest.split("_")[0])
        return str(rule.get(core, core))


@dataclass(frozen=True)
class PlantOverrides:
    """The plant's contact and integrator settings the config sets (None: keep the file's, or the URDF
    plant's). ``contact_solref`` [timeconst s, dampratio] and ``contact_solimp`` [dmin, dmax, width m,
    midpoint, power] go to the four foot geoms *and* the floor: a contact takes them from the geom of higher
    priority, which is the terrain. ``foot_margin_m`` [m] is the foot geoms' contact margin."""

    integrator: str | None = None  # a key of INTEGRATORS
    cone: str | None = "elliptic"  # a key of CONES
    noslip_iterations: int | None = None
    impratio: float | None = None  # [-] elliptic cone: ratio of frictional to normal impedance
    contact_solref: tuple[float, float] | None = None
    contact_solimp: tuple[float, float, float, float, float] | None = None
    foot_margin_m: float | None = None


def _fmt(values) -> str:
    """Numbers as compact text: ``0.02 1``."""
    return " ".join(f"{float(x):g}" for x in np.atleast_1d(values))


# ------------------------------------------------------------------------------------------- renaming


def rename(
    spec: mujoco.MjSpec, objtype: mujoco.mjtObj, elements: dict[str, Any], new_names: dict[str, str]
) -> None:
    """Give each element (``elements[old] -> element``) its name ``new_names[old]`` -- through unique
    temporary names, so swaps work -- and rewrite the string references of that type to it."""
    for i, element in enumerate(elements.values()):
        element.name = f"__taslel_rename_{objtype.name}_{i}"
    for old, element in elements.items():
        try:
            element.name = new_names[old]
        except ValueError as exc:
            raise ValueError(
                f"renaming {objtype.name} {old!r} to {new_names[old]!r}: another element of the file "
                f"already has that name"
            ) from exc
    mapping = {old: new_names[old] for old in elements}

    def swap(name: str) -> str:
        return mapping.get(name, name)

    for s in spec.sensors:
        if s.objtype == objtype:
            s.objname = swap(s.objname)
        if s.reftype == objtype:
            s.refname = swap(s.refname)
    if objtype == mujoco.mjtObj.mjOBJ_JOINT:
        for a in spec.actuators:
            if a.trntype in (mujoco.mjtTrn.mjTRN_JOINT, mujoco.mjtTrn.mjTRN_JOINTINPARENT):
                a.target = swap(a.target)
    if objtype in (mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_GEOM):
        for e in spec.equalities:
            if e.objtype == objtype:
                e.name1, e.name2 = swap(e.name1), swap(e.name2)
    if objtype == mujoco.mjtObj.mjOBJ_GEOM:
        for p in spec.pairs:
            p.geomname1, p.geomname2 = swap(p.geomname1), swap(p.geomname2)
    if objtype == mujoco.mjtObj.mjOBJ_BODY:
        for x in spec.excludes:
            x.bodyname1, x.bodyname2 = swap(x.bodyname1), swap(x.bodyname2)
        for a in spec.actuators:
            if a.trntype == mujoco.mjtTrn.mjTRN_BODY:
                a.target = swap(a.target)


def _available(names) -> str:
    names = sorted(n for n in names if n)
    return ", ".join(names[:24]) + (" ..." if len(names) > 24 else "") if names else "(none named)"


# -------------------------------------------------------------------------------------------- adapting


def adapt(
    spec: mujoco.MjSpec, names: PlantNames, torque_limit_nm: tuple[float, ...], where: str
) -> tuple[mujoco.MjsGeom | None, dict]:
    """Rename the file's joints, actuators, foot geoms and trunk to the core's names, make the 12 actuators
    torque motors, find the floor. Returns (the floor geom or None, record). Raises :class:`ConfigError`
    (prefixed ``where``) naming *joints*, *actuators*, *feet*, *trunk* or *floor* for each thing missing."""
    joints = {j.name: j for j in spec.joints if j.name}
    geoms = {g.name: g for g in spec.geoms if g.name}
    bodies = {b.name: b for b in spec.bodies if b.name}
    file_joint = {core: names.file_name("joints", core) for core in quad.JOINT_NAMES}
    feet = {core: names.file_name("feet", core) for core in quad.FOOT_FRAMES}
    trunk = names.trunk or quad.TRUNK_BODY
    unnamed = [g for g in spec.geoms if not g.name and g.type == mujoco.mjtGeom.mjGEOM_SPHERE]
    problems = _joint_problems(file_joint, joints) + _foot_problems(feet, geoms, unnamed)
    problems += _trunk_problems(spec, trunk, bodies)
    chosen, act_problems = _find_actuators(spec, names, file_joint)
    problems += act_problems
    floor, floor_problem = _find_floor(spec, names)
    if floor_problem:
        problems.append(floor_problem)
    if problems:
        raise ConfigError(f"{where} does not fit the controller:\n  " + "\n  ".join(problems))

    # torque motors first (it deletes the other actuators on the leg joints), then the core's names
    record: dict[str, object] = _torque_motors(spec, chosen, torque_limit_nm)
    renamed = _rename_to_core(
        spec,
        [
            ("joints", mujoco.mjtObj.mjOBJ_JOINT, joints, file_joint),
            ("feet", mujoco.mjtObj.mjOBJ_GEOM, geoms, feet),
            ("trunk", mujoco.mjtObj.mjOBJ_BODY, bodies, {quad.TRUNK_BODY: trunk}),
            _actuator_renames(chosen),
        ],
    )
    for core, act in chosen.items():  # unnamed actuators (nothing can refer to them) get the joint's name
        act.name = act.name or core
    old_floor = _name_floor(spec, floor)
    if old_floor is not None:
        renamed["floor"] = old_floor
    if renamed:
        record["renamed"] = renamed
    return floor, record


def _as_core(core: str, file_name: str) -> str:
    """``core``, followed by ``(as 'file name')`` when the file names it differently."""
    return f"{core} (as {file_name!r})" if file_name != core else core


def _joint_problems(file_joint: dict[str, str], joints: dict[str, mujoco.MjsJoint]) -> list[str]:
    """The *joints* problem (as a list of at most one) when a core joint's file name is not in the file."""
    missing = [_as_core(core, f) for core, f in file_joint.items() if f not in joints]
    if not missing:
        return []
    return [
        (
            f"joints: no joint {', '.join(missing)} (robot.plant_names.joints); "
            f"joints in the file: {_available(joints)}"
        )
    ]


def _foot_problems(feet: dict[str, str], geoms: dict[str, mujoco.MjsGeom],
                   unnamed: Sequence[mujoco.MjsGeom] = ()) -> list[str]:  # fmt: skip
    """The *feet* problem (as a list of at most one) when a core foot's file name is not a sphere geom; with
    a hint naming the bodies of unnamed sphere geoms (Menagerie-style files leave the feet unnamed)."""
    sphere = mujoco.mjtGeom.mjGEOM_SPHERE
    bad_feet = [_as_core(core, f) for core, f in feet.items() if f not in geoms or geoms[f].type != sphere]
    if not bad_feet:
        return []
    problem = (f"feet: no sphere geom {', '.join(bad_feet)} (robot.plant_names.feet); "
               f"sphere geoms in the file: {_available(n for n, g in geoms.items() if g.type == sphere)}")
    if unnamed:
        bodies = sorted({g.parent.name or "(unnamed body)" for g in unnamed})
        problem += (f"; the file has {len(unnamed)} unnamed sphere geom(s) (in bodies {', '.join(bodies[:8])}): "
                    f"name these {len(feet)} spheres {', '.join(feet.values())} in the file (name=\"...\" on each "
                    f"foot's <geom>), or name them as you like and map them with robot.plant_names.feet")
    return [problem]


def _trunk_problems(spec: mujoco.MjSpec, trunk: str, bodies: dict[str, mujoco.MjsBody]) -> list[str]:
    """The *trunk* problems: no body named ``trunk`` in the file, no free joint (floating base)."""
    problems = []
    if trunk not in bodies:
        problems.append(
            f"trunk: no body {trunk!r} (robot.plant_names.trunk); bodies in the file: {_available(bodies)}"
        )
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in spec.joints):
        problems.append("trunk: no free joint (the floating base)")
    return problems


def _actuator_renames(chosen: dict[str, mujoco.MjsActuator]) -> tuple[str, mujoco.mjtObj, dict, dict]:
    """The renaming of the named chosen actuators, as an entry of :func:`_rename_to_core`'s list."""
    return (
        "actuators",
        mujoco.mjtObj.mjOBJ_ACTUATOR,
        {a.name: a for a in chosen.values() if a.name},
        {core: a.name for core, a in chosen.items() if a.name},
    )


def _rename_to_core(
    spec: mujoco.MjSpec, renames: list[tuple[str, mujoco.mjtObj, dict[str, object], dict[str, str]]]
) -> dict[str, object]:
    """For each (kind, object type, {file name: element}, {core name: file name}): rename the elements whose
    file name differs to their core name (and every reference to them). Returns the record's ``renamed``
    part, {kind: {core name: file name}} for the kinds with a renamed element."""
    renamed: dict[str, object] = {}
    for kind, objtype, table, wanted in renames:
        to_core = {f: core for core, f in wanted.items() if f != core}
        if to_core:
            rename(spec, objtype, {f: table[f] for f in to_core}, to_core)
            renamed[kind] = {core: f for f, core in to_core.items()}
    return renamed


def _name_floor(spec: mujoco.MjSpec, floor: mujoco.MjsGeom | None) -> str | None:
    """Name the file's floor geom :data:`FLOOR` (with every reference to it). Returns its old name for the
    record (``(unnamed plane)`` if it had none), None when there is no floor or it already has the name."""
    if floor is None or floor.name == FLOOR:
        return None
    old = floor.name or "(unnamed plane)"
    if floor.name:
        rename(spec, mujoco.mjtObj.mjOBJ_GEOM, {floor.name: floor}, {floor.name: FLOOR})
    else:
        floor.name = FLOOR
    return old


def _find_actuators(
    spec: mujoco.MjSpec, names: PlantNames, file_joint: dict[str, str]
) -> tuple[dict[str, mujoco.MjsActuator], list[str]]:
    """The actuator of each core joint (by name with ``names.actuators``, else the one driving the joint)."""
    by_name = {a.name: a for a in spec.actuators if a.name}
    joint_names = {j.name for j in spec.joints}
    driving = _actuators_by_joint(spec)
    chosen: dict[str, mujoco.MjsActuator] = {}
    unfit: dict[str, list[str]] = {"missing": [], "ambiguous": [], "wrong": []}
    for core, fj in file_joint.items():
        if names.actuators is not None:
            act, kind, problem = _named_actuator(names, core, fj, by_name)
        elif fj not in joint_names:
            continue  # reported under joints
        else:
            act, kind, problem = _driving_actuator(core, fj, driving.get(fj, []))
        if act is None:
            unfit[kind].append(problem)
        else:
            chosen[core] = act
    problems = _actuator_match_problems(unfit, by_name) + _actuator_type_problems(chosen)
    return chosen, problems


_JOINT_TRANSMISSIONS = (mujoco.mjtTrn.mjTRN_JOINT, mujoco.mjtTrn.mjTRN_JOINTINPARENT)


def _actuators_by_joint(spec: mujoco.MjSpec) -> dict[str, list[mujoco.MjsActuator]]:
    """{joint name: the actuators with a joint transmission driving it}, in file order."""
    driving: dict[str, list] = {}
    for a in spec.actuators:
        if a.trntype in _JOINT_TRANSMISSIONS:
            driving.setdefault(a.target, []).append(a)
    return driving


def _named_actuator(
    names: PlantNames, core: str, fj: str, by_name: dict[str, mujoco.MjsActuator]
) -> tuple[mujoco.MjsActuator | None, str, str]:
    """The actuator ``names.actuators`` names for core joint ``core`` (file joint ``fj``): (actuator, "", "")
    or (None, "missing" / "wrong", what is wrong) when there is none or it does not drive that joint."""
    fa = names.file_name("actuators", core)
    if fa not in by_name:
        return None, "missing", f"{core} (as {fa!r})"
    act = by_name[fa]
    if act.trntype not in _JOINT_TRANSMISSIONS or act.target != fj:
        return None, "wrong", f"{fa!r} drives {act.target!r}, not joint {fj!r}"
    return act, "", ""


def _driving_actuator(
    core: str, fj: str, acts: list[mujoco.MjsActuator]
) -> tuple[mujoco.MjsActuator | None, str, str]:
    """The one actuator ``acts`` driving core joint ``core`` (file joint ``fj``): (actuator, "", ""), or
    (None, "missing" / "ambiguous", the joint and the actuators found) when there is none or several."""
    if len(acts) == 1:
        return acts[0], "", ""
    problem = (
        f"{core}"
        + (f" (joint {fj!r})" if fj != core else "")
        + (f": {', '.join(repr(a.name) for a in acts)}" if acts else "")
    )
    return None, ("missing" if not acts else "ambiguous"), problem


def _actuator_match_problems(
    unfit: dict[str, list[str]], by_name: dict[str, mujoco.MjsActuator]
) -> list[str]:
    """The *actuators* problems of the joints without an actuator (``unfit["missing"]``), with several
    (``"ambiguous"``) or with a named actuator driving something else (``"wrong"``)."""
    problems = []
    if unfit["missing"]:
        problems.append(
            f"actuators: none for {', '.join(unfit['missing'])} (robot.plant_names.actuators); "
            f"actuators in the file: {_available(by_name)}"
        )
    if unfit["ambiguous"]:
        problems.append(
            f"actuators: several drive {'; '.join(unfit['ambiguous'])}: name the one to command in "
            f"robot.plant_names.actuators"
        )
    if unfit["wrong"]:
        problems.append(f"actuators: {'; '.join(unfit['wrong'])}")
    return problems


def _actuator_type_problems(chosen: dict[str, mujoco.MjsActuator]) -> list[str]:
    """The *actuators* problems of the chosen actuators that are neither a torque motor nor a servo (no
    activation dynamics, fixed gain, no or affine bias), which :func:`_torque_motors` cannot convert."""
    problems = []
    for core, act in chosen.items():
        if (
            act.dyntype != mujoco.mjtDyn.mjDYN_NONE
            or act.gaintype != mujoco.mjtGain.mjGAIN_FIXED
            or act.biastype not in (mujoco.mjtBias.mjBIAS_NONE, mujoco.mjtBias.mjBIAS_AFFINE)
        ):
            problems.append(
                f"actuators: {act.name or core!r} is neither a torque motor nor a position/velocity "
                f"servo (dyntype {act.dyntype.name}, gaintype {act.gaintype.name}, "
                f"biastype {act.biastype.name})"
            )
    return problems


def _torque_motors(
    spec: mujoco.MjSpec, chosen: dict[str, mujoco.MjsActuator], torque_limit_nm: tuple[float, ...]
) -> dict:
    """Make each chosen actuator a torque motor taking joint torque [N·m] as ctrl (gain 1, gear 1); delete
    other actuators on the 12 joints. A servo (affine bias: tau = kp (ctrl - q) - kv qdot) becomes a motor
    with ctrlrange +- its joint's ``torque_limit_nm`` (12, core order; the robot's by default); a motor with gear x
    gain g != 1 gets gear 1 and its ctrlrange scaled by g. Returns the record: ``actuators_converted`` [[core joint,
    what], ...], ``actuators_removed`` [names]."""
    converted, removed = [], []
    for core, act in chosen.items():
        gain = float(act.gainprm[0]) * float(act.gear[0])
        if act.biastype == mujoco.mjtBias.mjBIAS_AFFINE:
            kp, kv = float(act.gainprm[0]), -float(act.biasprm[2])
            limit = float(torque_limit_nm[quad.JOINT_NAMES.index(core)])  # [N·m]
            converted.append([core, f"servo kp={kp:g} kv={kv:g} -> motor +-{limit:g} N·m"])
            act.set_to_motor()
            act.gear = [1.0, 0, 0, 0, 0, 0]
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.ctrlrange = [-limit, limit]
        elif gain != 1.0:
            converted.append([core, f"motor gear x gain {gain:g} -> 1 (ctrlrange scaled)"])
            act.ctrlrange = np.asarray(act.ctrlrange) * gain
            act.gainprm[0], act.gear = 1.0, [1.0, 0, 0, 0, 0, 0]
    kept = list(chosen.values())
    targets = {a.target for a in kept}
    for act in list(spec.actuators):
        if act.target in targets and not any(act == k for k in kept):  # MjSpec elements compare by identity
            removed.append(act.name or f"(unnamed, on {act.target})")
            spec.delete(act)
    record: dict[str, object] = {}
    if converted:
        record["actuators_converted"] = converted
    if removed:
        record["actuators_removed"] = removed
    return record


def _find_floor(spec: mujoco.MjSpec, names: PlantNames) -> tuple[mujoco.MjsGeom | None, str]:
    """(the file's floor geom or None, a problem or ""): ``names.floor``, else the only plane geom of the
    world body (the one named ``floor`` when there are several)."""
    world = [g for g in spec.geoms if g.parent == spec.worldbody]
    if names.floor is not None:
        found = [g for g in world if g.name == names.floor]
        if not found:
            return None, (
                f"floor: no geom {names.floor!r} on the world body (robot.plant_names.floor); "
                f"world geoms: {_available(g.name for g in world)}"
            )
        return found[0], ""
    planes = [g for g in world if g.type == mujoco.mjtGeom.mjGEOM_PLANE]
    if len(planes) > 1:
        named = [g for g in planes if g.name == FLOOR]
        if named:
            return named[0], ""
        return None, (
            f"floor: {len(planes)} plane geoms on the world body ({_available(g.name for g in planes)}): "
            f"name the floor in robot.plant_names.floor"
        )
    return (planes[0] if planes else None), ""


# ------------------------------------------------------------------------------------------- overrides


def apply_overrides(spec: mujoco.MjSpec, overrides: PlantOverrides, timestep_s: float) -> dict[str, list]:
    """Set the time step [s] (always: the config's physics rate) and each override that is not None on the
    spec's options, foot geoms (core names) and ``floor`` geom. Returns {setting: [before, after]} for the
    settings whose value changed (numbers as text)."""
    changes: dict[str, list] = {}

    def note(key: str, before, after) -> None:
        if before != after:
            changes[key] = [before, after]

    note("timestep_s", f"{spec.option.timestep:g}", f"{timestep_s:g}")
    spec.option.timestep = timestep_s
    o = overrides
    if o.integrator is not None:
        note("integrator", mujoco.mjtIntegrator(spec.option.integrator).name, INTEGRATORS[o.integrator].name)
        spec.option.integrator = INTEGRATORS[o.integrator]
    if o.cone is not None:
        note("cone", mujoco.mjtCone(spec.option.cone).name, CONES[o.cone].name)
        spec.option.cone = CONES[o.cone]
    if o.noslip_iterations is not None:
        note("noslip_iterations", spec.option.noslip_iterations, int(o.noslip_iterations))
        spec.option.noslip_iterations = int(o.noslip_iterations)
    if o.impratio is not None:
        note("impratio", f"{spec.option.impratio:g}", f"{o.impratio:g}")
        spec.option.impratio = float(o.impratio)
    feet = [spec.geom(f) for f in quad.FOOT_FRAMES]
    floor = [g for g in [spec.geom(FLOOR)] if g is not None]
    for attr, value, geoms in (
        ("solref", o.contact_solref, feet + floor),
        ("solimp", o.contact_solimp, feet + floor),
        ("margin", o.foot_margin_m, feet),
    ):
        if value is None:
            continue
        for g in geoms:
            note(f"{g.name}.{attr}", _fmt(getattr(g, attr)), _fmt(value))
            # cast: "margin" is o.foot_margin_m, a number
            setattr(g, attr, list(np.atleast_1d(value)) if attr != "margin" else float(cast(float, value)))
    return changes


def store_record(spec: mujoco.MjSpec, record: dict) -> None:
    """Keep ``record`` in the model as the custom text :data:`RECORD_TEXT` (JSON), if it holds anything."""
    if record:
        spec.add_text(name=RECORD_TEXT, data=json.dumps(record, sort_keys=True))


def read_record(model: mujoco.MjModel) -> dict:
    """The adapter's record stored by :func:`store_record` ({} when the model has none)."""
    tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, RECORD_TEXT)
    if tid < 0:
        return {}
    start = model.text_adr[tid]
    raw = bytes(model.text_data[start : start + model.text_size[tid]]).rstrip(b"\x00")
    return json.loads(raw.decode())
