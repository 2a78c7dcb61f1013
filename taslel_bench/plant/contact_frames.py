"""Every contact of a foot with the terrain, in MuJoCo's own contact frame.

:class:`ContactFrameReader` walks ``data.contact`` after a physics step and keeps, for each foot, up to
:data:`MAX_CONTACTS_PER_FOOT` contacts of the foot sphere with any non-robot geom (floor, logs, steps,
heightfields): the force MuJoCo applied in that contact's frame (``mj_contactForce``: normal first, then the
two tangential components) [N], the contact's tangential friction coefficient ``friction[0]`` [-], the unit
normal pointing out of the terrain into the foot (world axes), and the tangential speed [m/s] of the foot's
material point at the contact position relative to the terrain's (the bodies' ``cvel``, as
``mj_objectVelocity`` reads it, moved to ``contact.pos``; the normal component removed) — the slip at the contact, not at the sphere's
lowest point. It also flags, per leg, a non-foot link of that leg (calf, thigh, hip) touching an obstacle
geom at distance <= 0 (a leg-link trip).

After ``mj_step`` the contact list, the constraint forces and the body velocities are those of the step's
*starting* state, the same instant the foot sensors (:mod:`taslel_bench.plant.contacts`) report.
"""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.plant.contacts import foot_geom_ids, obstacle_geom_mask
from taslel_bench.robot import a1

MAX_CONTACTS_PER_FOOT = 3  # a sphere meets a plane and a log's flank at once at most twice in practice


