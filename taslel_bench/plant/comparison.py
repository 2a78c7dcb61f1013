"""Plant vs the controller's model at build time: one flat dict for ``summary.json``.

What the MuJoCo plant is (masses, CoM, joint losses, actuator limits, integrator and contact settings, what
the plant adapter changed) beside what the Pinocchio model believes, so a run records the mismatch it was
run under. Keys start with ``plant_`` or ``model_`` (``model_minus_plant_`` for differences) and carry their
unit; vectors are compact text (``"0.02 1"``), a value that differs between the four feet is given per foot.

Poses: the stand pose is the trunk at the world origin with identity orientation and the given joint
angles, so positions are in the trunk frame [m]. The effective contact parameters are read from MuJoCo's
contacts with the robot standing on the floor (lowest foot 0.1 mm into it), as every episode starts.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin

from taslel_bench.plant.adapter import FLOOR, read_record
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.model import RobotModel

STAND_PENETRATION_M = 1e-4  # [m] lowest foot-sphere bottom below the floor for the contact read-out


def _fmt(values) -> str:
    return " ".join(f"{float(x):g}" for x in np.atleast_1d(values))


def _per_foot(values: list[str]) -> str:
    """One text when the four feet agree, else ``FL: ..; FR: ..`` (legs in core order)."""
    return (
        values[0]
        if len(set(values)) == 1
        else "; ".join(f"{leg}: {v}" for leg, v in zip(quad.LEGS, values, strict=True))
    )


def _stand_q(stand_joints_rad: np.ndarray) -> np.ndarray:
    q = np.zeros(quad.NQ)
    q[6] = 1.0  # identity orientation (x, y, z, w)
    q[7:] = stand_joints_rad
    return q


def plant_vs_model(
    mj_model: mujoco.MjModel, model: RobotModel, stand_joints_rad: np.ndarray
) -> dict[str, object]:
    """The report (module doc) for a compiled plant and the controller's model; ``stand_joints_rad`` (12,
    core order) is the stand pose's joint angles [rad]."""
    out: dict[str, object] = {}
    out.update(_masses_com_feet(mj_model, model, np.asarray(stand_joints_rad, float)))
    out.update(_joints(mj_model, model))
    out.update(_options_and_geoms(mj_model))
    out.update(_contacts_at_stand(mj_model, np.asarray(stand_joints_rad, float)))
    out.update(_adapter(mj_model))
    return out


def _masses_com_feet(m: mujoco.MjModel, pm: RobotModel, qj: np.ndarray) -> dict[str, object]:
    """Total and trunk mass [kg], whole-robot CoM and foot centres at the stand pose [m, trunk frame]."""
    trunk = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
    root = m.body_rootid[trunk]
    d, br = mujoco.MjData(m), StateBridge(m)
    q = _stand_q(qj)
    br.qpos_mj(q, d.qpos)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    plant_com = d.subtree_com[root].copy()
    feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f) for f in quad.FOOT_FRAMES]
    plant_feet = d.geom_xpos[feet].copy()
    pm.update(q, np.zeros(quad.NV))
    model_feet = pm.foot_pos_in_world.copy()
    model_com = pin.centerOfMass(pm.model, pm.model.createData(), q)
    plant_total = float(m.body_mass[m.body_rootid == root].sum())
    plant_trunk, model_trunk = float(m.body_mass[trunk]), float(pm.model.inertias[1].mass)
    out: dict[str, object] = {
        "plant_total_mass_kg": plant_total,
        "model_total_mass_kg": pm.total_mass_kg,
        "model_minus_plant_total_mass_kg": pm.total_mass_kg - plant_total,
        "plant_trunk_mass_kg": plant_trunk,
        "model_trunk_mass_kg": model_trunk,
        "model_minus_plant_trunk_mass_kg": model_trunk - plant_trunk,
    }
    for i, axis in enumerate("xyz"):
        out[f"plant_com_stand_{axis}_m"] = float(plant_com[i])
        out[f"model_com_stand_{axis}_m"] = float(model_com[i])
    out["model_minus_plant_com_stand_m"] = float(np.linalg.norm(model_com - plant_com))
    out["model_minus_plant_foot_pos_stand_max_m"] = float(np.abs(model_feet - plant_feet).max())
    return out


def _joints(m: mujoco.MjModel, pm: RobotModel) -> dict[str, object]:
    """Joint damping [N·m·s/rad], armature [kg·m²], friction loss [N·m] (min and max over the 12 joints) of
    both; the plant's higher-order damping coefficients and its torque limit per joint [N·m]."""
    br = StateBridge(m)
    dofs = br.joint_dadr
    plant = {
        "damping_nms_per_rad": m.dof_damping[dofs],
        "armature_kgm2": m.dof_armature[dofs],
        "frictionloss_nm": m.dof_frictionloss[dofs],
    }
    model = {
        "damping_nms_per_rad": pm.model.damping[6:],
        "armature_kgm2": pm.model.armature[6:],
        "frictionloss_nm": pm.model.friction[6:],
    }
    out: dict[str, object] = {}
    for side, values in (("plant", plant), ("model", model)):
        for key, v in values.items():
            out[f"{side}_joint_{key}_min"] = float(np.min(v))
            out[f"{side}_joint_{key}_max"] = float(np.max(v))
    out["plant_joint_damping_higher_order_max"] = float(np.abs(m.dof_dampingpoly[dofs]).max())
    out["model_frictionloss_smoothing_radps"] = float(pm.frictionloss_smoothing_radps)
    out["model_urdf"] = pm.urdf_path
    limits = np.array(
        [_torque_limit(m, int(a), int(j)) for a, j in zip(br.actuator_ids, m.dof_jntid[dofs], strict=True)]
    )
    out["plant_torque_limit_nm_min"] = float(limits.min())
    out["plant_torque_limit_nm_max"] = float(limits.max())
    return out


