"""The limit's parts replayed on the loop's own ticks: each part alone, and all of them back to back with no glue.

The bench's sum-of-parts limit times each part alone. Whether the loop can reach it depends on what costs the
difference: the parts evicting each other's code and data from the caches when they run one after the other,
or the Python glue between them. :func:`record_ticks` runs the episode once more and copies, on ``n``
consecutive walking ticks, what each part is called with (the plant state and torque before the tick's first
physics step, the controller's arguments, the Pinocchio (q, v), the filter's inputs and u_nom) and the backend's
answer. :func:`replay` then calls the parts on those ticks twice over, timing each call as the bench does:

* ``alone``: each part over the ticks in its own loop (what it needs from the parts before it, untimed);
* ``back to back``: the parts of tick i one after the other, tick after tick, with nothing between them but
  the replay's argument lookups: what a tick would cost with no glue at all.

The back-to-back replay must redo the loop's work, else :func:`replay` raises: every plant state after a step
equal to the loop's (to :data:`STATE_TOLERANCE`) and every QP answer's u within ``answer_tol_nm`` of the
loop's (the harness's wrong-answer tolerance ``record.reference_tol_nm`` by default: an iterative solver's
answer moves within its own tolerance with its warm start, and the replay's first solve starts cold; an
active-set solver such as DAQP gives the loop's answer to rounding). Used by ``python -m taslel_bench.bench
--cold`` and ``studies.tick_interleaving``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Self

import mujoco
import numpy as np

from taslel_bench.filter.layout import TickInputs
from taslel_bench.sim.build import Built

PARTS = ("controller", "pinocchio_update", "qp_build", "qp_solve", "mj_step", "contact_check")  # tick order
STATE_TOLERANCE = 1e-9  # largest |qpos difference| between a replayed step's end and the loop's
AFTER_STAND_TICKS = 100  # the recording starts this many ticks into the walk (past the first steps' transient)


class TickRecorder:
    """Copies of the part arguments of ticks ``k0 .. k0 + n - 1`` (instance-level wrappers while installed;
    ``mujoco.mj_step`` is wrapped too, as the episode calls it through the module)."""

    def __init__(self, built: Built, k0: int, n: int) -> None:
        self.e, self.f, self.k0, self.n = built.episode, built.filter, k0, n
        self.tick = -1
        self.rows: dict[str, list] = {"controller": [], "mj_step": []}
        if self.f is not None:
            self.rows.update(pinocchio_update=[], qp_build=[])
        self.solutions: list[np.ndarray | None] = []  # the backend's answer on each recorded tick
        self._step = None

    def __enter__(self) -> Self:
        e, f = self.e, self.f
        self._orig = {"compute": e.controller.compute, "update": e.model.update,
                      "filter": f.filter if f is not None else None}  # fmt: skip
        e.controller.compute = self._compute
        if f is not None:
            e.model.update = self._update
            f.filter = self._filter
        self._step = mujoco.mj_step
        mujoco.mj_step = self._mj_step
        return self

    def __exit__(self, *exc) -> None:
        mujoco.mj_step = self._step
        del self.e.controller.compute  # the instance attributes: the methods again
        if self.f is not None:
            del self.e.model.update, self.f.filter

    def _on(self) -> bool:
        return self.k0 <= self.tick < self.k0 + self.n

    def _compute(self, t, q_joints, qd_joints, base_pose=None, base_velocity=None, tau_applied=None):
        self.tick = round(t / self.e.s.control_dt_s)  # the controller runs first in every tick
        if self._on():
            self.rows["controller"].append((t, q_joints.copy(), qd_joints.copy(),
                                            *(None if x is None else x.copy()
                                              for x in (base_pose, base_velocity, tau_applied))))  # fmt: skip
        return self._orig["compute"](t, q_joints, qd_joints, base_pose, base_velocity, tau_applied)

    def _update(self, q, v):
        if self._on():
            self.rows["pinocchio_update"].append((q.copy(), v.copy()))
        return self._orig["update"](q, v)

    def _filter(self, inputs: TickInputs, u_nom):
        on = self._on()
        if on:
            mu_feet = None if inputs.mu_per_foot is None else inputs.mu_per_foot.copy()
            self.rows["qp_build"].append((inputs.v.copy(), inputs.in_stance.copy(), inputs.mu,
                                          inputs.swing_phase.copy(), inputs.swing_phase_rate, mu_feet,
                                          u_nom.copy()))  # fmt: skip
        result = self._orig["filter"](inputs, u_nom)
        if on:
            self.solutions.append(None if result.solve is None or result.solve.x is None else result.solve.x.copy())
        return result

    def _mj_step(self, m, d):
        if self._on():
            self.rows["mj_step"].append((d.qpos.copy(), d.qvel.copy(), d.ctrl.copy(), d.qacc_warmstart.copy()))
        assert self._step is not None  # installed (as mujoco.mj_step) only between __enter__ and __exit__
        return self._step(m, d)


def record_ticks(built: Built, n: int, after_stand_ticks: int = AFTER_STAND_TICKS) -> TickRecorder:
    """Run the built episode once more (no analysis) recording ``n`` walking ticks from ``after_stand_ticks``
    after the stand. Raises if the run ends before them."""
    e = built.episode
    k0 = round(e.controller.stand_duration_s / e.s.control_dt_s) + after_stand_ticks
    analyse, e.s = e.s.analyse, replace(e.s, analyse=False)
    try:
        with TickRecorder(built, k0, n) as rec:
            e.run()
    finally:
        e.s = replace(e.s, analyse=analyse)
    got = len(rec.rows["controller"])
    if got < n or min(len(v) for v in rec.rows.values()) < n:
        raise RuntimeError(f"the episode recorded {got} of {n} walking ticks from tick {k0} (it ended early or "
                           "is too short)")
    return rec


def _calls(built: Built, rec: TickRecorder) -> tuple[dict[str, Callable], Callable, Callable]:
    """({part: call(i)} on recorded tick ``i``, set_state(i): the replay's plant at the recorded state before
    tick i's first physics step, qpos(): a copy of the replay plant's qpos). The build and the solve read the
    model and QP the calls before them left."""
    e, f, rows = built.episode, built.filter, rec.rows
    m, d = e.m, mujoco.MjData(e.m)
    states = rows["mj_step"][:: e.physics_per_tick]  # the first physics step of each tick
    check, ctrl = e.contacts.check_non_foot_contact, e.controller.compute

    def set_state(i):
        qpos, qvel, u, warm = states[i]
        d.qpos[:], d.qvel[:], d.ctrl[:], d.qacc_warmstart[:] = qpos, qvel, u, warm

    calls: dict[str, Callable] = {"controller": lambda i: ctrl(*rows["controller"][i])}
    if f is not None:
        inputs = []
        for v, stance, mu, phase, rate, mu_feet, u_nom in rows["qp_build"]:
            x = TickInputs(e.model, v, stance, mu, phase, rate, mu_feet)
            if f._friction_margin > 0.0:  # as SafetyFilter.filter does before its build
                x = x.with_mu_scaled(1.0 - f._friction_margin)
            inputs.append((x, u_nom))
        upd, build, solve = e.model.update, f.build, f._solve
        calls.update(pinocchio_update=lambda i: upd(*rows["pinocchio_update"][i]),
                     qp_build=lambda i: build(*inputs[i]), qp_solve=lambda i: solve(f.problem))  # fmt: skip
    calls.update(mj_step=lambda i: mujoco.mj_step(m, d), contact_check=lambda i: check(d))
    return calls, set_state, lambda: d.qpos.copy()


NEEDS = {"qp_build": ("pinocchio_update",), "qp_solve": ("pinocchio_update", "qp_build"),
         "contact_check": ("mj_step",)}  # what a part alone needs run before it (untimed)  # fmt: skip


def replay(built: Built, rec: TickRecorder, answer_tol_nm: float | None = None
           ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, float]]:  # fmt: skip
    """({part: µs per recorded tick} alone, the same back to back, {"u_nm", "qpos"}: the largest difference
    of the back-to-back replay's answers and states from the loop's) for the parts the loop runs (no Pinocchio
    update and no QP without a filter). Raises if the replay does not redo the loop's work (module doc;
    ``answer_tol_nm`` None: the run's ``record.reference_tol_nm``)."""
    calls, set_state, qpos = _calls(built, rec)
    order = [p for p in PARTS if p in calls]
    n, pc = rec.n, time.perf_counter
    reset = built.filter.reset if built.filter is not None else lambda: None
    alone = {p: np.empty(n) for p in order}
    for part in order:
        reset()  # the solver's warm start from tick to tick, as in the loop
        call, before, out = calls[part], NEEDS.get(part, ()), alone[part]
        physics = part in ("mj_step", "contact_check")
        for i in range(n):
            if physics:
                set_state(i)
            for p in before:
                calls[p](i)
            t0 = pc()
            call(i)
            out[i] = pc() - t0
    reset()
    back = {p: np.empty(n) for p in order}
    seq = [(calls[p], back[p], p == "mj_step", p == "qp_solve") for p in order]
    answers, after_step = [], []
    for i in range(n):
        for call, out, physics, solve in seq:
            if physics:
                set_state(i)  # the recorded plant state (the loop's plant is already there): untimed
            t0 = pc()
            result = call(i)
            out[i] = pc() - t0
            if solve:
                answers.append(result.x)
        after_step.append(qpos())
    tol = float(built.cfg.record.reference_tol_nm) if answer_tol_nm is None else answer_tol_nm
    worst = _check_faithful(built, rec, answers, after_step, tol)
    return {p: x * 1e6 for p, x in alone.items()}, {p: x * 1e6 for p, x in back.items()}, worst


