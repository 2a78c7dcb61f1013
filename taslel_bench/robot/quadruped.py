"""The core's vocabulary of a quadruped with three actuated joints per leg: names and sizes, no robot's values.

Every robot the harness simulates (``conf/robot/<name>.yaml``, :class:`taslel_bench.robot.description.RobotDescription`)
is mapped onto this layout, whatever its own names and joint order:

* **Legs** ``LEGS = ("FL", "FR", "RL", "RR")``: front-left, front-right, rear-left, rear-right. A robot names its
  legs as it likes (ANYmal: LF, RF, LH, RH; Solo: FL, FR, HL, HR); its description says which is which.
* **Joints** per leg ``[hip, thigh, calf]``: the abduction (roll about the trunk's x axis), the hip flexion and the
  knee (pitch about y). Joint vectors of length 12 are in ``LEGS`` order, three per leg (the *core order*).
* **Plant names**: the MuJoCo plant's joints, actuators, foot geoms and sites carry the core names below
  (``FL_hip_joint``, ``FL_foot``, body ``trunk``); the plant builder renames the robot's own names to them, so the
  state bridge, the contact reader and the scenarios never see a robot's names.

Units everywhere: metres, radians, seconds, newtons, newton-metres, kilograms.
"""

from __future__ import annotations

LEGS: tuple[str, ...] = ("FL", "FR", "RL", "RR")
JOINT_ROLES: tuple[str, ...] = ("hip", "thigh", "calf")
JOINT_NAMES: tuple[str, ...] = tuple(f"{leg}_{j}_joint" for leg in LEGS for j in JOINT_ROLES)  # plant names
FOOT_FRAMES: tuple[str, ...] = tuple(f"{leg}_foot" for leg in LEGS)  # plant foot geoms and sites
TRUNK_BODY = "trunk"  # plant body carrying the free joint
N_LEGS = 4
N_JOINTS = 12
NV = 18  # free flyer (6) + 12 joints
NQ = 19  # position (3) + quaternion (4) + 12 joints
# +1 for left legs, -1 for right legs; +1 for front legs, -1 for rear legs
LEG_SIDE: tuple[float, ...] = (1.0, -1.0, 1.0, -1.0)
LEG_FORE: tuple[float, ...] = (1.0, 1.0, -1.0, -1.0)


def leg_index(leg: str) -> int:
    """Index of ``leg`` in :data:`LEGS`; a clear error for unknown names."""
    if leg not in LEGS:
        raise ValueError(f"unknown leg {leg!r}; valid legs: {', '.join(LEGS)}")
    return LEGS.index(leg)