def _torque_limit(m: mujoco.MjModel, act: int, joint: int) -> float:
    """The largest joint torque [N·m] actuator ``act`` can apply: gain x gear x ctrlrange, clipped by its
    forcerange and the joint's actuator-force range (inf when nothing limits it)."""
    limit = np.inf
    if m.actuator_ctrllimited[act]:
        limit = np.abs(m.actuator_ctrlrange[act]).max() * abs(
            m.actuator_gainprm[act, 0] * m.actuator_gear[act, 0]
        )
    if m.actuator_forcelimited[act]:
        limit = min(limit, np.abs(m.actuator_forcerange[act]).max())
    if m.jnt_actfrclimited[joint]:
        limit = min(limit, np.abs(m.jnt_actfrcrange[joint]).max())
    return float(limit)


def _geom_params(m: mujoco.MjModel, g: int) -> dict[str, str]:
    return {
        "solref": _fmt(m.geom_solref[g]),
        "solimp": _fmt(m.geom_solimp[g]),
        "margin_m": f"{m.geom_margin[g]:g}",
        "gap_m": f"{m.geom_gap[g]:g}",
        "friction": _fmt(m.geom_friction[g]),
        "priority": str(m.geom_priority[g]),
        "condim": str(m.geom_condim[g]),
    }


def _options_and_geoms(m: mujoco.MjModel) -> dict[str, object]:
    """Integrator, time step [s], cone, solver options; contact parameters of the foot geoms and the floor."""
    out: dict[str, object] = {
        "plant_integrator": mujoco.mjtIntegrator(m.opt.integrator).name.removeprefix("mjINT_").lower(),
        "plant_timestep_s": float(m.opt.timestep),
        "plant_cone": mujoco.mjtCone(m.opt.cone).name.removeprefix("mjCONE_").lower(),
        "plant_noslip_iterations": int(m.opt.noslip_iterations),
        "plant_impratio": float(m.opt.impratio),
    }
    feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f) for f in quad.FOOT_FRAMES]
    per_foot = [_geom_params(m, g) for g in feet]
    for key in per_foot[0]:
        out[f"plant_foot_{key}"] = _per_foot([p[key] for p in per_foot])
    out["plant_foot_radius_m"] = _per_foot([f"{m.geom_size[g, 0]:g}" for g in feet])
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, FLOOR)
    if floor >= 0:
        out.update({f"plant_floor_{k}": v for k, v in _geom_params(m, floor).items()})
    return out


def _contacts_at_stand(m: mujoco.MjModel, qj: np.ndarray) -> dict[str, object]:
    """The parameters MuJoCo actually uses for the foot contacts (after combining foot and terrain geoms by
    priority or mixing) with the robot standing on the floor."""
    d, br = mujoco.MjData(m), StateBridge(m)
    q = _stand_q(qj)
    br.qpos_mj(q, d.qpos)
    mujoco.mj_kinematics(m, d)
    feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f) for f in quad.FOOT_FRAMES]
    q[2] = -float(np.min(d.geom_xpos[feet, 2] - m.geom_size[feet, 0])) - STAND_PENETRATION_M
    br.qpos_mj(q, d.qpos)
    mujoco.mj_forward(m, d)
    rows = {}
    for i in range(d.ncon):
        c = d.contact[i]
        leg = next((quad.LEGS[k] for k, g in enumerate(feet) if g in (c.geom1, c.geom2)), None)
        if leg is not None:
            rows.setdefault(
                leg,
                {
                    "solref": _fmt(c.solref),
                    "solimp": _fmt(c.solimp),
                    "friction": _fmt(c.friction),
                    "includemargin_m": f"{c.includemargin:g}",
                    "condim": str(c.dim),
                },
            )
    out: dict[str, object] = {"plant_contact_feet_at_stand": len(rows)}
    if rows:
        legs = [leg for leg in quad.LEGS if leg in rows]
        for key in rows[legs[0]]:
            values = [rows[leg][key] for leg in legs]
            out[f"plant_contact_{key}"] = (
                values[0]
                if len(set(values)) == 1
                else "; ".join(f"{leg}: {v}" for leg, v in zip(legs, values, strict=True))
            )
    return out


def _adapter(m: mujoco.MjModel) -> dict[str, object]:
    """What the plant adapter and the overrides changed (``""`` when nothing)."""
    rec = read_record(m)
    renamed = {
        kind: (
            f"{len(v)} ({next(iter(v.values()))!r} ...)"
            if isinstance(v, dict) and len(v) > 1
            else repr(next(iter(v.values())))
            if isinstance(v, dict)
            else repr(v)
        )
        for kind, v in rec.get("renamed", {}).items()
    }
    by_what: dict[str, list[str]] = {}
    for joint, what in rec.get("actuators_converted", []):
        by_what.setdefault(what, []).append(joint)
    return {
        "plant_renamed": "; ".join(f"{kind}: {v}" for kind, v in renamed.items()),  # full map: config.yaml
        "plant_actuators_converted": "; ".join(
            f"{what} ({len(joints)} joints)" if len(joints) > 2 else f"{what} ({', '.join(joints)})"
            for what, joints in by_what.items()
        ),
        "plant_actuators_removed": ", ".join(rec.get("actuators_removed", [])),
        "plant_floor_source": rec.get("floor", "the harness's (URDF plant)"),
        "plant_overrides": "; ".join(f"{k}: {b} -> {a}" for k, (b, a) in rec.get("overrides", {}).items()),
    }
