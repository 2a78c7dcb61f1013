"""Instructions per control tick of the default loop and of the parts of the bench's sum-of-parts limit
(the tick-cost work): callgrind counts, repeatable whatever else loads the machine (the timings of
``python -m taslel_bench.bench`` are not).

    python -m studies.tick_instructions [overrides ...]      # e.g. scenario=flat; needs valgrind and gcc

One valgrind run of this module in ``--child`` mode: a 1 s episode loads every kernel, then a second run is counted
over walking ticks 600..1099 (``record.reference_every=0``: the reference check's batches are outside the tick
anyway), then each part alone at that run's final state, ``N`` calls each (mj_step and the QP solve: the loop's
own plant states and QPs of 100 ticks replayed in order, the median), then the contact-frame recording and the trace's
row copy, whose time the wall time does not count or counts outside the tick. Collection is switched by
callgrind's client requests from a small C helper compiled on the fly (``valgrind/callgrind.h``).
"""

from __future__ import annotations

import ctypes
import glob
import os
import subprocess
import sys
import tempfile
from pathlib import Path

N = 300  # calls of each part
REPLAYED = 100  # ticks whose plant states and QPs are replayed (one dump per mj_step / solve: the median counts)
LOOP_TICKS = (600, 1100)  # walking ticks counted in the loop (the stand ends at tick 500)
HELPER = r"""
#include <valgrind/callgrind.h>
void cg_instr_on(void) { CALLGRIND_START_INSTRUMENTATION; }
void cg_begin(void) { CALLGRIND_ZERO_STATS; CALLGRIND_TOGGLE_COLLECT; }
void cg_end(void) { CALLGRIND_TOGGLE_COLLECT; CALLGRIND_DUMP_STATS; }
"""
PARTS = ("mj_step (loop states)", "controller", "contact_check", "pinocchio_update", "qp_build", "qp_solve",
         "contact-frame recording", "trace row copy")  # fmt: skip


def _child(helper: str, overrides: list[str]) -> None:
    """Under valgrind: dump 1 = the loop's ticks, one dump per replayed mj_step, one per part timed in a loop
    (controller, contact check, Pinocchio update, QP build), one per replayed QP solve, then the contact-frame
    recording, the trace row copy and an empty loop."""
    from dataclasses import replace

    from taslel_bench.api import compose
    from taslel_bench.filter.layout import TickInputs
    from taslel_bench.record.trace import EpisodeTrace
    from taslel_bench.sim.build import Built

    cg = ctypes.CDLL(helper)
    b = Built(compose(["duration=1.0", "scenario=obstacle", "progress=false", "record.reference_every=0", *overrides]))
    e = b.episode
    e.s = replace(e.s, analyse=False)
    e.run()  # every kernel loaded
    cg.cg_instr_on()
    seq, trace = _count_loop(cg, e)
    _count_replayed_steps(cg, e, trace)
    d, br = e.d, e.bridge
    q, v = br.q_pin(d.qpos), br.v_pin(d.qpos, d.qvel)
    qj, qdj, t = q[7:].copy(), v[6:].copy(), e.controller.stand_duration_s + 0.4
    gs = e.controller.contact_plan(t)
    u = e.controller.compute(t, qj, qdj)
    inputs = TickInputs(e.model, v, gs.in_stance, 1.0, gs.swing_phase, gs.swing_phase_rate)
    fres = b.filter.filter(inputs, u)
    _count_each(cg, [lambda: e.controller.compute(t, qj, qdj), lambda: e.contacts.check_non_foot_contact(d),
                     lambda: e.model.update(q, v), lambda: b.filter.build(inputs, u)])  # fmt: skip
    _count_replayed_solves(cg, b, seq)
    m = e.m
    scratch = EpisodeTrace(8, True, m.nq, m.nv, m.nsensordata, [x.name for x in b.filter.barriers])
    plant = (d.qpos, d.qvel, d.sensordata)
    clock = (0.0, 1.0, 2.0, 3.0, 4.0)

    def empty():
        pass

    _count_each(cg, [lambda: e.contact_frames.record(d, scratch.contact_log, 3),
                     lambda: scratch.record(3, t, plant, gs, gs.in_stance, u, u, fres, 1.0, True, 1.0, clock,
                                            b.filter.barriers, False, False), empty])  # fmt: skip


