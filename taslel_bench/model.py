"""The controller's model of the A1: Pinocchio, built from the same URDF as the plant.

All per-tick rigid-body quantities the nominal controller and the safety filter need are computed once
by :meth:`A1Model.update` into preallocated arrays (no allocation per tick beyond Pinocchio's own).

Frames and units: ``q`` is Pinocchio's (position of the trunk origin in world [m], quaternion xyzw,
12 joint angles [rad] in :data:`robot.LEGS` order); ``v`` is (trunk linear velocity in the **trunk**
frame [m/s], angular velocity in the trunk frame [rad/s], joint velocities [rad/s]). Foot quantities are
expressed at the foot-sphere centre in LOCAL_WORLD_ALIGNED axes (world orientation).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from taslel_bench import robot

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class A1Model:
    """Pinocchio model + data and the per-tick dynamics terms.

    After :meth:`update`:
      * ``M`` (18x18) mass matrix [kg, kg·m, kg·m²], full symmetric;
      * ``h`` (18) bias forces C(q, v) v + g(q) [N, N·m];
      * ``foot_pos_in_world`` (4x3) foot-sphere centres [m];
      * ``foot_vel_in_world`` (4x3) their linear velocities [m/s];
      * ``foot_jac_in_world`` (4x3x18) translational Jacobians, world axes;
      * ``foot_jdotv_in_world`` (4x3) classical acceleration at vdot = 0, i.e. J̇·v [m/s²].
    """

    def __init__(self) -> None:
        self.model = pin.buildModelFromUrdf(str(robot.a1_urdf_path()), pin.JointModelFreeFlyer())
        self.data = self.model.createData()
        names = list(self.model.names)[2:]
        if tuple(names) != robot.JOINT_NAMES:
            raise RuntimeError(f"Pinocchio joint order {names} differs from robot.JOINT_NAMES")
        self.foot_frame_ids = [self.model.getFrameId(f) for f in robot.FOOT_FRAMES]
        self.total_mass_kg = float(pin.computeTotalMass(self.model))
        nv = self.model.nv
        self.M = np.zeros((nv, nv))
        self.h = np.zeros(nv)
        self.foot_pos_in_world = np.zeros((robot.N_LEGS, 3))
        self.foot_vel_in_world = np.zeros((robot.N_LEGS, 3))
        self.foot_jac_in_world = np.zeros((robot.N_LEGS, 3, nv))
        self.foot_jdotv_in_world = np.zeros((robot.N_LEGS, 3))
        self._lower = np.tril_indices(nv, -1)

    def update(self, q: np.ndarray, v: np.ndarray) -> None:
        """Compute all per-tick terms at (q, v) (Pinocchio conventions, see module doc)."""
        m, d = self.model, self.data
        # one pass: kinematics at (q, v) with zero joint acceleration (so frame accelerations are J̇v),
        # joint Jacobians, M (upper triangle), nonlinear effects
        pin.computeAllTerms(m, d, q, v)
        pin.updateFramePlacements(m, d)
        self.M[:] = d.M
        self.M[self._lower] = self.M.T[self._lower]  # mirror the upper triangle
        self.h[:] = d.nle
        oMf, pos, jac, jdotv = d.oMf, self.foot_pos_in_world, self.foot_jac_in_world, self.foot_jdotv_in_world
        for i, fid in enumerate(self.foot_frame_ids):
            pos[i] = oMf[fid].translation
            jac[i] = pin.getFrameJacobian(m, d, fid, _LWA)[:3]
            jdotv[i] = pin.getFrameClassicalAcceleration(m, d, fid, _LWA).linear
        np.matmul(jac, v, out=self.foot_vel_in_world)  # foot-centre velocity J v (one product for 4 feet)

    def neutral_q(self) -> np.ndarray:
        return pin.neutral(self.model)
