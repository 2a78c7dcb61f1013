"""The controller's model of the robot: Pinocchio, built from the same URDF as the plant.

All per-tick rigid-body quantities the nominal controller and the safety filter need are computed once
by :meth:`RobotModel.update` into preallocated arrays (no allocation per tick beyond Pinocchio's own).

Frames and units: ``q`` is Pinocchio's (position of the trunk origin in world [m], quaternion xyzw,
12 joint angles [rad] in the core order of :mod:`taslel_bench.robot.quadruped`); ``v`` is (trunk linear velocity in the
**trunk** frame [m/s], angular velocity in the trunk frame [rad/s], joint velocities [rad/s]). Foot quantities are
expressed at the foot-sphere centre in LOCAL_WORLD_ALIGNED axes (world orientation).

What the model believes about the robot (URDF file, joint damping, armature, Coulomb friction, trunk mass
and CoM, payload) is a :class:`taslel_bench.robot.model_options.ModelOptions`; the defaults give the URDF as is.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from taslel_bench.robot import model_options
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription, default_robot, foot_frame, pinocchio_model
from taslel_bench.robot.model_options import ModelOptions
from taslel_bench.util.jit import kernel


class RobotModel:
    """Pinocchio model + data of one robot (:class:`RobotDescription`) and the per-tick dynamics terms.

    After :meth:`update`:
      * ``M`` (18x18) mass matrix [kg, kg·m, kg·m²], full symmetric, armature on the joints' diagonal;
      * ``h`` (18) bias forces C(q, v) v + g(q) [N, N·m], plus on the joint rows the known joint losses
        d qdot + F tanh(qdot / v_eps) (damping d, Coulomb friction F of the options; 0 by default): the
        equations of motion are M vdot + h = S u + J' lambda;
      * ``foot_pos_in_world`` (4x3) foot-sphere centres [m];
      * ``foot_vel_in_world`` (4x3) their linear velocities [m/s];
      * ``foot_jac_in_world`` (4x3x18) translational Jacobians, world axes;
      * ``foot_jdotv_in_world`` (4x3) classical acceleration at vdot = 0, i.e. J̇·v [m/s²].
    """

    def __init__(self, robot: RobotDescription | None = None, options: ModelOptions | None = None) -> None:
        self.robot = robot = robot if robot is not None else default_robot()
        self.options = options = options or ModelOptions()
        self.urdf_path = options.urdf or str(robot.urdf_path)
        self.model = pinocchio_model(robot, options.urdf)
        model_options.apply(self.model, options, robot.trunk_link)
        self.data = self.model.createData()
        # known joint losses added to h's joint rows each tick (skipped when all are 0: h is Pinocchio's nle)
        self.joint_damping = np.array(self.model.damping[6:])  # [N·m·s/rad] core order, URDF's + options'
        self.joint_frictionloss = np.array(self.model.friction[6:])  # [N·m] core order, URDF's + options'
        self.frictionloss_smoothing_radps = float(options.frictionloss_smoothing_radps)  # [rad/s]
        self._joint_losses = bool(self.joint_damping.any() or self.joint_frictionloss.any())
        self.foot_frame_ids = [self.model.getFrameId(foot_frame(robot, i)) for i in range(quad.N_LEGS)]
        self.total_mass_kg = float(pin.computeTotalMass(self.model))
        nv = self.model.nv
        self.M = np.zeros((nv, nv))
        self.h = np.zeros(nv)
        self.foot_pos_in_world = np.zeros((quad.N_LEGS, 3))
        self.foot_vel_in_world = np.zeros((quad.N_LEGS, 3))
        self.foot_jac_in_world = np.zeros((quad.N_LEGS, 3, nv))
        self.foot_jdotv_in_world = np.zeros((quad.N_LEGS, 3))
        # velocity columns that move foot i: the free flyer's 6 and the leg's 3 (Pinocchio's support)
        cols = []
        for fid in self.foot_frame_ids:
            support = self.model.supports[self.model.frames[fid].parentJoint][1:]
            cols.append([self.model.joints[j].idx_v + k for j in support for k in range(self.model.joints[j].nv)])
        self._foot_cols = np.array(cols, dtype=np.int64)  # (4, 9)

    def update(self, q: np.ndarray, v: np.ndarray) -> None:
        """Compute all per-tick terms at (q, v) (Pinocchio conventions, see module doc)."""
        m, d = self.model, self.data
        # kinematics at (q, v), joint Jacobians data.J (world frame), M (upper triangle), nonlinear effects;
        # then data.dJ, the time derivative of data.J, for the feet's J̇v
        pin.computeAllTerms(m, d, q, v)
        pin.computeJointJacobiansTimeVariation(m, d, q, v)
        place, (f0, f1, f2, f3) = pin.updateFramePlacement, self.foot_frame_ids
        _dynamics_and_foot_terms(
            d.M, d.nle, d.J, d.dJ, v, self._foot_cols,
            place(m, d, f0).translation, place(m, d, f1).translation,
            place(m, d, f2).translation, place(m, d, f3).translation,
            self.M, self.h, self.foot_pos_in_world, self.foot_jac_in_world, self.foot_vel_in_world,
            self.foot_jdotv_in_world,
        )  # fmt: skip
        if self._joint_losses:
            _add_joint_losses(self.h, v, self.joint_damping, self.joint_frictionloss,
                              self.frictionloss_smoothing_radps)

    def neutral_q(self) -> np.ndarray:
        return pin.neutral(self.model)


@kernel
def _add_joint_losses(h, v, damping, frictionloss, v_eps):
    """h[6 + j] += damping[j] v[6 + j] + frictionloss[j] tanh(v[6 + j] / v_eps) for the 12 joints: the torques
    [N·m] the joint losses take from the motors (MuJoCo's passive damping force is -damping qdot)."""
    for j in range(damping.shape[0]):
        w = v[6 + j]
        h[6 + j] += damping[j] * w + frictionloss[j] * np.tanh(w / v_eps)


@kernel
def _dynamics_and_foot_terms(M_upper, nle, J_world, dJ_world, v, foot_cols, p0, p1, p2, p3,
                             M, h, foot_pos, foot_jac, foot_vel, foot_jdotv):  # fmt: skip
    """M = the symmetric matrix of Pinocchio's upper triangle ``M_upper``; h = ``nle``; per foot i with
    centre p_i [m] (``p0`` .. ``p3``, world):

    * J_p = J_lin + omega x p, the translational Jacobian (world axes) from the joint Jacobians
      ``J_world`` (6 x nv, Pinocchio ``data.J``: linear rows = velocity of the body point at the world
      origin, angular rows = angular velocity, world axes), on the columns ``foot_cols[i]`` that move the
      foot, 0 elsewhere;
    * v_p = J_p v [m/s];
    * J̇_p v = J̇_lin v + (J̇_ang v) x p + omega x v_p [m/s²], the classical acceleration at vdot = 0, from
      ``dJ_world`` (Pinocchio ``data.dJ``, the time derivative of ``data.J``) and omega = J_ang v.
    """
    n = M.shape[0]
    for r in range(n):
        for c in range(r, n):
            M[r, c] = M_upper[r, c]
            M[c, r] = M_upper[r, c]
        h[r] = nle[r]
    foot_jac[:] = 0.0
    for i in range(foot_cols.shape[0]):
        p = p0 if i == 0 else p1 if i == 1 else p2 if i == 2 else p3
        px, py, pz = p[0], p[1], p[2]
        foot_pos[i, 0], foot_pos[i, 1], foot_pos[i, 2] = px, py, pz
        vx = vy = vz = 0.0  # v_p
        wx = wy = wz = 0.0  # omega
        ax = ay = az = 0.0  # J̇_lin v
        bx = by = bz = 0.0  # J̇_ang v
        for c in foot_cols[i]:
            ox, oy, oz = J_world[3, c], J_world[4, c], J_world[5, c]
            jx = J_world[0, c] + oy * pz - oz * py
            jy = J_world[1, c] + oz * px - ox * pz
            jz = J_world[2, c] + ox * py - oy * px
            foot_jac[i, 0, c], foot_jac[i, 1, c], foot_jac[i, 2, c] = jx, jy, jz
            vc = v[c]
            vx, vy, vz = vx + jx * vc, vy + jy * vc, vz + jz * vc
            wx, wy, wz = wx + ox * vc, wy + oy * vc, wz + oz * vc
            ax, ay, az = ax + dJ_world[0, c] * vc, ay + dJ_world[1, c] * vc, az + dJ_world[2, c] * vc
            bx, by, bz = bx + dJ_world[3, c] * vc, by + dJ_world[4, c] * vc, bz + dJ_world[5, c] * vc
        foot_vel[i, 0], foot_vel[i, 1], foot_vel[i, 2] = vx, vy, vz
        foot_jdotv[i, 0] = ax + (by * pz - bz * py) + (wy * vz - wz * vy)
        foot_jdotv[i, 1] = ay + (bz * px - bx * pz) + (wz * vx - wx * vz)
        foot_jdotv[i, 2] = az + (bx * py - by * px) + (wx * vy - wy * vx)