def _count_loop(cg, e):
    """One dump over the loop's walking ticks LOOP_TICKS (an extra run that also records their QPs); returns
    (the QP sequence of the REPLAYED ticks from LOOP_TICKS[0], the run's trace)."""
    import taslel_bench.sim.episode as episode_module
    from taslel_bench.qp.tick_bench import QPSequence
    from taslel_bench.sim.observers import FilterQPs

    tick = episode_module.Episode._tick

    def counted_tick(self, k, trace, res):
        if k == LOOP_TICKS[0]:
            cg.cg_begin()
        out = tick(self, k, trace, res)
        if k == LOOP_TICKS[1] - 1:
            cg.cg_end()
        return out

    episode_module.Episode._tick = counted_tick
    seq = QPSequence(LOOP_TICKS[0], REPLAYED)
    try:
        trace = e.with_observers([FilterQPs(seq)]).run().trace
    finally:
        episode_module.Episode._tick = tick
    return seq, trace


def _count_replayed_steps(cg, e, trace) -> None:
    """One dump per mj_step from the loop's recorded states (setting the state is not counted)."""
    import mujoco

    m, br = e.m, e.bridge
    dm = mujoco.MjData(m)
    for k in range(LOOP_TICKS[0], LOOP_TICKS[0] + REPLAYED):
        dm.qpos[:], dm.qvel[:] = trace.qpos_mj[k - 1], trace.qvel_mj[k - 1]
        dm.ctrl[br.actuator_ids] = trace.u[k]
        if k > LOOP_TICKS[0]:
            cg.cg_begin()
        mujoco.mj_step(m, dm)
        if k > LOOP_TICKS[0]:
            cg.cg_end()


def _count_each(cg, parts) -> None:
    """One dump per part: N calls after one uncounted call."""
    for fn in parts:
        fn()
        cg.cg_begin()
        for _ in range(N):
            fn()
        cg.cg_end()


def _count_replayed_solves(cg, b, seq) -> None:
    """One dump per replayed QP solve, in order from a fresh backend (the first, its setup, not counted)."""
    import numpy as np

    from taslel_bench.qp.tick_bench import QPSequence

    problem, backend = b.filter.backend_problem, b.backend
    backend.reset()
    for i, values in enumerate(seq.values):
        for field, value in zip(QPSequence.FIELDS, values, strict=True):
            np.copyto(getattr(problem, field), value)
        if i:
            cg.cg_begin()
        backend.solve(problem)
        if i:
            cg.cg_end()


def _summary(out: str) -> list[int]:
    """Instructions of each dump, in order."""
    files = sorted(glob.glob(out + ".*"), key=lambda f: int(f.rsplit(".", 1)[1]))
    counts = []
    for f in files:
        with open(f) as fh:
            counts.append(next(int(line.split()[1]) for line in fh if line.startswith("summary:")))
    return counts


def report(counts: list[int]) -> str:
    """The table: loop per tick, each part per call (the QP solve: median over the replayed QPs), the glue."""
    import numpy as np

    loop = counts[0] / (LOOP_TICKS[1] - LOOP_TICKS[0])
    empty = counts[-1] / N
    steps, rest = counts[1:REPLAYED], counts[REPLAYED:]
    per = {PARTS[0]: float(np.median(steps))}
    per.update({name: rest[i] / N - empty for i, name in enumerate(PARTS[1:5])})
    per["qp_solve"] = float(np.median(rest[4:-3]))
    per["contact-frame recording"] = counts[-3] / N - empty
    per["trace row copy"] = counts[-2] / N - empty
    limit_parts = sum(per[p] for p in PARTS[:6])
    glue = loop - limit_parts - per["contact-frame recording"]
    lines = [f"loop: {loop:,.0f} instructions per walking tick", *(f"  {p}: {x:,.0f}" for p, x in per.items()),
             f"  the limit's parts together: {limit_parts:,.0f} ({limit_parts / loop:.0%} of the loop)",
             f"  the rest (glue between the parts, trace row copy included): {glue:,.0f} "
             f"({glue / loop:.0%})"]  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if argv[:1] == ["--child"]:
        _child(argv[1], argv[2:])
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        src, lib = Path(tmp) / "cgctl.c", Path(tmp) / "libcgctl.so"
        src.write_text(HELPER)
        subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-o", str(lib), str(src)], check=True)
        out = str(Path(tmp) / "cg.out")
        cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", "--collect-atstart=no",
               f"--callgrind-out-file={out}", sys.executable, "-m", "studies.tick_instructions", "--child", str(lib),
               *argv]  # fmt: skip
        env = {**os.environ, "PYTHONHASHSEED": "0"}
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        print(report(_summary(out)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
