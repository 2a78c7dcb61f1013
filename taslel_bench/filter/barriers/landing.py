"""Landing with small tangential velocity (``filter.barriers.landing``, preset ``filter=terrain``): near
touchdown the swing foot's speed along the terrain is bounded by its distance to it, so it arrives nearly
at rest along the surface (less touchdown slip)."""

from __future__ import annotations

import numpy as np

from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.layout import INACTIVE_RHS, NV, TickInputs
from taslel_bench.interfaces import QPProblem
from taslel_bench.robot import quadruped as quad

MIN_TANGENTIAL_SPEED_MPS = 1e-3  # [m/s] below this the direction of the tangential velocity is undefined: no row


class LandingVelocity(Barrier):
    """One row per swing foot in the second half of its swing within ``activation_m`` [m] of the terrain: a
    first-order CBF h = ``speed_per_distance`` d - e . v >= 0 (the tangential speed at most k d [m/s]),
    d the foot sphere's distance to the terrain, n its normal, v_t = v - (n . v) n the tangential velocity and
    e = v_t / |v_t| (held for the tick). hdot = k n . v - e . (J vdot + J̇v) (e and n held) and the row
    enforces hdot + a2 h >= 0:  e'J vdot <= a2 h + k n . v - e . J̇v. ``h_e`` is h (relative degree one),
    so the filter's planned condition reads psi = hdot + a2 h like the second-order barriers'."""

    def __init__(self, world: BarrierWorld, name: str = "landing", speed_per_distance: float = 10.0,
                 activation_m: float = 0.04, min_phase: float = 0.5) -> None:  # fmt: skip
        super().__init__(world, name)
        self.terrain = world.terrain
        self.k, self.activation_m, self.min_phase = float(speed_per_distance), float(activation_m), float(min_phase)

    def write(self, qp: QPProblem, x: TickInputs) -> None:
        m, r0 = x.model, self.start
        qp.G[r0 : r0 + quad.N_LEGS] = 0.0
        qp.h[r0 : r0 + quad.N_LEGS] = INACTIVE_RHS
        self.h[:], self.h_e[:] = np.nan, np.nan
        legs = np.flatnonzero(~np.asarray(x.in_stance, bool) & (np.asarray(x.swing_phase) >= self.min_phase))
        if legs.size == 0:
            return
        dist, normal, _ = self.terrain.near_distance(m.foot_pos_in_world[legs], self.foot_radius_m)
        for d, n, i in zip(dist, normal, legs, strict=True):
            if not np.isfinite(d) or d >= self.activation_m:
                continue
            v = m.foot_vel_in_world[i]
            v_t = v - (n @ v) * n
            speed = float(np.linalg.norm(v_t))
            if speed < MIN_TANGENTIAL_SPEED_MPS:
                continue
            e = v_t / speed
            h = self.k * max(float(d), 0.0) - speed
            qp.G[r0 + i, :NV] = e @ m.foot_jac_in_world[i]
            qp.h[r0 + i] = self.alpha2 * h + self.k * float(n @ v) - float(e @ m.foot_jdotv_in_world[i])
            self.h[i], self.h_e[i] = h, h
        self.tighten(qp)
