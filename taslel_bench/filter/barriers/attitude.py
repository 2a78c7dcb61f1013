"""Trunk attitude (``filter.barriers.attitude``, preset ``filter=terrain``): the trunk's pitch and roll kept
within +-``max_tilt_deg``. Not a leg barrier: its two rows are ``pitch`` and ``roll``.

On a step or a slope the nominal trot (joint PD about a stand pose, no terrain knowledge) pitches the trunk
as its front feet climb; measured on ``steps`` (seed 0), with the front feet over the first riser the pitch
grew to 15 deg and the rear thigh hit the floor."""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.layout import INACTIVE_RHS, TickInputs
from taslel_bench.interfaces import QPProblem


class TrunkAttitude(Barrier):
    """h = theta_max² - theta² >= 0 for the pitch theta and the roll phi of the trunk (ZYX Euler angles from
    Pinocchio's base quaternion, world frame). With the base angular velocity omega (trunk axes, v[3:6]) and
    its derivative (vdot[3:6]): thetadot = cos phi omega_y - sin phi omega_z, phidot ~ omega_x (products of
    rates in the second derivatives dropped), hdot = -2 theta thetadot, hddot = -2 thetadot² - 2 theta
    thetaddot. Row (ECBF, h_e = hdot + a1 h): 2 theta (cos phi vdot_4 - sin phi vdot_5) <= a2 h_e + a1 hdot -
    2 thetadot²; the same for the roll with vdot_3."""

    def __init__(self, world: BarrierWorld, name: str = "attitude", max_tilt_deg: float = 12.0) -> None:
        super().__init__(world, name)
        self.max_tilt_rad = math.radians(float(max_tilt_deg))

    rows = ("pitch", "roll")

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        r0 = self.start
        qp.G[r0 : r0 + self.n_rows] = 0.0
        qp.h[r0 : r0 + self.n_rows] = INACTIVE_RHS
        self.h[:], self.h_e[:] = np.nan, np.nan
        rot = np.asarray(x.model.data.oMi[1].rotation)  # trunk -> world
        pitch = math.asin(max(-1.0, min(1.0, -rot[2, 0])))
        roll = math.atan2(rot[2, 1], rot[2, 2])
        wx, wy, wz = x.v[3], x.v[4], x.v[5]
        cr, sr = math.cos(roll), math.sin(roll)
        tmax2 = self.max_tilt_rad**2
        for slot, angle, rate, coeffs in ((0, pitch, cr * wy - sr * wz, ((4, cr), (5, -sr))),
                                          (1, roll, wx, ((3, 1.0),))):  # fmt: skip
            h = tmax2 - angle * angle
            hdot = -2.0 * angle * rate
            h_e = hdot + self.alpha1 * h
            for col, c in coeffs:
                qp.G[r0 + slot, col] = 2.0 * angle * c
            qp.h[r0 + slot] = self.alpha2 * h_e + self.alpha1 * hdot - 2.0 * rate * rate
            self.h[slot], self.h_e[slot] = h, h_e
        self.tighten(qp)
