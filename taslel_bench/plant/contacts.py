"""Plant-side contact readings: which foot touches what, with which force, friction and slip.

:class:`FootContactReader` reads the foot sensors that :func:`taslel_bench.plant.build.add_foot_contact_sensors`
adds (one slice of ``sensordata`` per physics step) and classifies the other robot-terrain contacts (a fall,
a lower leg on the floor, a trip on an obstacle). Frames: world axes, forces on the robot [N].
"""

from __future__ import annotations

import mujoco
import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.geoms import OBSTACLE_BODY, OBSTACLE_SENSOR_SUFFIX
from taslel_bench.util.jit import kernel


def obstacle_geom_mask(model: mujoco.MjModel) -> np.ndarray:
    """(ngeom,) bool: geoms of the :data:`OBSTACLE_BODY` (all False when the plant has none)."""
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBSTACLE_BODY)
    return model.geom_bodyid == body if body >= 0 else np.zeros(model.ngeom, bool)



def foot_radius_m(model: mujoco.MjModel) -> float:
    """[m] radius of the plant's foot spheres (the core's ``FL_foot`` geom; every robot has one radius)."""
    return float(model.geom_size[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, quad.FOOT_FRAMES[0]), 0])


def foot_geom_ids(model: mujoco.MjModel) -> np.ndarray:
    """MuJoCo geom ids of the four foot spheres, in :data:`quad.LEGS` order."""
    return np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f) for f in quad.FOOT_FRAMES])


def measure_contact_friction(model: mujoco.MjModel, data: mujoco.MjData) -> list[tuple[str, float]]:
    """(foot name, sliding friction coefficient) of every active foot contact, read from ``data.contact``."""
    feet = {int(g): name for g, name in zip(foot_geom_ids(model), quad.FOOT_FRAMES, strict=True)}
    out = []
    for i in range(data.ncon):
        c = data.contact[i]
        for g in (int(c.geom1), int(c.geom2)):
            if g in feet:
                out.append((feet[g], float(c.friction[0])))
    return out