class ContactFrameReader:
    """Per-foot contact-frame quantities of the last step (arrays (4, K), K = MAX_CONTACTS_PER_FOOT, zero /
    False in unused slots; ``count`` (4,) the number of foot-terrain contacts, possibly more than K, in which
    case the K with the largest normal force are kept):

    ``normal_force_n`` f_n [N] >= 0; ``tangential_force_n`` |f_t| [N]; ``mu`` tangential friction [-];
    ``normal_w`` (4, K, 3) unit normal out of the terrain, world axes; ``slip_mps`` tangential speed of the
    contact point relative to the terrain [m/s]; ``on_obstacle`` the terrain geom is an obstacle and the
    contact is touching (distance <= 0); ``touching`` the contact's distance is <= 0 (not only inside a
    margin); ``leg_link_obstacle`` (4,) a non-foot link of the leg touches an
    obstacle (distance <= 0)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        feet = foot_geom_ids(model)
        root = model.body_rootid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, a1.TRUNK_BODY)]
        self._is_robot = model.body_rootid[model.geom_bodyid] == root
        self._foot_leg = np.full(model.ngeom, -1)
        self._foot_leg[feet] = np.arange(a1.N_LEGS)
        self._link_leg = np.full(model.ngeom, -1)  # leg of every other robot geom below the trunk
        for g in range(model.ngeom):
            name = model.body(model.geom_bodyid[g]).name
            for i, leg in enumerate(a1.LEGS):
                if self._is_robot[g] and self._foot_leg[g] < 0 and name.startswith(f"{leg}_"):
                    self._link_leg[g] = i
        self._is_obstacle = obstacle_geom_mask(model)
        k = MAX_CONTACTS_PER_FOOT
        self.normal_force_n = np.zeros((a1.N_LEGS, k))
        self.tangential_force_n = np.zeros((a1.N_LEGS, k))
        self.mu = np.zeros((a1.N_LEGS, k))
        self.normal_w = np.zeros((a1.N_LEGS, k, 3))
        self.slip_mps = np.zeros((a1.N_LEGS, k))
        self.on_obstacle = np.zeros((a1.N_LEGS, k), bool)
        self.touching = np.zeros((a1.N_LEGS, k), bool)
        self.count = np.zeros(a1.N_LEGS, np.int32)
        self.leg_link_obstacle = np.zeros(a1.N_LEGS, bool)
        self._force = np.zeros(6)
        self._elliptic = model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC

    def _clear(self) -> None:
        for a in (self.normal_force_n, self.tangential_force_n, self.mu, self.normal_w, self.slip_mps):
            a.fill(0.0)
        self.on_obstacle.fill(False)
        self.touching.fill(False)
        self.count.fill(0)
        self.leg_link_obstacle.fill(False)

    def read(self, data: mujoco.MjData) -> None:
        """Fill the arrays from ``data`` (after ``mj_step`` or ``mj_forward``); vectorised over contacts."""
        self._clear()
        if data.ncon == 0:
            return
        con = data.contact
        geom = con.geom
        robot = self._is_robot[geom]
        terrain_pair = robot[:, 0] != robot[:, 1]
        foot_leg = self._foot_leg[geom]
        self._leg_links(geom, terrain_pair & (con.dist <= 0.0))
        idx = np.flatnonzero(terrain_pair & ((foot_leg[:, 0] >= 0) | (foot_leg[:, 1] >= 0)))
        if idx.size == 0:
            return
        pair = geom[idx]
        foot_is_geom2 = foot_leg[idx, 1] >= 0
        foot = np.where(foot_is_geom2, pair[:, 1], pair[:, 0])
        ground = np.where(foot_is_geom2, pair[:, 0], pair[:, 1])
        force = self._forces_in_contact_frame(data, con, idx)  # [N] (k, 3) normal, tangent1, tangent2
        n = con.frame[idx, :3] * np.where(foot_is_geom2, 1.0, -1.0)[:, None]  # out of the terrain, into the foot
        p = con.pos[idx]
        v = self._point_velocity(data, foot, p) - self._point_velocity(data, ground, p)  # [m/s] foot - terrain
        v_t = v - np.sum(v * n, axis=1)[:, None] * n
        legs = self._foot_leg[foot]
        order = np.lexsort((-force[:, 0], legs))  # by leg, then the largest normal force first
        legs_sorted = legs[order]
        slot = np.arange(order.size) - np.searchsorted(legs_sorted, legs_sorted, side="left")
        keep = slot < MAX_CONTACTS_PER_FOOT
        j, leg, slot = order[keep], legs_sorted[keep], slot[keep]
        np.add.at(self.count, legs, 1)
        dist = con.dist[idx]
        self.normal_force_n[leg, slot] = force[j, 0]
        self.tangential_force_n[leg, slot] = np.hypot(force[j, 1], force[j, 2])
        self.mu[leg, slot] = con.friction[idx[j], 0]
        self.normal_w[leg, slot] = n[j]
        self.slip_mps[leg, slot] = np.linalg.norm(v_t[j], axis=1)
        self.touching[leg, slot] = dist[j] <= 0.0
        self.on_obstacle[leg, slot] = self._is_obstacle[ground[j]] & (dist[j] <= 0.0)

    def _leg_links(self, geom: np.ndarray, touching: np.ndarray) -> None:
        """``leg_link_obstacle`` from the touching robot-terrain contacts ``geom`` (ncon, 2)."""
        link_leg = self._link_leg[geom]
        for side in (0, 1):
            hit = touching & (link_leg[:, side] >= 0) & self._is_obstacle[geom[:, 1 - side]]
            self.leg_link_obstacle[link_leg[hit, side]] = True

    def _forces_in_contact_frame(self, data: mujoco.MjData, con, idx: np.ndarray) -> np.ndarray:
        """(k, 3) [N] force of contacts ``idx`` in their frames: with the elliptic cone and condim 3 the
        constraint forces themselves (what ``mj_contactForce`` returns), otherwise ``mj_contactForce``."""
        adr, dim = con.efc_address[idx], con.dim[idx]
        if self._elliptic and np.all(dim == 3) and np.all(adr >= 0):
            return data.efc_force[adr[:, None] + np.arange(3)]
        out = np.zeros((idx.size, 3))
        for r, i in enumerate(idx):
            mujoco.mj_contactForce(self.model, data, int(i), self._force)
            out[r] = self._force[:3]
        return out

    def _point_velocity(self, data: mujoco.MjData, geoms: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(k, 3) [m/s] world-axes velocity of the material point at ``p`` (k, 3) [m] of each geom's body:
        ``cvel`` holds (omega, v) at the subtree centre of mass of the body's root (as mj_objectVelocity
        reads it), so v_p = v + omega x (p - c)."""
        body = self.model.geom_bodyid[geoms]
        cvel = data.cvel[body]
        r = p - data.subtree_com[self.model.body_rootid[body]]
        w, v = cvel[:, :3], cvel[:, 3:]
        return v + np.stack([w[:, 1] * r[:, 2] - w[:, 2] * r[:, 1], w[:, 2] * r[:, 0] - w[:, 0] * r[:, 2],
                             w[:, 0] * r[:, 1] - w[:, 1] * r[:, 0]], axis=1)
