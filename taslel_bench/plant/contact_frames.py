"""Every contact of a foot with the terrain, in MuJoCo's own contact frame.

In the control loop :meth:`ContactFrameReader.record` copies the raw contact rows of the tick's last physics
step into a :class:`ContactLog` (the contact list's geoms, normals, positions, friction, distances, the
contact-frame forces, and the velocities of the foot bodies); after the episode :meth:`ContactFrameReader.frames`
turns them into per-foot quantities for every contact of a foot sphere with any non-robot geom (floor, logs,
steps, heightfields), vectorised over ticks:

* the force MuJoCo applied in that contact's frame (what ``mj_contactForce`` returns: normal first, then the
  two tangential components) [N]: f_n and |f_t|;
* the contact's tangential friction coefficient ``friction[0]`` [-];
* the unit normal pointing out of the terrain into the foot (world axes; frame row 0 points from geom1 to
  geom2);
* the tangential speed [m/s] of the foot's material point at the contact position (the body's ``cvel`` moved
  to ``contact.pos``, as ``mj_objectVelocity`` reads it; the normal component removed) — the slip at the
  contact, not at the sphere's lowest point. Terrain geoms are static (world or mocap bodies: no velocity);
* per leg, a non-foot link of that leg (calf, thigh, hip) touching an obstacle geom at distance <= 0, the same
  for any other terrain geom (the floor), and for an obstacle at contact points farther than
  :data:`FOOT_NEIGHBOURHOOD_M` from that leg's foot-sphere centre (the
  A1 URDF's calf box runs to the foot centre and leaves the 2 cm sphere 1.65 cm from it: where the foot stands on
  a log's curve the box grazes the log beside the foot, as it grazes the floor on flat ground).

After ``mj_step`` the contact list, the constraint forces and the body velocities are those of the step's
*starting* state, the same instant the foot sensors (:mod:`taslel_bench.plant.contacts`) report.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from taslel_bench.plant.contacts import foot_geom_ids, obstacle_geom_mask
from taslel_bench.robot import quadruped as quad
from taslel_bench.util.jit import kernel

# contacts kept per foot and tick: a sphere on the floor or a log has 1-2, on the rough heightfield (a union of
# triangular prisms) up to 6 measured; beyond this, the foot's least loaded ones are dropped and counted
# (``foot_contacts_dropped``)
MAX_CONTACTS_PER_FOOT = 8
FOOT_NEIGHBOURHOOD_M = 0.04  # [m] a leg-link contact point nearer than this to its foot's centre is beside the foot
FLANK_COS = math.cos(math.radians(45.0))  # a contact normal more than 45 deg from world z: a flank (riser, log side)
MAX_CONTACTS_LOGGED = 24  # contacts kept per tick (flat ground: 2-4; beyond, counted: ``contacts_not_logged``)


class ContactLog:
    """Raw contact rows per tick (``capacity`` ticks, up to :data:`MAX_CONTACTS_LOGGED` contacts each)."""

    def __init__(self, capacity: int) -> None:
        c, m = capacity, MAX_CONTACTS_LOGGED
        self.count = np.zeros(c, np.int32)  # ncon of the tick (may exceed m)
        self.geom = np.full((c, m, 2), -1, np.int32)
        self.normal = np.zeros((c, m, 3))  # frame row 0, from geom1 to geom2
        self.pos = np.zeros((c, m, 3))  # [m] contact position, world
        self.friction = np.zeros((c, m))  # [-] tangential coefficient
        self.dist = np.zeros((c, m))  # [m] negative: penetration
        self.force = np.zeros((c, m, 3))  # [N] in the contact frame (normal, tangent1, tangent2)
        self.foot_cvel = np.zeros((c, quad.N_LEGS, 6))  # (omega, v at the root's subtree com) of each foot's body
        self.root_com = np.zeros((c, 3))  # [m] subtree centre of mass of the robot's root body


class ContactFrameReader:
    """Records raw contact rows in the loop (:meth:`record`) and derives the per-foot contact-frame arrays
    (:meth:`frames`)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        feet = foot_geom_ids(model)
        trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
        self._root = int(model.body_rootid[trunk])
        self._is_robot = model.body_rootid[model.geom_bodyid] == self._root
        self._foot_leg = np.full(model.ngeom + 1, -1)  # index -1 (an unused row) maps to -1 too
        self._foot_leg[feet] = np.arange(quad.N_LEGS)
        self._link_leg = np.full(model.ngeom + 1, -1)  # leg of every other robot geom below the trunk
        for g in range(model.ngeom):
            name = model.body(model.geom_bodyid[g]).name
            for i, leg in enumerate(quad.LEGS):
                if self._is_robot[g] and self._foot_leg[g] < 0 and name.startswith(f"{leg}_"):
                    self._link_leg[g] = i
        self._is_robot = np.append(self._is_robot, True)
        self._is_obstacle = np.append(obstacle_geom_mask(model), False)
        self._foot_bodies = model.geom_bodyid[feet]
        # elliptic cones and condim 3 everywhere (no explicit pairs): a contact's 3 efc rows are its
        # contact-frame force, as mj_contactForce returns it; else mj_contactForce per contact
        self._efc_rows_are_forces = bool(model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and model.npair == 0
                                         and np.all(model.geom_condim == 3))
        self._force6 = np.zeros(6)
        # empty contact fields for a tick without contacts (the compiled copy's argument types)
        self._no_geom, self._no_rows = np.zeros((0, 2), np.int32), np.zeros((0, 9))
        self._no_dist, self._no_adr = np.zeros(0), np.zeros(0, np.int32)
        self._views: tuple | None = None  # (data, its cvel, its subtree_com): views made once per MjData

    # ---------------------------------------------------------------------------------------- in the loop
    def record(self, data: mujoco.MjData, log: ContactLog, k: int) -> None:
        """Copy tick ``k``'s contact rows (after ``mj_step`` or ``mj_forward``) into ``log`` (row ``k``): one
        compiled call (:func:`_copy_contacts`) with the contact list's fields, which are numpy views made on
        every read (~0.2 us each); the fixed-size ones are made once per ``data``."""
        if self._views is None or self._views[0] is not data:
            self._views = (data, data.cvel, data.subtree_com)
        _, cvel, subtree_com = self._views
        n = data.ncon
        if n == 0:
            self._record_no_contact(log, k, cvel, subtree_com)
            return
        con = data.contact
        efc_force = data.efc_force if self._efc_rows_are_forces else self._no_dist
        if _copy_contacts(k, n, con.geom, con.frame, con.pos, con.friction, con.dist, con.efc_address, efc_force,
                          self._efc_rows_are_forces, cvel, subtree_com, self._foot_bodies, self._root, log.count,
                          log.geom, log.normal, log.pos, log.friction, log.dist, log.force, log.foot_cvel,
                          log.root_com):  # fmt: skip
            return
        for i in range(min(n, MAX_CONTACTS_LOGGED)):  # forces not in the efc rows (see __init__)
            mujoco.mj_contactForce(self.model, data, i, self._force6)
            log.force[k, i] = self._force6[:3]

    def _record_no_contact(self, log: ContactLog, k: int, cvel: np.ndarray, subtree_com: np.ndarray) -> None:
        """Row ``k`` of a tick without contacts: the count, the foot bodies' cvel and the root's subtree com."""
        _copy_contacts(k, 0, self._no_geom, self._no_rows, self._no_rows, self._no_rows, self._no_dist, self._no_adr,
                       self._no_dist, False, cvel, subtree_com, self._foot_bodies, self._root, log.count, log.geom,
                       log.normal, log.pos, log.friction, log.dist, log.force, log.foot_cvel, log.root_com)  # fmt: skip

    def warm_up(self, data: mujoco.MjData) -> None:
        """Load the compiled copy for ``data``'s contact list and for a tick without contacts (into a scratch log)."""
        scratch = ContactLog(1)
        self.record(data, scratch, 0)
        self._record_no_contact(scratch, 0, data.cvel, data.subtree_com)

    # -------------------------------------------------------------------------------------- after the loop
    def frames(self, log: ContactLog, k0: int, k1: int, foot_pos_w: np.ndarray) -> dict[str, np.ndarray]:
        """Per-foot arrays of ticks ``k0:k1`` (shape (n, 4, K), K = MAX_CONTACTS_PER_FOOT, zero / False in
        unused slots; each foot's contacts sorted by normal force, the largest first, the K largest kept; the
        count of the others in ``foot_contacts_dropped`` (n, 4), of all in ``foot_contacts`` (n, 4), and the
        tick's contacts beyond
        :data:`MAX_CONTACTS_LOGGED` in ``contacts_not_logged`` (n,)):
        ``contact_fn_n`` f_n [N]; ``contact_ft_n`` |f_t| [N]; ``contact_mu`` [-]; ``contact_normal_w``
        (n, 4, K, 3) out of the terrain; ``contact_slip_mps`` [m/s]; ``contact_touching`` distance <= 0;
        ``contact_on_obstacle`` touching an obstacle geom; ``leg_link_obstacle_contact`` (n, 4),
        ``leg_link_floor_contact`` (n, 4) the same with a terrain geom that is not an obstacle, and
        ``leg_link_obstacle_contact_off_foot`` (n, 4) for contact points beyond :data:`FOOT_NEIGHBOURHOOD_M` of
        the leg's foot centre (``foot_pos_w`` (n, 4, 3) [m], the foot-sphere centres of those ticks: the foot
        sensors', read once per tick already)."""
        t = slice(k0, k1)
        n, kk = k1 - k0, MAX_CONTACTS_PER_FOOT
        geom = log.geom[t]
        robot = self._is_robot[geom]
        used = geom[..., 0] >= 0
        terrain_pair = used & (robot[..., 0] != robot[..., 1])
        touching = log.dist[t] <= 0.0
        out: dict[str, np.ndarray] = {"leg_link_obstacle_contact": np.zeros((n, quad.N_LEGS), bool),
               "leg_link_obstacle_contact_off_foot": np.zeros((n, quad.N_LEGS), bool),
               "leg_link_floor_contact": np.zeros((n, quad.N_LEGS), bool),
               "contacts_not_logged": np.maximum(log.count[t] - MAX_CONTACTS_LOGGED, 0)}
        link = self._link_leg[geom]
        for side in (0, 1):
            floor = terrain_pair & touching & (link[..., side] >= 0) & ~self._is_obstacle[geom[..., 1 - side]]
            tick, j = np.nonzero(floor)
            out["leg_link_floor_contact"][tick, link[tick, j, side]] = True
            hit = terrain_pair & touching & (link[..., side] >= 0) & self._is_obstacle[geom[..., 1 - side]]
            tick, j = np.nonzero(hit)
            leg = link[tick, j, side]
            out["leg_link_obstacle_contact"][tick, leg] = True
            from_foot = np.linalg.norm(log.pos[t][tick, j] - foot_pos_w[tick, leg], axis=1)
            off = from_foot > FOOT_NEIGHBOURHOOD_M
            out["leg_link_obstacle_contact_off_foot"][tick[off], leg[off]] = True
        foot_leg = self._foot_leg[geom]
        tick, j = np.nonzero(terrain_pair & ((foot_leg[..., 0] >= 0) | (foot_leg[..., 1] >= 0)))
        foot_is_geom2 = foot_leg[tick, j, 1] >= 0
        leg = np.where(foot_is_geom2, foot_leg[tick, j, 1], foot_leg[tick, j, 0])
        ground = np.where(foot_is_geom2, geom[tick, j, 0], geom[tick, j, 1])
        force = log.force[t][tick, j]
        normal = log.normal[t][tick, j] * np.where(foot_is_geom2, 1.0, -1.0)[:, None]
        # [N] per foot, every terrain contact's normal weighted by its normal force, summed (its direction: the
        # foot's mean contact normal; the foot's net force is the foot sensor's, the trace's grf_plant_w)
        out["foot_contact_normal_w"] = np.zeros((n, quad.N_LEGS, 3))
        np.add.at(out["foot_contact_normal_w"], (tick, leg), normal * force[:, :1])
        # [m/s] the foot's material point at the contact: v + omega x (p - c), c the root's subtree com
        cvel = log.foot_cvel[t][tick, leg]
        r = log.pos[t][tick, j] - log.root_com[t][tick]
        v = cvel[:, 3:] + np.cross(cvel[:, :3], r)
        v_t = v - np.sum(v * normal, axis=1)[:, None] * normal
        order = np.lexsort((-force[:, 0], leg, tick))  # per (tick, leg), the largest normal force first
        key = tick[order] * quad.N_LEGS + leg[order]
        slot = np.arange(order.size) - np.searchsorted(key, key, side="left")
        keep = slot < kk
        out["foot_contacts"] = np.zeros((n, quad.N_LEGS), np.int32)
        np.add.at(out["foot_contacts"], (tick, leg), 1)
        out["foot_contacts_dropped"] = np.maximum(out["foot_contacts"] - kk, 0)
        o, s = order[keep], slot[keep]
        ti, li = tick[o], leg[o]
        arrays = {"contact_fn_n": np.zeros((n, quad.N_LEGS, kk)), "contact_ft_n": np.zeros((n, quad.N_LEGS, kk)),
                  "contact_mu": np.zeros((n, quad.N_LEGS, kk)), "contact_slip_mps": np.zeros((n, quad.N_LEGS, kk)),
                  "contact_normal_w": np.zeros((n, quad.N_LEGS, kk, 3)),
                  "contact_touching": np.zeros((n, quad.N_LEGS, kk), bool),
                  "contact_on_obstacle": np.zeros((n, quad.N_LEGS, kk), bool)}
        arrays["contact_fn_n"][ti, li, s] = force[o, 0]
        arrays["contact_ft_n"][ti, li, s] = np.hypot(force[o, 1], force[o, 2])
        arrays["contact_mu"][ti, li, s] = log.friction[t][tick[o], j[o]]
        arrays["contact_normal_w"][ti, li, s] = normal[o]
        arrays["contact_slip_mps"][ti, li, s] = np.linalg.norm(v_t[o], axis=1)
        touch = touching[tick[o], j[o]]
        arrays["contact_touching"][ti, li, s] = touch
        arrays["contact_on_obstacle"][ti, li, s] = touch & self._is_obstacle[ground[o]]
        out.update(arrays)
        return out


