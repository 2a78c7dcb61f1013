"""The control tick's merged kernels against the code they replaced, number for number: the trace's
one-call row copy, the fall terms with the foot-contact count, the PD law on the stacked references."""

from __future__ import annotations

import math
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from taslel_bench.control.nominal import _pd
from taslel_bench.filter.safety_filter import FilterResult
from taslel_bench.interfaces import FrictionEstimate, QPSolution
from taslel_bench.plant.contacts import more_contacts_than_feet
from taslel_bench.record.trace import EpisodeTrace
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.build import Built
from taslel_bench.sim.terminations import _HEIGHT, _NONE, _OTHER_CONTACTS, _TILT, _step_term, _trunk_term
from tests.conftest import compose_cfg

NQ, NV, NSENSOR = 19, 18, 7


def _tick_inputs(rng: np.random.Generator, fallback: bool, iterations: int | None):
    """Random raw rows of one tick, a gait state with read-only arrays (the gait table's) and a filter result."""
    gs = SimpleNamespace(phi=float(rng.random()), swing_phase=rng.random(4), in_stance=rng.random(4) < 0.5)
    gs.swing_phase.flags.writeable = False
    sol = QPSolution(rng.normal(size=12), "solved", float(rng.random()) * 1e-5, iterations)
    fres = FilterResult(rng.normal(size=12), rng.normal(size=12), rng.normal(size=NV),
                        "max_iter" if fallback else "solved", fallback, float(rng.random()) * 1e-5, sol,
                        float(rng.random()))  # fmt: skip
    plant = (rng.normal(size=NQ), rng.normal(size=NV), rng.normal(size=NSENSOR))
    return gs, fres, plant


def _barrier(rng: np.random.Generator) -> SimpleNamespace:
    return SimpleNamespace(
        name="clearance", h=rng.normal(size=4), h_e=rng.normal(size=4), psi_planned=rng.normal(size=4)
    )


@pytest.mark.parametrize("fallback", [False, True])
def test_trace_record_writes_every_row_the_numpy_assignments_wrote(fallback):
    rng = np.random.default_rng(3)
    tr = EpisodeTrace(6, filter_on=True, nq=NQ, nv=NV, nsensordata=NSENSOR, barrier_names=["clearance"])
    gs, fres, plant = _tick_inputs(rng, fallback, iterations=4)
    stance = rng.random(4) < 0.5
    u_nom, u, barrier = rng.normal(size=12), rng.normal(size=12), _barrier(rng)
    clock = tuple(np.cumsum(rng.random(5)))
    est = FrictionEstimate(mu=0.7, sigma=0.0, ready=False, mu_per_foot=np.array([0.7, 0.8, 0.9, 1.0]))
    tr.record(2, 0.25, plant, gs, stance, u_nom, u, fres, est, 0.9, clock, [barrier], True, False)
    r = 2
    assert tr.n == 3 and tr.t_s[r] == 0.25 and tr.gait_phase[r] == gs.phi
    for got, want in ((tr.qpos_mj, plant[0]), (tr.qvel_mj, plant[1]), (tr.sensordata_mj, plant[2]), (tr.u_nom, u_nom),
                      (tr.u, u), (tr.in_stance, stance), (tr.scheduled_stance, gs.in_stance),
                      (tr.swing_phase, gs.swing_phase), (tr.vdot_filter, fres.vdot)):  # fmt: skip
        np.testing.assert_array_equal(got[r], want)
    np.testing.assert_array_equal(tr.grf_filter_w[r].ravel(), fres.lam)
    assert (tr.mu_hat[r], tr.mu_true[r], tr.mu_hat_ready[r]) == (0.7, 0.9, False)
    np.testing.assert_array_equal(tr.mu_hat_foot[r], est.mu_per_foot)
    assert tr.tick_us[r] == (clock[4] - clock[0]) * 1e6
    np.testing.assert_array_equal(tr.tick_parts_s[r], np.diff(clock))
    assert tr.nonfoot_obstacle_contact[r] and not tr.shin_floor_contact[r]
    assert tr.qp_status[r] == (1 if fallback else 0) and tr.qp_fallback[r] == fallback
    assert tr.qp_build_us[r] == fres.build_time_s * 1e6 and tr.qp_solve_us[r] == fres.solve.solve_time_s * 1e6
    assert tr.qp_iterations[r] == 4 and tr.ecbf_margin_mps2[r] == fres.ecbf_margin_mps2
    log = tr.barriers["clearance"]
    np.testing.assert_array_equal(log.h_m[r], barrier.h)
    np.testing.assert_array_equal(log.he_mps[r], barrier.h_e)
    if fallback:
        assert np.all(np.isnan(log.psi_planned_mps2[r])) and tr.events[-1]["kind"] == "qp_failure"
    else:
        np.testing.assert_array_equal(log.psi_planned_mps2[r], barrier.psi_planned)
    # untouched rows keep their initial values
    assert np.isnan(tr.qp_build_us[0]) and tr.qp_status[0] == -1 and tr.qp_iterations[0] == -1


