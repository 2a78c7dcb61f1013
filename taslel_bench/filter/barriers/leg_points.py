"""Kinematics of points on a lower leg for the whole-leg barriers: position of the knee (the calf joint), and
for any world point p rigidly attached to a leg's calf body its translational Jacobian (world axes), velocity
and J̇v, from the controller model's joint Jacobians at the current (q, v) (Pinocchio ``data.J``/``data.dJ``,
filled by :meth:`taslel_bench.robot.model.RobotModel.update`). Same formula as the foot terms of the model:
J_p = J_lin + omega x p on the columns that move the leg (free flyer + the leg's three joints)."""

from __future__ import annotations

import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.model import RobotModel
from taslel_bench.util.jit import kernel


class LegPoints:
    """Per-episode lookup of the calf joints and the leg columns of one :class:`RobotModel`."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        pm = model.model
        self.knee_joints = [pm.getJointId(model.robot.joint_names[3 * leg + 2]) for leg in range(quad.N_LEGS)]
        self.cols = []
        for j in self.knee_joints:
            support = pm.supports[j][1:]
            self.cols.append(np.array([pm.joints[s].idx_v + k for s in support for k in range(pm.joints[s].nv)],
                                      dtype=np.int64))
        self.cols_array = np.array(self.cols)  # (4, 9) velocity columns that move each calf body
        # the knees' world positions [m] as live views of Pinocchio's data.oMi (no copy: they follow each
        # update of the model; a kernel reads them without a Python call per knee and tick), valid while the
        # model keeps this data object (``data``)
        self.data = model.data
        self.knee_views = tuple(model.data.oMi[j].translation for j in self.knee_joints)

    def knees(self) -> np.ndarray:
        """(4, 3) world positions [m] of the four knees."""
        oMi = self.model.data.oMi
        return np.array([oMi[j].translation for j in self.knee_joints])

    def knee(self, leg: int) -> np.ndarray:
        """World position [m] of leg ``leg``'s calf joint (the knee)."""
        return np.array(self.model.data.oMi[self.knee_joints[leg]].translation)

    def point_terms(self, leg: int, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(J (3, nv), velocity (3,) [m/s], J̇v (3,) [m/s²]) of the world point ``p`` [m] fixed to leg ``leg``'s
        calf body, at the model's current state and velocity ``v``."""
        jac, vel, jdotv = np.zeros((3, self.model.model.nv)), np.zeros(3), np.zeros(3)
        _point_terms(self.model.data.J, self.model.data.dJ, self.cols[leg], np.asarray(p, float), v, jac, vel, jdotv)
        return jac, vel, jdotv


@kernel
def _point_terms(J_world, dJ_world, cols, p, v, jac, vel, jdotv):
    """J_p = J_lin + omega x p on ``cols``, v_p = J_p v, J̇_p v = J̇_lin v + (J̇_ang v) x p + omega x v_p."""
    px, py, pz = p[0], p[1], p[2]
    wx = wy = wz = ax = ay = az = bx = by = bz = 0.0
    vx = vy = vz = 0.0
    for c in cols:
        ox, oy, oz = J_world[3, c], J_world[4, c], J_world[5, c]
        jx = J_world[0, c] + oy * pz - oz * py
        jy = J_world[1, c] + oz * px - ox * pz
        jz = J_world[2, c] + ox * py - oy * px
        jac[0, c], jac[1, c], jac[2, c] = jx, jy, jz
        vc = v[c]
        vx, vy, vz = vx + jx * vc, vy + jy * vc, vz + jz * vc
        wx, wy, wz = wx + ox * vc, wy + oy * vc, wz + oz * vc
        ax, ay, az = ax + dJ_world[0, c] * vc, ay + dJ_world[1, c] * vc, az + dJ_world[2, c] * vc
        bx, by, bz = bx + dJ_world[3, c] * vc, by + dJ_world[4, c] * vc, bz + dJ_world[5, c] * vc
    vel[0], vel[1], vel[2] = vx, vy, vz
    jdotv[0] = ax + (by * pz - bz * py) + (wy * vz - wz * vy)
    jdotv[1] = ay + (bz * px - bx * pz) + (wz * vx - wx * vz)
    jdotv[2] = az + (bx * py - by * px) + (wx * vy - wy * vx)
