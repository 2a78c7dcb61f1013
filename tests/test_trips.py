"""The one trip rule (:mod:`taslel_bench.metrics.clearance`) on synthetic traces: a flank strike at any swing
phase (a), a contact on a walkable surface in the first half of the swing (b) and a leg link's contact are trips,
a walkable landing in the second half (c) is a touchdown, on the floor as on an obstacle; the 20 ms boundary in
whole ticks; and the contact slots' overflow counted, not dropped silently."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from taslel_bench.metrics.clearance import clearance_metrics, ticks_before_touchdown
from taslel_bench.plant.contact_frames import MAX_CONTACTS_LOGGED, MAX_CONTACTS_PER_FOOT, ContactFrameReader, ContactLog
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.build import Built
from tests.conftest import compose_cfg
from tests.test_metrics import clear_contact, set_contact, synthetic_trace

DT = 1e-3  # [s]
SWING = 200  # ticks of the planned swing (0.2 s)
FLANK = (-np.sin(np.radians(60)), 0.0, 0.5)  # a normal 60 deg from vertical
TILTED_TOP = (np.sin(np.radians(40)), 0.0, np.cos(np.radians(40)))  # 40 deg: still walkable


def swinging(n: int = 400, foot: int = 1) -> object:
    """A trace whose ``foot`` lifts off at tick 0 and swings (by the plan and the filter) for SWING ticks, its swing
    phase built as a gait clock builds it (tick x dt / swing time, in floating point), then stands; the other
    feet stand on the floor throughout."""
    tr = synthetic_trace(n=n)
    tr.t_s[:n] = np.arange(n) * DT
    tr.in_stance[:SWING, foot] = False
    tr.scheduled_stance[:] = True
    tr.scheduled_stance[:SWING, foot] = False
    tr.swing_phase[:SWING, foot] = np.arange(SWING) * DT / (SWING * DT)
    clear_contact(tr, slice(0, SWING), foot)
    return tr


@pytest.mark.parametrize("obstacle", [False, True])
def test_a_flank_strike_is_a_trip_at_any_swing_phase_on_every_surface(obstacle):
    for tick in (30, 150, 195):  # (a): early, late and just before the planned touchdown
        tr = swinging()
        set_contact(tr, [tick, tick + 1], 1, 5.0, normal=FLANK, obstacle=obstacle)
        m = clearance_metrics(tr, 0, DT)
        assert (m["trips"], m["foot_trips_flank"], m["touchdowns_early"]) == (1, 1, 0), tick
        assert m["foot_trips_floor"] == (0 if obstacle else 1)


@pytest.mark.parametrize("obstacle", [False, True])
def test_a_walkable_contact_in_the_first_half_of_the_swing_is_a_trip(obstacle):
    tr = swinging()
    set_contact(tr, [40, 41, 42], 1, 5.0, normal=TILTED_TOP, obstacle=obstacle)  # (b): a scuff while lifting
    m = clearance_metrics(tr, 0, DT)
    assert (m["trips"], m["foot_trips_top"], m["foot_trips_flank"], m["touchdowns_early"]) == (1, 1, 0, 0)
    assert m["foot_trips_floor"] == (0 if obstacle else 1)
    assert m["first_trip_s"] == pytest.approx(0.040)


@pytest.mark.parametrize("obstacle", [False, True])
def test_a_walkable_landing_in_the_second_half_is_a_touchdown_never_a_trip(obstacle):
    tr = swinging()
    set_contact(tr, slice(100, None), 1, 40.0, normal=TILTED_TOP, obstacle=obstacle)  # (c): at phase 0.5
    m = clearance_metrics(tr, 0, DT)
    assert (m["trips"], m["foot_trips"], m["touchdowns_early"]) == (0, 0, 1)
    assert m["touchdowns_early_floor"] == (0 if obstacle else 1)
    assert m["touchdowns_early_beyond_20ms"] == 1  # 100 ms before the planned touchdown


def test_a_landing_with_a_flank_among_its_contacts_is_a_strike_and_a_flank_met_after_landing_too():
    tr = swinging()
    set_contact(tr, slice(150, None), 1, 40.0, obstacle=True)  # a top ...
    set_contact(tr, [150], 1, 5.0, normal=FLANK, obstacle=True, slot=1)  # ... and a riser's edge on the same tick
    m = clearance_metrics(tr, 0, DT)
    assert (m["trips"], m["foot_trips_flank"], m["touchdowns_early"], m["foot_trips_flank_in_contact"]) == (1, 1, 0, 0)
    tr = swinging()
    set_contact(tr, slice(150, None), 1, 40.0, obstacle=True)  # a touchdown on a top, then the riser 20 ms later
    set_contact(tr, [170, 171], 1, 5.0, normal=FLANK, obstacle=True, slot=1)
    m = clearance_metrics(tr, 0, DT)
    assert (m["trips"], m["foot_trips_flank"], m["touchdowns_early"], m["foot_trips_flank_in_contact"]) == (1, 1, 1, 1)


def test_every_leg_link_contact_with_an_obstacle_is_a_trip_beside_its_foot_or_not():
    tr = swinging()
    tr.leg_link_obstacle_contact[[50, 51], 0] = True  # beside the foot (a calf grazing the log it stands on)
    tr.leg_link_obstacle_contact[[90], 2] = True  # away from it
    tr.leg_link_obstacle_contact_off_foot[[90], 2] = True
    tr.leg_link_floor_contact[[120], 3] = True  # on the floor: counted apart
    m = clearance_metrics(tr, 0, DT)
    assert (m["trips"], m["shin_trips"], m["shin_trips_off_foot"], m["leg_link_floor_contacts"]) == (2, 2, 1, 1)


def test_contacts_continuing_from_stance_or_flickering_are_not_new():
    tr = swinging()
    set_contact(tr, slice(0, 3), 1, 0.0, obstacle=False)  # lift-off: the contact runs 3 ticks into the swing
    set_contact(tr, [8], 1, 0.0)  # flickers back 5 ms later: the same contact
    m = clearance_metrics(tr, 0, DT)
    assert (m["trips"], m["touchdowns_early"]) == (0, 0)
    set_contact(tr, [30], 1, 5.0)  # a new one 22 ms after: a scuff
    assert clearance_metrics(tr, 0, DT)["trips"] == 1


def test_a_landing_exactly_20_ms_early_is_near_the_touchdown_in_whole_ticks():
    """Tick 180 of the 200-tick swing: its phase, computed as a gait clock does, is 0.8999999999999999, below
    1 - 0.02 / 0.2 in floating point; in ticks it is exactly 20 before the touchdown, not beyond. 21 ms is."""
    tr = swinging()
    assert tr.swing_phase[180, 1] < 1.0 - 0.02 / 0.2  # the float comparison that missed it
    set_contact(tr, slice(180, SWING), 1, 40.0)
    m = clearance_metrics(tr, 0, DT)
    assert (m["touchdowns_early"], m["touchdowns_early_beyond_20ms"]) == (1, 0)
    tr = swinging()
    set_contact(tr, slice(179, SWING), 1, 40.0)
    m = clearance_metrics(tr, 0, DT)
    assert (m["touchdowns_early"], m["touchdowns_early_beyond_20ms"]) == (1, 1)
    assert ticks_before_touchdown(np.array([0.9, 0.8999999999999999, 0.895]), 0.005).tolist() == [20, 20, 21]


def test_the_rule_reads_the_swing_phase_the_trace_recorded_not_a_gait_setting():
    """A controller with a 0.3 s swing (or one estimating its phase from the time since lift-off): 20 ms before
    its touchdown is phase 1 - 20 / 300, read from the recorded phase's per-tick step."""
    tr = swinging()
    tr.swing_phase[:SWING, 1] = np.arange(SWING) * DT / 0.3  # its swing would end at tick 300
    tr.scheduled_stance[:SWING, 1] = False
    set_contact(tr, slice(180, SWING), 1, 40.0)  # 120 ms before its touchdown
    assert clearance_metrics(tr, 0, DT)["touchdowns_early_beyond_20ms"] == 1
    tr = swinging(n=500)
    tr.in_stance[:300, 1] = False
    tr.scheduled_stance[:300, 1] = False
    tr.swing_phase[:300, 1] = np.arange(300) * DT / 0.3
    clear_contact(tr, slice(0, 300), 1)
    set_contact(tr, slice(280, 300), 1, 40.0)  # 20 ms before it
    m = clearance_metrics(tr, 0, DT)
    assert (m["touchdowns_early"], m["touchdowns_early_beyond_20ms"]) == (1, 0)