def test_trace_record_without_a_filter_result_and_after_a_roll():
    rng = np.random.default_rng(4)
    tr = EpisodeTrace(4, filter_on=True, nq=NQ, nv=NV, nsensordata=NSENSOR, barrier_names=["clearance"])
    gs, fres, plant = _tick_inputs(rng, False, iterations=None)
    for k in range(3):
        tr.record(k, 0.001 * k, plant, gs, np.ones(4, bool), plant[1][:12], plant[1][:12], fres if k else None,
                  FrictionEstimate(mu=1.0, sigma=0.0, ready=True), 1.0, (0.0, 1.0, 2.0, 3.0, 4.0), [_barrier(rng)],
                  False, True)  # fmt: skip
    # tick 0 had no filter: its filter rows keep their initial values; tick 1's iterations were None (-1 kept)
    assert np.all(np.isnan(tr.grf_filter_w[0])) and np.all(np.isnan(tr.vdot_filter[0]))
    assert tr.qp_status[0] == -1 and np.isnan(tr.qp_build_us[0]) and np.isnan(tr.qp_solve_us[0])
    assert tr.ecbf_margin_mps2[0] == 0.0 and np.all(np.isnan(tr.barriers["clearance"].h_m[0]))
    assert tr.qp_status[1] == 0 and tr.qp_iterations[1] == -1 and tr.qp_solve_us[1] == fres.solve.solve_time_s * 1e6
    tr.roll(2)  # episode tick 2 is row 0 now; tick 3 goes to row 1
    tr.record(3, 0.003, plant, gs, np.zeros(4, bool), plant[1][:12], plant[1][:12], fres,
              FrictionEstimate(mu=0.5, sigma=0.0, ready=True), 1.0, (0.0, 1.0, 2.0, 3.0, 4.0), [_barrier(rng)], False,
              False)  # fmt: skip
    assert tr.t_s[0] == 0.002 and tr.t_s[1] == 0.003 and tr.mu_hat[1] == 0.5 and not tr.in_stance[1].any()
    np.testing.assert_array_equal(tr.mu_hat_foot[1], np.full(4, 0.5))  # one mu: every foot's
    assert tr.tick_us[1] == 4e6 and tr.n == 4


def _step_term_python(qpos, a, height_m, cos_tilt_min, sensordata, found_rows, ncon):
    """The code _step_term replaced: the trunk terms, then FootContactReader's 4-sensor sum against ncon."""
    term = _trunk_term(qpos, a, height_m, cos_tilt_min)
    if term != _NONE:
        return term
    r0, r1, r2, r3 = (int(r) for r in found_rows)
    return _OTHER_CONTACTS if ncon > sensordata[r0] + sensordata[r1] + sensordata[r2] + sensordata[r3] else _NONE


def test_step_term_equals_trunk_terms_then_the_foot_contact_count():
    rng = np.random.default_rng(5)
    found_rows = np.array([0, 3, 5, 6])
    seen = set()
    for _ in range(400):
        qpos = np.zeros(19)
        qpos[2] = rng.uniform(0.05, 0.35)  # [m] trunk height around the 0.12 m threshold
        quat = rng.normal(size=4) * np.array([1.0, 0.6, 0.6, 0.3])
        qpos[3:7] = quat / np.linalg.norm(quat)
        sensordata = rng.integers(0, 3, size=8).astype(float)
        ncon = int(rng.integers(0, 9))
        got = _step_term(qpos, 0, 0.12, math.cos(math.radians(57.0)), sensordata, found_rows, ncon)
        assert got == _step_term_python(qpos, 0, 0.12, math.cos(math.radians(57.0)), sensordata, found_rows, ncon)
        assert more_contacts_than_feet(sensordata, found_rows, ncon) == (ncon > sensordata[found_rows].sum())
        seen.add(got)
    assert seen == {_NONE, _HEIGHT, _TILT, _OTHER_CONTACTS}  # every branch exercised


def test_after_step_gives_the_fall_and_flags_of_the_old_two_call_check():
    """A robot with no gains collapses: on every physics step, after_step's fall and the contact reader's flags
    equal the old sequence (trunk terms, then check_non_foot_contact)."""
    built = Built(compose_cfg(["duration=1", "controller.kp=0", "controller.kd=0", "filter.enabled=false",
                               "scenario=flat", "progress=false"]))  # fmt: skip
    e = built.episode
    e.initial_state()
    m, d, tm, contacts = e.m, e.d, e.terminations, e.contacts
    falls, flagged = [], 0
    for step in range(1500):
        mujoco.mj_step(m, d)
        fall = tm.after_step(d.qpos, d, step * 1e-3)
        flags = (contacts.body_contact, contacts.shin_contact, contacts.non_foot_obstacle_contact)
        term = _trunk_term(d.qpos, tm.a, tm.rule.height_m, math.cos(math.radians(tm.rule.tilt_deg)))
        if term == _NONE:
            old_body = contacts.check_non_foot_contact(d)
            assert flags == (old_body, contacts.shin_contact, contacts.non_foot_obstacle_contact)
            assert (fall is not None) == old_body
            flagged += any(flags)
        else:
            assert fall is not None and fall.term == ("trunk_height" if term == _HEIGHT else "trunk_tilt")
        if fall is not None:
            falls.append(fall.term)
            break
    assert falls, "the robot without gains should fall within 1.5 s"


