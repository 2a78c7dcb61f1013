"""Do the tick's parts slow each other down, or does the glue between them slow them down? (issue 25)

    python -m studies.tick_interleaving [--ticks N] [--rounds R] [overrides ...]

The bench's sum-of-parts limit times each part alone, in a tight loop. The default loop runs at ~0.5-0.6 of
that limit, although by instructions it is at 0.82 of its parts (`studies.tick_instructions`). Two causes are
possible: the parts (MuJoCo, Pinocchio, the QP build, the solver) evict each other's code and data from the
caches when they run one after the other, or the Python glue between them (its bytecode, objects, numpy
temporaries and Numba hand-overs) costs more time than its instructions suggest and evicts the parts' caches.

This study records N consecutive walking ticks of one episode (the plant state and torque before each physics
step, the Pinocchio (q, v), the controller's arguments, the filter's inputs and u_nom), then replays them three
ways, timing every call with ``perf_counter`` as the bench does:

* ``alone``: each part over the N ticks in its own loop (the bench's isolated parts, replayed in order);
* ``bare``: the parts of tick i back to back, tick after tick, with nothing between them but the replay's
  argument lookups (what a tick would cost with no glue at all);
* ``loop``: a clean run of the episode loop, its own per-part timers (``tick_<part>_us``) over the same ticks
  (their sum is the tick) and its wall time per tick (the tick plus what runs between ticks: the trace's row
  copy, the end checks, the loop itself), as the bench's real-time factor counts it.

If ``bare`` is as slow as ``loop`` the parts evict each other and no glue cut reaches the limit; if ``bare``
is close to ``alone`` the glue is what costs. Prints medians [µs] per part and the share sum(alone) / x, x the
bare sum, the loop's tick and its wall time per tick; each round runs the loop and both replays one after the
other, because this VM's speed drifts by up to 2x within minutes. Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import mujoco
import numpy as np

from taslel_bench.api import compose
from taslel_bench.filter.layout import TickInputs
from taslel_bench.record.trace import TICK_PARTS
from taslel_bench.sim.build import Built

PARTS = ("mj_step", "controller", "pinocchio_update", "qp_build", "qp_solve", "contact_check")  # the limit's


class Recorder:
    """Copies of each walking tick's part arguments, ticks ``k0 .. k0 + n - 1`` (instance-level wrappers)."""

    def __init__(self, built: Built, k0: int, n: int) -> None:
        self.e, self.f, self.k0, self.n = built.episode, built.filter, k0, n
        self.tick = -1
        self.rows: dict[str, list] = {p: [] for p in PARTS if p not in ("qp_solve", "contact_check")}
        self.solutions: list[np.ndarray | None] = []  # the backend's answer on each recorded tick
        e, f = self.e, self.f
        self._orig = {"compute": e.controller.compute, "update": e.model.update, "filter": f.filter}
        e.controller.compute = self._compute
        e.model.update = self._update
        f.filter = self._filter
        self._step = mujoco.mj_step
        mujoco.mj_step = self._mj_step

    def _on(self) -> bool:
        return self.k0 <= self.tick < self.k0 + self.n

    def _compute(self, t, q_joints, qd_joints, base_pose=None):
        self.tick = round(t / self.e.s.control_dt_s)  # the controller runs first in every tick
        if self._on():
            self.rows["controller"].append((t, q_joints.copy(), qd_joints.copy(),
                                            None if base_pose is None else base_pose.copy()))
        return self._orig["compute"](t, q_joints, qd_joints, base_pose)

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
                                          u_nom.copy()))
        result = self._orig["filter"](inputs, u_nom)
        if on:
            self.solutions.append(None if result.solve.x is None else result.solve.x.copy())
        return result

    def _mj_step(self, m, d):
        if self._on():
            self.rows["mj_step"].append((d.qpos.copy(), d.qvel.copy(), d.ctrl.copy(), d.qacc_warmstart.copy()))
        return self._step(m, d)

    def close(self) -> None:
        mujoco.mj_step = self._step
        for name in ("compute", "update"):
            delattr(self.e.controller if name == "compute" else self.e.model, name)
        delattr(self.f, "filter")


