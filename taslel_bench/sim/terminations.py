"""When an episode ends: the one fall rule and the state guard, used by every loop that runs a robot (the
benchmark, estimator data collection, in-loop studies) through :class:`taslel_bench.sim.episode.Episode`.

Named terms, checked after **every physics step** on the state that step produced:

* ``trunk_height``: the trunk origin below ``FallRule.height_m`` [m] (read from ``qpos``; ``xpos`` still
  holds the step's starting state after ``mj_step``);
* ``trunk_tilt``: the angle between trunk z and world z beyond ``FallRule.tilt_deg``;
* ``body_contact``: the trunk, a hip or a thigh (anything above the knee) touching the terrain at
  distance <= 0 (MuJoCo's contacts, found for the step's *starting* state: the time is one step earlier).

and after every control tick, ``non_finite_state``: NaN or infinity anywhere in the state, a joint/trunk
speed beyond ``max_speed``, or MuJoCo resetting the data (its own divergence guard): an error, not a fall.
The time of a fall is that of the first physics state past a threshold, on the physics-step grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from taslel_bench.plant.contacts import FootContactReader, more_contacts_than_feet
from taslel_bench.util.jit import kernel

TERMS = ("trunk_height", "trunk_tilt", "body_contact")


@dataclass(frozen=True)
class FallRule:
    """Thresholds of the fall terms (``robot.fall_height_m``, ``robot.fall_tilt_deg``)."""

    height_m: float  # [m] trunk origin below this -> fall
    tilt_deg: float  # [deg] trunk tilt beyond this -> fall
    max_speed: float = 200.0  # [rad/s, m/s] ||qvel||_2 beyond this (or non-finite) -> "exploding state" error


@dataclass
class Fall:
    term: str  # one of TERMS
    reason: str  # what crossed which threshold, for people
    t_s: float  # [s] episode time of the first physics state past the threshold


class Terminations:
    """The fall terms and the state guard of one episode (``qpos_adr``: the free joint's qpos address)."""

    def __init__(self, rule: FallRule, qpos_adr: int, contacts: FootContactReader, physics_dt_s: float) -> None:
        self.rule, self.a, self.contacts, self.dt = rule, qpos_adr, contacts, physics_dt_s
        self._height_m = float(rule.height_m)  # [m]
        self._cos_tilt_min = math.cos(math.radians(rule.tilt_deg))
        self._vmax_sq = rule.max_speed**2
        self._found_rows = contacts.found_rows

    def after_step(self, qpos: np.ndarray, data: mujoco.MjData, t_s: float) -> Fall | None:
        """The first fall term crossed by the state ``qpos`` a physics step produced at episode time ``t_s``.
        Also updates the contact reader's non-foot contact flags (unless the trunk term ended the episode)."""
        contacts = self.contacts
        term = _step_term(qpos, self.a, self._height_m, self._cos_tilt_min, contacts.sensordata_of(data),
                         self._found_rows, data.ncon)  # one compiled call  # fmt: skip
        if term == _NONE:
            contacts.clear_non_foot_contacts()
            return None
        return self.fall_of(term, qpos, data, t_s)

    def fall_of(self, term: int, qpos: np.ndarray, data: mujoco.MjData | None, t_s: float) -> Fall | None:
        """The fall that :func:`_step_term`'s code ``term`` (not _NONE) means for the state ``qpos`` a physics
        step produced at episode time ``t_s`` [s] (None: only shins touch); ``data`` holds the contacts of the step's
        starting state (MuJoCo's after ``mj_step``), read only for :data:`READS_CONTACTS` (None for the others)."""
        contacts = self.contacts
        if term == _HEIGHT:
            z = qpos[self.a + 2]
            return Fall("trunk_height", f"trunk height {z:.3f} m < {self.rule.height_m} m", t_s)
        if term == _TILT:
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, _cos_tilt(qpos, self.a)))))
            return Fall("trunk_tilt", f"trunk tilt {tilt:.0f} deg", t_s)
        if data is None:
            raise ValueError("Terminations.fall_of: the contacts term needs data with the step's starting contacts")
        contacts.classify_other_contacts(data)  # term == _OTHER_CONTACTS: of the step's starting state
        if contacts.body_contact:
            name = contacts.non_foot_contact_name
            return Fall("body_contact", f"{name} (above the knee) touched the terrain", t_s - self.dt)
        return None

    def after_steps(self, qpos: np.ndarray, ids: np.ndarray, sensordata: np.ndarray, ncon: np.ndarray,
                    out: np.ndarray) -> None:
        """:meth:`after_step`'s compiled test for the simulations ``ids`` of a batch (rows of ``qpos``, ``sensordata``,
        ``ncon``): ``out[j]`` = the term code of ``ids[j]``, 0 for none; a non-zero code goes to :meth:`fall_of`."""
        step_terms(qpos, ids, self.a, self._height_m, self._cos_tilt_min, sensordata, self._found_rows, ncon, out)

    def states_ok(self, qpos: np.ndarray, qvel: np.ndarray, ids: np.ndarray, out: np.ndarray) -> None:
        """``out[j]`` = not :meth:`state_is_bad` for the simulation ``ids[j]`` of a batch (rows of qpos and qvel)."""
        states_ok(qpos, qvel, ids, self._vmax_sq, out)

    def state_is_bad(self, qpos: np.ndarray, qvel: np.ndarray) -> bool:
        """NaN/inf anywhere in the state or a speed beyond the bound (one dot product each)."""
        return not _state_ok(qpos, qvel, self._vmax_sq)

    def on_grid(self, t_s: float) -> float:
        """``t_s`` rounded to the physics-step grid [s]."""
        return round(t_s / self.dt) * self.dt


