"""Unitree A1 constants and the URDF shipped by ``example-robot-data``: the one place for them.

Conventions used everywhere in the core (controller, filter, recordings):

* **Leg order** is ``LEGS = ("FL", "FR", "RL", "RR")`` — Pinocchio's order for this URDF. MuJoCo keeps the
  URDF order (FR, FL, RR, RL); only :mod:`taslel_bench.plant.bridge` knows about that.
* Joint vectors of length 12 are ``[hip, thigh, calf]`` per leg in ``LEGS`` order.
* Units: metres, radians, seconds, newtons, newton-metres, kilograms.
"""

from __future__ import annotations

import importlib.metadata
from functools import lru_cache
from pathlib import Path

import numpy as np

LEGS: tuple[str, ...] = ("FL", "FR", "RL", "RR")
JOINT_SUFFIXES: tuple[str, ...] = ("hip", "thigh", "calf")
JOINT_NAMES: tuple[str, ...] = tuple(f"{leg}_{j}_joint" for leg in LEGS for j in JOINT_SUFFIXES)
FOOT_FRAMES: tuple[str, ...] = tuple(f"{leg}_foot" for leg in LEGS)  # Pinocchio frames, MuJoCo geoms
TRUNK_BODY = "trunk"
N_LEGS = 4
N_JOINTS = 12
NV = 18  # free flyer (6) + 12 joints
NQ = 19

TORQUE_LIMIT_NM = 33.5  # [N·m] URDF effort limit of every A1 joint
FOOT_RADIUS_M = 0.02  # [m] radius of the URDF foot collision sphere
SHIN_RADIUS_M = 0.0115  # [m] the URDF calf collision is a 0.016 x 0.016 box: its half diagonal
SHIN_AXIS_FRACTION = 0.7  # [-] the shin the barriers guard: knee -> this fraction of the way to the foot centre
THIGH_LENGTH_M = 0.2  # [m] thigh joint -> calf joint, along -z of the thigh
CALF_LENGTH_M = 0.2  # [m] calf joint -> foot centre
HIP_OFFSET_Y_M = 0.0838  # [m] lateral offset hip joint -> thigh joint (sign: +left, -right)
# [m] hip-joint positions in the trunk frame, LEGS order
HIP_POSITIONS_IN_TRUNK = np.array(
    [[0.1805, 0.047, 0.0], [0.1805, -0.047, 0.0], [-0.1805, 0.047, 0.0], [-0.1805, -0.047, 0.0]]
)
# +1 for left legs, -1 for right legs (sign of the hip -> thigh lateral offset)
LEG_SIDE = np.array([1.0, -1.0, 1.0, -1.0])


def leg_index(leg: str) -> int:
    """Index of ``leg`` in :data:`LEGS`; a clear error for unknown names."""
    if leg not in LEGS:
        raise ValueError(f"unknown leg {leg!r}; valid legs: {', '.join(LEGS)}")
    return LEGS.index(leg)


@lru_cache(maxsize=1)
def a1_urdf_path() -> Path:
    """Path of ``robots/a1_description/urdf/a1.urdf`` inside the installed ``example-robot-data``.

    The wheel ships data only (no Python module), so the file is found through the distribution's
    file list rather than a hard-coded prefix.
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:  # pragma: no cover - install problem
        raise RuntimeError("example-robot-data is not installed; `pip install example-robot-data`") from exc
    for f in dist.files or ():
        if str(f).endswith("robots/a1_description/urdf/a1.urdf"):
            path = Path(dist.locate_file(f))
            if path.is_file():
                return path
    raise RuntimeError(
        "example-robot-data is installed but robots/a1_description/urdf/a1.urdf was not found in it"
    )