def _check_faithful(built: Built, rec: TickRecorder, answers: list, after_step: list, answer_tol_nm: float
                    ) -> dict[str, float]:  # fmt: skip
    """{"u_nm": the largest |u - u_loop| of the replayed answers [N·m], "qpos": the largest |qpos - qpos_loop|
    after each tick's first physics step}; raises beyond ``answer_tol_nm`` or :data:`STATE_TOLERANCE`."""
    ppt, steps = built.episode.physics_per_tick, rec.rows["mj_step"]
    recorded = [steps[i * ppt + 1][0] for i in range(len(after_step)) if i * ppt + 1 < len(steps)]  # the
    # state before the physics step after each tick's first one (the next tick's first with one step a tick)
    worst_q = max((float(np.max(np.abs(a - b))) for a, b in zip(after_step, recorded, strict=False)), default=0.0)
    u = built.filter.backend_problem.layout["u"] if built.filter is not None else slice(0)
    worst_u = max((_u_difference(a, b, u) for a, b in zip(answers, rec.solutions, strict=False)), default=0.0)
    if not (worst_u <= answer_tol_nm and worst_q <= STATE_TOLERANCE):
        raise RuntimeError(f"the replay does not redo the loop's work: max |u - u_loop| {worst_u:.3g} N·m "
                           f"(tolerance {answer_tol_nm:g}), max |qpos - qpos_loop| {worst_q:.3g} "
                           f"(tolerance {STATE_TOLERANCE:g})")  # fmt: skip
    return {"u_nm": worst_u, "qpos": worst_q}


def _u_difference(replayed: np.ndarray | None, loop: np.ndarray | None, u: slice) -> float:
    """max |u - u_loop| [N·m] of one tick's answers; 0 when neither has one, inf when only one does."""
    if replayed is None or loop is None:
        return 0.0 if replayed is None and loop is None else math.inf
    return float(np.max(np.abs(replayed[u] - loop[u])))
