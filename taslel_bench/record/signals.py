"""The signal channels of ``episode.mcap``: JSON messages of ``steps.parquet`` columns with named fields
(Foxglove plots them by path, e.g. ``/contact_force.FL.plant_w_n.z``, ``/joint_state.position_rad.FL_hip``).

A channel is a spec: a field maps to a ``steps.parquet`` column (a leaf) or to a dict of named fields
(vectors by axis ``x``/``y``/``z``, quaternions ``w``..``z``, per-foot values by leg ``FL``..``RR``, joints by
name). Every message also has ``t_s``, the simulated time [s] of the tick. Frames in the names: ``_w`` world
axes, ``_b`` trunk axes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from taslel_bench.record.trace import TICK_PARTS
from taslel_bench.robot import quadruped as quad

Spec = dict  # field -> column name (str) or a nested Spec
JOINTS = [j.removesuffix("_joint") for j in quad.JOINT_NAMES]
BOOLEAN_SUFFIXES = ("_stance", "_contact", "qp_fallback", "_ready")


def _axes(pattern: str, axes: str = "xyz") -> Spec:
    return {ax: pattern.format(ax=ax) for ax in axes}


def _per_leg(fields: Spec) -> Spec:
    """``{leg: fields with {leg} filled in}`` for every leg (LEGS order)."""
    def fill(spec):
        return spec.replace("{leg}", leg) if isinstance(spec, str) else {k: fill(v) for k, v in spec.items()}

    out = {}
    for leg in quad.LEGS:
        out[leg] = fill(fields)
    return out


def _axes_per_leg(pattern: str) -> Spec:
    return {ax: pattern.replace("{ax}", ax) for ax in "xyz"}


CHANNELS: dict[str, Spec] = {
    "/base_state": {
        "position_w_m": _axes("base_{ax}_w_m"),
        "quat_wxyz": _axes("base_quat_{ax}", "wxyz"),
        "rpy_rad": {name: f"base_{name}_rad" for name in ("roll", "pitch", "yaw")},
        "linvel_w_mps": _axes("base_v{ax}_w_mps"),
        "angvel_b_radps": _axes("base_w{ax}_b_radps"),
    },
    "/joint_state": {"position_rad": {j: f"q_{j}_rad" for j in JOINTS},
                     "velocity_radps": {j: f"qd_{j}_radps" for j in JOINTS}},
    "/torques": {"u_nom_nm": {j: f"u_nom_{j}_nm" for j in JOINTS}, "u_nm": {j: f"u_{j}_nm" for j in JOINTS}},
    "/contact_force": _per_leg({
        "filter_w_n": _axes_per_leg("{leg}_grf_filter_{ax}_w_n"),
        "plant_w_n": _axes_per_leg("{leg}_grf_plant_{ax}_w_n"),
        "stance": "{leg}_stance",
        "contact": "{leg}_contact",
        "mu_foot": "{leg}_mu_foot",
        "mu_hat_foot": "{leg}_mu_hat_foot",
        "contact_point_speed_mps": "{leg}_contact_point_speed_mps",
    }),
    "/qp": {"status": "qp_status", "fallback": "qp_fallback", "solve_us": "qp_solve_us", "build_us": "qp_build_us",
            "iterations": "qp_iterations"},
    "/tick": {"tick_us": "tick_us", **{f"{p}_us": f"tick_{p}_us" for p in TICK_PARTS}},
    "/barrier": _per_leg({  # + <name>_h_m, <name>_h_e_mps of every barrier family (channels())
        "h_m": "{leg}_barrier_h_m",
        "clearance_m": "{leg}_clearance_m",
        "obstacle_clearance_m": "{leg}_obstacle_clearance_m",
        "obstacle_contact": "{leg}_obstacle_contact",
    }),
    "/friction": {"mu_hat": "mu_hat", "mu_true": "mu_true", "mu_hat_ready": "mu_hat_ready"},
}
# computed for each chunk after its ticks (taslel_bench.metrics.residuals): written with the chunk
AFTER_EPISODE: dict[str, Spec] = {
    "/residual": {
        "trunk_force_n": "residual_trunk_force_n",
        "trunk_torque_nm": "residual_trunk_torque_nm",
        "joint_max_nm": "residual_joint_nm_max",
        **_per_leg({"foot_acc_error_mps2": "{leg}_foot_acc_error_mps2",
                    "barrier_psi_planned_mps2": "{leg}_barrier_psi_planned_mps2",
                    "barrier_psi_realized_mps2": "{leg}_barrier_psi_realized_mps2"}),
    },
}


def channels(barrier_names: Sequence[str] = ()) -> dict[str, Spec]:
    """:data:`CHANNELS` with, per foot of ``/barrier``, ``<name>_h_m`` and ``<name>_h_e_mps`` of each
    barrier family (``h_m``: the smallest h over the families)."""
    out = {topic: dict(spec) for topic, spec in CHANNELS.items()}
    out["/barrier"] = {leg: dict(fields) for leg, fields in out["/barrier"].items()}
    for name in barrier_names:
        for leg in quad.LEGS:
            out["/barrier"][leg][f"{name}_h_m"] = f"{leg}_barrier_{name}_h_m"
            out["/barrier"][leg][f"{name}_h_e_mps"] = f"{leg}_barrier_{name}_he_mps"
    return out


def json_schema(title: str, spec: Spec) -> dict:
    """The JSON schema of a channel's messages (``t_s`` and the spec's fields)."""
    def node(s) -> dict[str, Any]:
        if isinstance(s, str):
            return {"type": "boolean"} if s.endswith(BOOLEAN_SUFFIXES) else {"type": ["number", "null"]}
        return {"type": "object", "properties": {k: node(v) for k, v in s.items()}}

    return {"title": title, "type": "object", "properties": {"t_s": {"type": "number"}, **node(spec)["properties"]}}


def _leaves(spec: Spec, path: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], str]]:
    out = []
    for key, value in spec.items():
        out += [((*path, key), value)] if isinstance(value, str) else _leaves(value, (*path, key))
    return out


def _column_values(frame: pd.DataFrame, column: str) -> list:
    """A column as JSON-ready Python values (NaN -> None)."""
    a = frame[column].to_numpy()
    if a.dtype.kind == "f" and np.isnan(a).any():
        return [None if np.isnan(v) else v for v in a.tolist()]
    return a.tolist()


def messages(frame: pd.DataFrame, spec: Spec) -> list[dict]:
    """One message per row of ``frame`` (a steps.parquet frame): ``t_s`` and the spec's fields."""
    leaves = [(path, _column_values(frame, column)) for path, column in _leaves(spec)]
    out = []
    for i, t in enumerate(frame["t_s"].tolist()):
        msg: dict = {"t_s": t}
        for path, values in leaves:
            node = msg
            for key in path[:-1]:
                node = node.setdefault(key, {})
            node[path[-1]] = values[i]
        out.append(msg)
    return out