_NONE, _HEIGHT, _TILT, _OTHER_CONTACTS = 0, 1, 2, 3  # what _trunk_term / _step_term found
READS_CONTACTS = _OTHER_CONTACTS  # the term code whose fall (:meth:`Terminations.fall_of`) reads the contact list


@kernel
def _cos_tilt(qpos, a):  # pragma: no cover - compiled
    """cos of the angle between trunk z and world z from the trunk quaternion qpos[a + 3 : a + 7] (w, x, y, z)."""
    return 1.0 - 2.0 * (qpos[a + 4] * qpos[a + 4] + qpos[a + 5] * qpos[a + 5])


@kernel
def _trunk_term(qpos, a, height_m, cos_tilt_min):  # pragma: no cover - compiled
    """_HEIGHT if the trunk origin qpos[a + 2] is below ``height_m`` [m], else _TILT if the trunk tilt's cos
    is below ``cos_tilt_min``, else _NONE (the order of :data:`TERMS`)."""
    if qpos[a + 2] < height_m:
        return _HEIGHT
    if _cos_tilt(qpos, a) < cos_tilt_min:
        return _TILT
    return _NONE


@kernel
def _step_term(qpos, a, height_m, cos_tilt_min, sensordata, found_rows, ncon):  # pragma: no cover - compiled
    """:func:`_trunk_term`; then, if neither trunk term is crossed, _OTHER_CONTACTS when the contact list
    holds more than the feet's contacts (only then can the body touch the terrain), else _NONE."""
    term = _trunk_term(qpos, a, height_m, cos_tilt_min)
    if term == _NONE and more_contacts_than_feet(sensordata, found_rows, ncon):
        return _OTHER_CONTACTS
    return term


@kernel
def _state_ok(qpos, qvel, vmax_sq):  # pragma: no cover - compiled
    """||qvel||² < vmax_sq and every qpos entry finite (a NaN speed fails the first test)."""
    v2 = 0.0
    for x in qvel:
        v2 += x * x
    acc = 0.0
    for x in qpos:
        acc += x * 0.0
    return v2 < vmax_sq and acc == 0.0


@kernel
def step_terms(qpos, ids, a, height_m, cos_tilt_min, sensordata, found_rows, ncon, out):  # pragma: no cover - compiled
    """:func:`_step_term` of each simulation ``ids[i]`` of a batch (rows of ``qpos``, ``sensordata``, ``ncon``) into
    ``out[i]``: the same compiled test as one episode's."""
    for i in range(ids.shape[0]):
        s = ids[i]
        out[i] = _step_term(qpos[s], a, height_m, cos_tilt_min, sensordata[s], found_rows, ncon[s])


@kernel
def states_ok(qpos, qvel, ids, vmax_sq, out):  # pragma: no cover - compiled
    """:func:`_state_ok` of each simulation ``ids[i]`` of a batch (rows of ``qpos`` and ``qvel``) into ``out[i]``."""
    for i in range(ids.shape[0]):
        out[i] = _state_ok(qpos[ids[i]], qvel[ids[i]], vmax_sq)