class FootContactReader:
    """Plant-side contact quantities of the four feet after a step, from the foot sensors.

    ``forces_in_world`` (4, 3): net contact force **on** each foot [N], world axes (0 without contact) —
    the constraint forces MuJoCo applied in the last physics step. ``in_contact`` (4,) bool.
    Robot geoms other than the feet, touching terrain (checked through ``data.contact`` only when the
    contact count exceeds the feet's; a contact counts only at distance <= 0, a contact inside a geom margin
    is not a touch; ``data.contact`` after ``mj_step`` holds the contacts of the step's *starting* state):
    ``body_contact``: the trunk, a hip or a thigh (anything above the knee) touches any terrain: a fall;
    ``shin_contact``: a lower leg (the other geoms of the body that carries a foot sphere) touches the
    floor; ``non_foot_obstacle_contact``: a lower leg touches a physical obstacle (:data:`OBSTACLE_BODY`):
    a trip. ``non_foot_contact_name``: the body of the first such geom.
    ``slip_velocity_in_world`` (4, 2): horizontal velocity [m/s] of the sphere's lowest point (the contact
    point on flat ground): v_centre + omega x (-r z) — the centre of a rolling, non-slipping foot moves.
    ``foot_pos_in_world`` (4, 3): foot-sphere centres [m].
    Positions and velocities are the sensors' values, i.e. at the start of the last physics step.

    :meth:`read` fills these from one ``data``; :meth:`from_sensor_log` computes the same quantities for a
    whole log of ``sensordata`` rows at once (the episode trace records raw rows in the control loop).
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.foot_geoms = foot_geom_ids(model)

        def sensor_adr(kind: str) -> np.ndarray:
            ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{f}_{kind}") for f in quad.FOOT_FRAMES]
            if min(ids) < 0:
                raise ValueError(
                    f"plant model has no foot {kind} sensors; build it with plant.add_foot_contact_sensors"
                )
            return model.sensor_adr[ids]

        adr = sensor_adr("contact")
        self._found_rows = adr.copy()  # number of contacts per foot
        self._force_rows = adr[:, None] + np.arange(1, 4)  # fx, fy, fz (by the foot), world axes
        self._torque_rows = adr[:, None] + np.arange(4, 7)  # net torque about the contact point, world axes
        self._point_rows = adr[:, None] + np.arange(7, 10)  # force-weighted centroid of the contact points
        self._pos_rows = sensor_adr("pos")[:, None] + np.arange(3)
        self._lin_rows = sensor_adr("linvel")[:, None] + np.arange(2)  # vx, vy
        self._ang_rows = sensor_adr("angvel")[:, None] + np.array([1, 0])  # wy, wx
        self.foot_radius_m = float(model.geom_size[self.foot_geoms[0], 0])  # [m] the plant's foot spheres
        self._radius_sign = self.foot_radius_m * np.array([-1.0, 1.0])  # v_x - r w_y, v_y + r w_x
        self._is_foot = np.zeros(model.ngeom, bool)
        self._is_foot[self.foot_geoms] = True
        robot_root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
        self._is_robot_geom = model.body_rootid[model.geom_bodyid] == model.body_rootid[robot_root]
        foot_bodies = model.geom_bodyid[self.foot_geoms]
        self._is_lower_leg = np.isin(model.geom_bodyid, foot_bodies) & ~self._is_foot  # calves (knee to foot)
        self._is_obstacle = obstacle_geom_mask(model)
        self.has_obstacles = bool(self._is_obstacle.any())
        if self.has_obstacles:  # per foot: number of contacts with the obstacles body
            self._obstacle_rows = sensor_adr(OBSTACLE_SENSOR_SUFFIX)
        self.body_contact = self.shin_contact = self.non_foot_obstacle_contact = False
        self.non_foot_contact_name = ""
        self.forces_in_world = np.zeros((quad.N_LEGS, 3))
        self.in_contact = np.zeros(quad.N_LEGS, bool)
        self.slip_velocity_in_world = np.zeros((quad.N_LEGS, 2))
        self.foot_pos_in_world = np.zeros((quad.N_LEGS, 3))
        self._data: mujoco.MjData | None = None
        self._sensordata = np.zeros(0)

    def read(self, data: mujoco.MjData) -> None:
        """All quantities from ``data`` after a step."""
        _read_feet(self.sensordata_of(data), self._found_rows, self._force_rows, self._ang_rows, self._lin_rows,
                   self._pos_rows, self._radius_sign, self.forces_in_world, self.in_contact,
                   self.slip_velocity_in_world, self.foot_pos_in_world)  # fmt: skip
        self.check_non_foot_contact(data)

    def check_non_foot_contact(self, data: mujoco.MjData) -> bool:
        """Only ``body_contact``, ``shin_contact`` and ``non_foot_obstacle_contact`` (cheap unless there are
        more contacts than foot contacts). Returns ``body_contact`` (a fall)."""
        if more_contacts_than_feet(self.sensordata_of(data), self._found_rows, data.ncon):
            self.classify_other_contacts(data)
        else:
            self.clear_non_foot_contacts()
        return self.body_contact

    def sensordata_of(self, data: mujoco.MjData) -> np.ndarray:
        """``data.sensordata`` (the view is made once per ``data``: MjData makes a new wrapper on every read)."""
        if data is not self._data:
            self._data, self._sensordata = data, data.sensordata
        return self._sensordata

    @property
    def found_rows(self) -> np.ndarray:
        """sensordata index of each foot's contact count (LEGS order)."""
        return self._found_rows

    def clear_non_foot_contacts(self) -> None:
        """No robot geom other than the feet touches the terrain (the contact list holds only foot contacts)."""
        self.body_contact = self.shin_contact = self.non_foot_obstacle_contact = False

    def from_sensor_log(self, sensors: np.ndarray) -> dict[str, np.ndarray]:
        """(n, nsensordata) rows -> ``forces_in_world`` (n, 4, 3), ``in_contact`` (n, 4),
        ``slip_velocity_in_world`` (n, 4, 2), ``foot_pos_in_world`` (n, 4, 3); same definitions as :meth:`read`."""
        n = sensors.shape[0]
        return {
            "forces_in_world": -sensors[:, self._force_rows],
            "torques_in_world": -sensors[:, self._torque_rows],
            "contact_point_in_world": sensors[:, self._point_rows],
            "in_contact": sensors[:, self._found_rows] > 0.0,
            "slip_velocity_in_world": sensors[:, self._lin_rows] + sensors[:, self._ang_rows] * self._radius_sign,
            "foot_pos_in_world": sensors[:, self._pos_rows],
            "obstacle_contact": (sensors[:, self._obstacle_rows] > 0.0 if self.has_obstacles
                                 else np.zeros((n, quad.N_LEGS), bool)),
        }

    def classify_other_contacts(self, data: mujoco.MjData) -> None:
        """Non-foot robot geoms touching terrain at distance <= 0 (see the class doc): sets ``body_contact``,
        ``shin_contact``, ``non_foot_obstacle_contact`` and ``non_foot_contact_name``."""
        con = data.contact
        geom = con.geom
        robot_side = self._is_robot_geom[geom]
        other = (con.dist <= 0.0) & ~(self._is_foot[geom[:, 0]] | self._is_foot[geom[:, 1]])
        other &= robot_side[:, 0] != robot_side[:, 1]
        if not other.any():
            self.body_contact = self.shin_contact = self.non_foot_obstacle_contact = False
            return
        pairs = geom[other]
        robot_geom = np.where(robot_side[other, 0], pairs[:, 0], pairs[:, 1])
        on_obstacle = self._is_obstacle[np.where(robot_side[other, 0], pairs[:, 1], pairs[:, 0])]
        lower = self._is_lower_leg[robot_geom]
        body, shin, trip = ~lower, lower & ~on_obstacle, lower & on_obstacle
        self.body_contact, self.shin_contact, self.non_foot_obstacle_contact = (
            bool(body.any()),
            bool(shin.any()),
            bool(trip.any()),
        )
        first = robot_geom[np.argmax(body)] if self.body_contact else robot_geom[0]
        self.non_foot_contact_name = self.model.body(self.model.geom_bodyid[first]).name