@kernel
def _copy_contacts(k, n, geom, frame, pos, friction, dist, efc_address, efc_force, efc_rows_are_forces, cvel,
                   subtree_com, foot_bodies, root, L_count, L_geom, L_normal, L_pos, L_friction, L_dist, L_force,
                   L_foot_cvel, L_root_com):  # pragma: no cover - compiled  # fmt: skip
    """Row ``k`` of a :class:`ContactLog` from MuJoCo's contact list of ``n`` contacts (its fields ``geom``,
    ``frame``, ``pos``, ``friction``, ``dist``, ``efc_address``), the bodies' ``cvel`` and ``subtree_com``: the
    first MAX_CONTACTS_LOGGED contacts (unused geom slots -1), each foot body's cvel, the root's subtree centre of
    mass. The contact-frame forces are ``efc_force``'s three rows at each contact's efc address when
    ``efc_rows_are_forces`` and every address is >= 0 (elliptic cones, condim 3: what mj_contactForce returns);
    returns False when they are not written (the caller asks mj_contactForce)."""
    L_count[k] = n
    for i in range(foot_bodies.shape[0]):
        for j in range(6):
            L_foot_cvel[k, i, j] = cvel[foot_bodies[i], j]
    for j in range(3):
        L_root_com[k, j] = subtree_com[root, j]
    if n == 0:
        return True
    m = min(n, L_geom.shape[1])
    for i in range(m):
        L_geom[k, i, 0], L_geom[k, i, 1] = geom[i, 0], geom[i, 1]
        for j in range(3):
            L_normal[k, i, j] = frame[i, j]
            L_pos[k, i, j] = pos[i, j]
        L_friction[k, i] = friction[i, 0]
        L_dist[k, i] = dist[i]
    for i in range(m, L_geom.shape[1]):
        L_geom[k, i, 0], L_geom[k, i, 1] = -1, -1
    if not efc_rows_are_forces:
        return False
    for i in range(m):
        if efc_address[i] < 0:
            return False
    for i in range(m):
        for j in range(3):
            L_force[k, i, j] = efc_force[efc_address[i] + j]
    return True