def record(overrides: list[str], n: int) -> tuple[Built, Recorder]:
    """Run the episode once (kernels loaded), then once more recording ``n`` walking ticks (the recorder's
    copies slow that run: its timers are not used)."""
    built = Built(compose(["scenario=obstacle", "duration=3.0", "progress=false", "record.reference_every=0",
                           *overrides]))  # fmt: skip
    e = built.episode
    e.s = replace(e.s, analyse=False)
    e.run()
    rec = Recorder(built, round(e.controller.stand_duration_s / e.s.control_dt_s) + 100, n)
    try:
        e.run()
    finally:
        rec.close()
    return built, rec


def loop_run(built: Built, rec: Recorder) -> tuple[np.ndarray, float]:
    """A clean run of the episode: its own timers over the recorded ticks (µs per part, one row per tick,
    ``tick_<part>_us``) and its wall time per tick [µs] (mean over the run, as the real-time factor)."""
    res = built.episode.run()
    return res.trace.tick_parts_s[rec.k0 : rec.k0 + rec.n] * 1e6, res.wall_time_s / res.trace.n * 1e6


def _calls(built: Built, rec: Recorder) -> tuple[int, dict]:
    """(n ticks, {part: call(i)}): each part on recorded tick ``i``, in the tick's order (controller, Pinocchio
    update, QP build, QP solve, then physics: the plant set to the recorded state before the step, untimed,
    mj_step, the contact check). The build and the solve read the model and QP the calls before them left."""
    e, f, rows = built.episode, built.filter, rec.rows
    m, d = e.m, mujoco.MjData(e.m)
    n = min(len(v) for v in rows.values())
    ppt = e.physics_per_tick
    states = rows["mj_step"][::ppt][:n]  # the first physics step of each tick
    inputs = []
    for v, stance, mu, phase, rate, mu_feet, u_nom in rows["qp_build"][:n]:
        x = TickInputs(e.model, v, stance, mu, phase, rate, mu_feet)
        if f._friction_margin > 0.0:  # as SafetyFilter.filter does before its build
            x = x.with_mu_scaled(1.0 - f._friction_margin)
        inputs.append((x, u_nom))
    ctrl, upd, build, solve, check = (e.controller.compute, e.model.update, f.build, f._solve,
                                      e.contacts.check_non_foot_contact)  # fmt: skip

    def set_state(i):
        qpos, qvel, u, warm = states[i]
        d.qpos[:], d.qvel[:], d.ctrl[:], d.qacc_warmstart[:] = qpos, qvel, u, warm

    calls = {
        "controller": lambda i: ctrl(*rows["controller"][i]),
        "pinocchio_update": lambda i: upd(*rows["pinocchio_update"][i]),
        "qp_build": lambda i: build(*inputs[i]),
        "qp_solve": lambda i: solve(f.problem),
        "mj_step": lambda i: mujoco.mj_step(m, d),
        "contact_check": lambda i: check(d),
        "qpos": lambda: d.qpos.copy(),  # not a part: the state a step left (the replay's faithfulness check)
    }
    return n, calls, set_state


REPLAY_TOLERANCE = 1e-9  # largest |difference| between a replayed result and the recorded one