def test_contacts_beyond_the_slots_are_counted_not_dropped_silently():
    """A foot with MAX_CONTACTS_PER_FOOT + 2 contacts on one tick (a heightfield's prisms): the most loaded ones
    are kept, the 2 others counted; a tick with more contacts than the log holds counts the rest."""
    built = Built(compose_cfg(["scenario=logs", "progress=false", "record.mcap=false"]))
    m = built.mj_model
    foot = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, quad.FOOT_FRAMES[0])
    log_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "obstacles_0")
    reader, log = ContactFrameReader(m), ContactLog(2)
    n = MAX_CONTACTS_PER_FOOT + 2
    log.count[0], log.count[1] = n, MAX_CONTACTS_LOGGED + 5
    log.geom[0, :n] = (log_geom, foot)
    log.normal[0, :n] = (0.0, 0.0, 1.0)
    log.dist[0, :n] = -0.001
    log.force[0, :n, 0] = np.arange(1, n + 1)  # [N] 1 .. n
    frames = reader.frames(log, 0, 2, np.zeros((2, quad.N_LEGS, 3)))
    assert frames["contact_fn_n"][0, 0].tolist() == list(range(n, 2, -1))  # the K largest, largest first
    assert frames["foot_contacts_dropped"][:, 0].tolist() == [2, 0]
    assert frames["contacts_not_logged"].tolist() == [0, 5]
    tr = synthetic_trace(n=2)
    tr.foot_contacts_dropped[:2] = frames["foot_contacts_dropped"]
    tr.contacts_not_logged[:2] = frames["contacts_not_logged"]
    m = clearance_metrics(tr, 0, DT)
    assert (m["foot_contacts_dropped"], m["contacts_not_logged"]) == (2, 5)
