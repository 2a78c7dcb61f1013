"""State bridge MuJoCo (plant) <-> Pinocchio (controller's model). The only module that knows both.

Conversions (docs/concepts.md, "conversion traps"):
  * quaternion: MuJoCo wxyz -> Pinocchio xyzw;
  * trunk linear velocity: MuJoCo world axes -> Pinocchio trunk axes (angular is in the trunk frame in both);
  * leg order: MuJoCo keeps the plant model's joint order (URDF: FR, FL, RR, RL); Pinocchio and the core use
    :data:`quad.LEGS` = FL, FR, RL, RR. The permutation is built from joint and actuator names, so any
    plant MJCF with the core joint names works (the plant builder renames a robot's joints to them).
"""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.jit import kernel


@kernel
def quat_wxyz_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix (world from body) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = quat_wxyz[0], quat_wxyz[1], quat_wxyz[2], quat_wxyz[3]
    R = np.empty((3, 3))
    R[0, 0], R[0, 1], R[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[1, 0], R[1, 1], R[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[2, 0], R[2, 1], R[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return R


class StateBridge:
    """Index maps between a MuJoCo plant model and the core's joint order."""

    def __init__(self, mj_model: mujoco.MjModel) -> None:
        missing = []
        qadr, dadr, act = [], [], []
        for name in quad.JOINT_NAMES:
            jid = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, name)
            aid = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
            if jid < 0:
                missing.append(f"joint {name}")
            if aid < 0:
                missing.append(f"actuator {name}")
            qadr.append(mj_model.jnt_qposadr[jid] if jid >= 0 else -1)
            dadr.append(mj_model.jnt_dofadr[jid] if jid >= 0 else -1)
            act.append(aid)
        free = [j for j in range(mj_model.njnt) if mj_model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if not free:
            missing.append("a free joint on the trunk")
        if missing:
            raise ValueError(f"plant model does not fit the core's quadruped: missing {', '.join(missing)}")
        self.free_qadr = int(mj_model.jnt_qposadr[free[0]])
        self.free_dadr = int(mj_model.jnt_dofadr[free[0]])
        self.joint_qadr = np.array(qadr)  # core joint i -> MuJoCo qpos index
        self.joint_dadr = np.array(dadr)  # core joint i -> MuJoCo qvel index
        self.actuator_ids = np.array(act)  # core joint i -> MuJoCo actuator index
        self.nu = mj_model.nu
        a, d = self.free_qadr, self.free_dadr
        self._q_pin_from_qpos = np.concatenate([np.arange(a, a + 3), [a + 4, a + 5, a + 6, a + 3], self.joint_qadr])
        self._v_pin_from_qvel = np.concatenate([np.arange(d, d + 6), self.joint_dadr])
        self._quat_trunk_from_world = np.zeros(4)  # scratch for v_pin
        self._vel_in_trunk = np.zeros(3)

    # --- MuJoCo -> Pinocchio -------------------------------------------------------------------------
    def q_pin(self, qpos: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Pinocchio configuration (19) from MuJoCo ``qpos``."""
        out = np.empty(quad.NQ) if out is None else out
        np.take(qpos, self._q_pin_from_qpos, out=out)  # position, quaternion x y z w, joints in core order
        return out

    def v_pin(self, qpos: np.ndarray, qvel: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Pinocchio velocity (18) from MuJoCo ``qvel``: trunk linear velocity rotated into trunk axes."""
        out = np.empty(quad.NV) if out is None else out
        a, d = self.free_qadr, self.free_dadr
        np.take(qvel, self._v_pin_from_qvel, out=out)  # angular velocity and joints are already right
        mujoco.mju_negQuat(self._quat_trunk_from_world, qpos[a + 3 : a + 7])  # inverse rotation
        mujoco.mju_rotVecQuat(self._vel_in_trunk, qvel[d : d + 3], self._quat_trunk_from_world)
        out[:3] = self._vel_in_trunk
        return out

    def state_pin(self, qpos: np.ndarray, qvel: np.ndarray, q_out: np.ndarray, v_out: np.ndarray) -> None:
        """:meth:`q_pin` and :meth:`v_pin` in one compiled call (the control tick's state read); the joint
        angles [rad] and velocities [rad/s] in core order are then ``q_out[7:]`` and ``v_out[6:]``."""
        _state_pin(qpos, qvel, self._q_pin_from_qpos, self._v_pin_from_qvel, self.free_qadr + 3, q_out, v_out)

    # --- Pinocchio -> MuJoCo -------------------------------------------------------------------------
    def qpos_mj(self, q: np.ndarray, qpos: np.ndarray) -> np.ndarray:
        """Write a Pinocchio configuration into MuJoCo ``qpos`` (in place) and return it."""
        a = self.free_qadr
        qpos[a : a + 3] = q[:3]
        qpos[a + 3] = q[6]
        qpos[a + 4 : a + 7] = q[3:6]
        qpos[self.joint_qadr] = q[7:]
        return qpos

    def qvel_mj(self, q: np.ndarray, v: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """Write a Pinocchio velocity into MuJoCo ``qvel`` (in place) and return it."""
        d = self.free_dadr
        rot_world_from_trunk = quat_wxyz_to_matrix(np.array([q[6], q[3], q[4], q[5]]))
        qvel[d : d + 3] = rot_world_from_trunk @ v[:3]
        qvel[d + 3 : d + 6] = v[3:6]
        qvel[self.joint_dadr] = v[6:]
        return qvel

    def ctrl_mj(self, u: np.ndarray, ctrl: np.ndarray) -> np.ndarray:
        """Write joint torques in core order [N·m] into MuJoCo ``ctrl`` (in place)."""
        ctrl[self.actuator_ids] = u
        return ctrl

    def joint_vector(self, mj_vec: np.ndarray, by: str = "dof") -> np.ndarray:
        """Reorder a per-joint MuJoCo vector (indexed by qvel address) into core order."""
        return mj_vec[self.joint_dadr if by == "dof" else self.actuator_ids]


@kernel
def _state_pin(qpos, qvel, q_from_qpos, v_from_qvel, quat_adr, q, v):
    """q = qpos[q_from_qpos]; v = qvel[v_from_qvel] with v[:3] (world axes in MuJoCo) rotated into trunk
    axes by the inverse of the trunk quaternion qpos[quat_adr : quat_adr + 4] (w, x, y, z)."""
    for i in range(q.shape[0]):
        q[i] = qpos[q_from_qpos[i]]
    for i in range(v.shape[0]):
        v[i] = qvel[v_from_qvel[i]]
    quat = qpos[quat_adr : quat_adr + 4]
    R = quat_wxyz_to_matrix(quat / np.sqrt(quat @ quat))  # MuJoCo keeps |quat| ~ 1: make R a rotation
    vx, vy, vz = v[0], v[1], v[2]
    for i in range(3):  # R' v_world
        v[i] = R[0, i] * vx + R[1, i] * vy + R[2, i] * vz