def replay(built: Built, rec: Recorder) -> tuple[np.ndarray, np.ndarray]:
    """(alone, bare): µs of each part (columns PARTS) on each recorded tick, replayed alone (each part over
    every tick in its own loop; what it needs from the parts before it prepared untimed) and back to back.
    Raises if the back-to-back replay does not redo the loop's work: every solve's answer as recorded and
    every physics step ending in the recorded state of the next one (to ``REPLAY_TOLERANCE``)."""
    n, calls, set_state = _calls(built, rec)
    order = ("controller", "pinocchio_update", "qp_build", "qp_solve", "mj_step", "contact_check")
    needs = {"qp_build": ("pinocchio_update",), "qp_solve": ("pinocchio_update", "qp_build"),
             "contact_check": ("mj_step",)}  # fmt: skip
    col = {p: PARTS.index(p) for p in order}
    pc = time.perf_counter
    alone, bare = np.empty((n, len(PARTS))), np.empty((n, len(PARTS)))
    for part in order:
        built.filter.reset()  # the solver's warm start from tick to tick, as in the loop
        call, before, j = calls[part], needs.get(part, ()), col[part]
        for i in range(n):
            if part in ("mj_step", "contact_check"):
                set_state(i)
            for p in before:
                calls[p](i)
            t0 = pc()
            call(i)
            alone[i, j] = pc() - t0
    built.filter.reset()
    c = [calls[p] for p in order]
    cols = [col[p] for p in order]
    answers, next_qpos = [], []
    for i in range(n):
        t0 = pc()
        c[0](i)
        t1 = pc()
        c[1](i)
        t2 = pc()
        c[2](i)
        t3 = pc()
        answer = c[3](i)
        t4 = pc()
        set_state(i)  # the recorded plant state: not a part of the tick (the loop's plant is already there)
        t5 = pc()
        c[4](i)
        t6 = pc()
        c[5](i)
        t7 = pc()
        bare[i, cols] = (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t6 - t5, t7 - t6)
        answers.append(answer.x)
        next_qpos.append(calls["qpos"]())
    _check_faithful(rec, answers, next_qpos)
    return alone * 1e6, bare * 1e6


def _check_faithful(rec: Recorder, answers: list, next_qpos: list) -> None:
    """Raise unless the replayed answers and post-step states are the recorded ones (see :func:`replay`)."""
    worst_x = max(float(np.max(np.abs(a - b))) for a, b in zip(answers, rec.solutions))
    ppt = len(rec.rows["mj_step"]) // max(len(rec.solutions), 1)
    recorded = [row[0] for row in rec.rows["mj_step"][ppt::ppt]]  # the state before each next tick's step
    worst_q = max(float(np.max(np.abs(a - b))) for a, b in zip(next_qpos, recorded))
    if not (worst_x <= REPLAY_TOLERANCE and worst_q <= REPLAY_TOLERANCE):
        raise RuntimeError(f"the replay does not redo the loop's work: max |x - x_loop| {worst_x:.3g}, "
                           f"max |qpos - qpos_loop| {worst_q:.3g} (tolerance {REPLAY_TOLERANCE})")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ticks", type=int, default=1000, help="walking ticks recorded and replayed")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of (clean loop run, replay alone, replay bare)")
    ap.add_argument("overrides", nargs="*", help="config overrides, e.g. filter.formulation=full")
    args = ap.parse_args(argv)
    built, rec = record(args.overrides, args.ticks)
    print(f"median µs per part over {args.ticks} walking ticks; each round: a clean run of the loop, then the "
          "replays, one after the other (the VM's speed drifts between rounds)\n")
    print("| round | way | " + " | ".join(PARTS) + " | sum | alone / this |")
    print("|---|---|" + "---|" * (len(PARTS) + 2))
    for r in range(args.rounds):
        loop, wall_us = loop_run(built, rec)
        alone, bare = replay(built, rec)
        a, b = np.median(alone, axis=0), np.median(bare, axis=0)
        for way, x in (("alone", a), ("bare", b)):
            print(f"| {r} | {way} | " + " | ".join(f"{v:.1f}" for v in x) + f" | {x.sum():.1f} | {a.sum() / x.sum():.2f} |")
        parts = ", ".join(f"{k} {v:.1f}" for k, v in zip(TICK_PARTS, np.median(loop, axis=0)))
        tick = float(np.median(loop.sum(axis=1)))
        print(f"| {r} | loop tick, median ({parts}) |" + " |" * len(PARTS) + f" {tick:.1f} | {a.sum() / tick:.2f} |")
        print(f"| {r} | loop wall per tick, mean |" + " |" * len(PARTS) + f" {wall_us:.1f} | {a.sum() / wall_us:.2f} |")


if __name__ == "__main__":
    main()