@kernel
def _read_feet(sd, found_rows, force_rows, ang_rows, lin_rows, pos_rows, radius_sign, forces, in_contact, slip,
               foot_pos):  # pragma: no cover - compiled
    """:meth:`FootContactReader.read`'s foot quantities from the sensor data ``sd`` in one call (the numpy steps it
    replaced, element by element: forces = -sd[force_rows] (the sensor gives the force by the foot), in contact =
    sd[found_rows] > 0, slip = sd[ang_rows] radius_sign + sd[lin_rows], foot_pos = sd[pos_rows])."""
    for i in range(found_rows.shape[0]):
        in_contact[i] = sd[found_rows[i]] > 0.0
        for a in range(3):
            forces[i, a] = -sd[force_rows[i, a]]
            foot_pos[i, a] = sd[pos_rows[i, a]]
        for a in range(2):
            slip[i, a] = sd[ang_rows[i, a]] * radius_sign[a] + sd[lin_rows[i, a]]


@kernel
def more_contacts_than_feet(sensordata, found_rows, ncon):  # pragma: no cover - compiled
    """True if MuJoCo's contact list (``ncon`` contacts) holds more than the feet's contacts: the sum of the
    foot sensors' contact counts ``sensordata[found_rows]``. Only then can another robot geom touch something."""
    n_found = 0.0
    for r in found_rows:
        n_found += sensordata[r]
    return ncon > n_found