def test_pd_on_stacked_references_equals_the_clipped_pd_law():
    rng = np.random.default_rng(6)
    refs, q, qd, u = rng.normal(size=(2, 12)), rng.normal(size=12), rng.normal(size=12) * 10, np.empty(12)
    _pd(refs, q, qd, 100.0, 3.0, np.full(12, 20.0), u)
    want = np.clip(100.0 * (refs[0] - q) + 3.0 * (refs[1] - qd), -20.0, 20.0)
    np.testing.assert_array_equal(u, want)
    assert np.any(np.abs(want) == 20.0) and np.any(np.abs(want) < 20.0)  # both branches of the clip


def test_controller_references_are_rows_of_one_array():
    """q_des / qd_des are views of the array the table row is copied into (a subclass writes them in place)."""
    from taslel_bench.control.gait import GaitParams
    from taslel_bench.control.nominal import NominalController, PDGains

    ctl = NominalController(GaitParams(), PDGains())
    for k in range(1, 900):  # the stand, the first period (table filled) and the second (table read)
        ctl.update_references(k * 1e-3)
    np.testing.assert_array_equal(ctl._references, np.stack([ctl.q_des, ctl.qd_des]))
    fresh = NominalController(GaitParams(), PDGains())
    fresh.use_tables = False
    fresh.update_references(899e-3)
    np.testing.assert_allclose(ctl.q_des, fresh.q_des, atol=1e-12)
    np.testing.assert_allclose(ctl.qd_des, fresh.qd_des, atol=1e-8)
    assert ctl.q_des.base is ctl._references and ctl.qd_des.base is ctl._references
    assert ctl.q_des.shape[0] == quad.N_JOINTS


def _record_numpy(reader, data: mujoco.MjData, log, k: int) -> None:
    """The numpy code ContactFrameReader.record replaced, kept here as the reference."""
    from taslel_bench.plant.contact_frames import MAX_CONTACTS_LOGGED

    n = data.ncon
    log.count[k] = n
    np.take(data.cvel, reader._foot_bodies, axis=0, out=log.foot_cvel[k])
    log.root_com[k] = data.subtree_com[reader._root]
    if n == 0:
        return
    m = min(n, MAX_CONTACTS_LOGGED)
    con = data.contact
    log.geom[k, :m] = con.geom[:m]
    log.geom[k, m:] = -1
    log.normal[k, :m] = con.frame[:m, :3]
    log.pos[k, :m] = con.pos[:m]
    log.friction[k, :m] = con.friction[:m, 0]
    log.dist[k, :m] = con.dist[:m]
    adr = con.efc_address[:m]
    if reader._efc_rows_are_forces and adr.min() >= 0:
        np.take(data.efc_force, adr[:, None] + np.arange(3), out=log.force[k, :m])
    else:
        force6 = np.zeros(6)
        for i in range(m):
            mujoco.mj_contactForce(reader.model, data, i, force6)
            log.force[k, i] = force6[:3]


@pytest.mark.parametrize("efc_rows_are_forces", [True, False])
def test_contact_rows_copied_as_the_numpy_code_did(efc_rows_are_forces):
    """On logs (feet on logs and floor, up to several contacts per tick) and in the air (no contact), both paths
    of the force read: every ContactLog array row equal to the numpy code's, bit for bit."""
    from taslel_bench.plant.contact_frames import ContactLog

    built = Built(compose_cfg(["duration=1", "scenario=logs", "progress=false", "record.mcap=false"]))
    e = built.episode
    e.initial_state()
    reader = e.contact_frames
    reader._efc_rows_are_forces = reader._efc_rows_are_forces and efc_rows_are_forces
    ticks = 400
    got, want = ContactLog(ticks + 1), ContactLog(ticks + 1)
    counts = []
    for k in range(ticks):
        e.d.ctrl[:] = 0.0
        mujoco.mj_step(e.m, e.d)
        reader.record(e.d, got, k)
        _record_numpy(reader, e.d, want, k)
        counts.append(e.d.ncon)
    e.d.qpos[2] += 1.0  # lifted 1 m: no contact
    mujoco.mj_forward(e.m, e.d)
    assert e.d.ncon == 0
    reader.record(e.d, got, ticks)
    _record_numpy(reader, e.d, want, ticks)
    for name in vars(want):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    assert max(counts) >= 4 and min(counts) >= 1  # several contacts at once on some ticks
