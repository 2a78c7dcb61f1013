"""Per-tick cost and real-time factor of an episode, with a breakdown of the tick's parts.

    python -m taslel_bench.bench [--duration 5] [--solvers daqp,osqp,qpsolvers:osqp] [--scenario obstacle]
                                 [--main osqp,clarabel] [--controllers trot,policy]

Prints, for the nominal-only loop and for the filter with each solver and formulation: median tick time,
real-time factor, the median cost of each part of the tick measured inside the loop, the same parts
measured in isolation on the episode's final state, and the *sum-of-parts limit*: the real-time factor the
loop would reach if a tick cost only the sum of its parts timed alone (mj_step x physics steps per tick,
controller, Pinocchio update, contact check, QP build, QP solve), with the loop's factor as a share of it.
Runs share one process and are reported side by side. A solver ``qpsolvers:<name>`` is the per-call route
(``solver=qpsolvers solver.name=<name>``). ``--controllers trot,policy`` runs every loop once per nominal
controller (``policy``: the robot's shipped learned policy, ``controller=policy policy=<robot>_walk``).

``--main osqp,clarabel`` also runs the main command, ``python -m taslel_bench -m solver=osqp,clarabel`` (its
default config: two 10 s runs as two parallel jobs sharing the cores), in a temporary sweep folder and reports
each run's real-time factor from its ``summary.json``.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from rich.console import Console
from rich.table import Table

from taslel_bench.api import compose
from taslel_bench.control.plan import compute_of
from taslel_bench.filter.layout import TickInputs
from taslel_bench.qp.tick_replay import AFTER_STAND_TICKS, record_ticks, replay
from taslel_bench.record.run_files import atomic_write
from taslel_bench.record.trace import TICK_PARTS, EpisodeTrace
from taslel_bench.sim.build import Built
from taslel_bench.sim.observers import FilterQPs
from taslel_bench.util.machine import CpuWatch, machine_info
from taslel_bench.util.tables import markdown_table


def _median_us(fn, n: int = 2000) -> float:
    times = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        times[i] = time.perf_counter() - t0
    return float(np.median(times) * 1e6)


REPLAY_TICKS = 1000  # walking ticks whose QPs the isolated solve replays in order


class QPSequence:
    """A QP recorder (an observer through :class:`taslel_bench.sim.observers.FilterQPs`): copies of the backend
    QP's values on ``n`` consecutive ticks
    from tick ``k0``, for replaying them in order (each solve warm-started from the previous tick's answer,
    as in the loop). Used on an extra, untimed run of the episode."""

    FIELDS = ("P", "q", "A", "b", "G", "h", "lb", "ub")

    def __init__(self, k0: int, n: int) -> None:
        self.k0, self.n = k0, n
        self.values: list[tuple[np.ndarray, ...]] = []

    def on_tick(self, k: int, t_s: float, problem, result) -> None:
        if self.k0 <= k < self.k0 + self.n:
            self.values.append(tuple(getattr(problem, f).copy() for f in self.FIELDS))


def replayed_solve_us(built: Built, n: int = REPLAY_TICKS) -> float:
    """Median µs of the backend solving the QPs of ``n`` consecutive walking ticks in order, timed alone:
    one more (untimed) run of the episode records them, then they are written into the filter's backend
    problem one by one and solved (a fresh solver, warm-started from tick to tick as in the loop). Solving
    one tick's QP again and again would warm-start each solve from its own answer (no iterations): a
    lower bound the loop cannot reach."""
    e = built.episode
    if built.filter is None or built.backend is None:
        raise ValueError("replayed_solve_us: the run has no safety filter (no QP to solve)")
    seq = QPSequence(round(e.controller.stand_duration_s / e.s.control_dt_s) + 1, n)
    e.with_observers([FilterQPs(seq)], analyse=False).run()
    problem, backend = built.filter.backend_problem, built.backend
    backend.reset()
    times = np.empty(len(seq.values))
    for i, values in enumerate(seq.values):
        for field, value in zip(QPSequence.FIELDS, values, strict=True):
            np.copyto(getattr(problem, field), value)
        t0 = time.perf_counter()
        backend.solve(problem)
        times[i] = time.perf_counter() - t0
    return float(np.median(times[1:]) * 1e6) if len(times) > 1 else float("nan")  # [0]: the setup


def replayed_mj_step_us(built: Built, trace: EpisodeTrace, n: int = REPLAY_TICKS) -> float:
    """Median µs of ``mj_step`` replaying ``n`` consecutive walking ticks of the episode's ``trace`` in order
    (a fresh MjData set to the state after tick k - 1 with tick k's torques, timed alone; MuJoCo's solver
    warm start carries over from the previous replayed step as in the loop). Stepping one copy of the final
    state over and over drifts away from the loop's states: with no torques the robot collapses onto its
    trunk (7 contacts instead of 2-4 and a dearer step)."""
    e = built.episode
    m, act = e.m, e.bridge.actuator_ids
    d = mujoco.MjData(m)
    k0 = max(round(e.controller.stand_duration_s / e.s.control_dt_s) + 1 - trace.offset, 1)
    rows = range(k0, min(k0 + n, trace.n - trace.offset))
    times = np.empty(len(rows))
    for i, k in enumerate(rows):
        d.qpos[:], d.qvel[:] = trace.qpos_mj[k - 1], trace.qvel_mj[k - 1]
        d.ctrl[act] = trace.u[k]
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        times[i] = time.perf_counter() - t0
    return float(np.median(times[1:])) * 1e6 if len(times) > 1 else float("nan")  # [0]: no warm start yet


def part_costs(built: Built, trace: EpisodeTrace | None = None) -> dict[str, float]:
    """Median µs of each tick part at the episode's final state (mj_step over the states of the episode's
    ``trace`` replayed in order, :func:`replayed_mj_step_us`, None: run the episode once more for it; the QP
    solve over a replayed sequence of the episode's QPs, :func:`replayed_solve_us`). Only the parts the loop
    runs: no Pinocchio update and no QP without a filter."""
    e = built.episode
    d, br = e.d, e.bridge
    qj, qdj = d.qpos[br.joint_qadr].copy(), d.qvel[br.joint_dadr].copy()
    q, v = br.q_pin(d.qpos), br.v_pin(d.qpos, d.qvel)
    t = [e.controller.stand_duration_s + 1.0]

    tau = np.zeros(12)
    compute = compute_of(e.controller)

    def ctrl():
        t[0] += 1e-3
        compute(t[0], qj, qdj, q[:7], v[:6], tau)

    if trace is None:
        trace = e.run().traced()
    costs = {
        "mj_step": replayed_mj_step_us(built, trace),
        "controller": _median_us(ctrl),
        "contact_check": _median_us(lambda: e.contacts.check_non_foot_contact(d)),
    }
    if (safety_filter := built.filter) is not None:
        costs["pinocchio_update"] = _median_us(lambda: e.model.update(q, v))
        gs = e.controller.contact_plan(t[0])
        u = compute(t[0], qj, qdj, q[:7], v[:6], tau)
        inputs = TickInputs(e.model, v, gs.in_stance, 1.0, gs.swing_phase, gs.swing_phase_rate)
        costs["qp_build"] = _median_us(lambda: safety_filter.build(inputs, u), 1000)
        costs["qp_solve"] = replayed_solve_us(built)
    return costs


_COLUMNS = ("loop", "tick µs (median)", "real-time factor", "sum-of-parts limit", "share of limit", "status",
            "fell", "in the loop µs (median)", "isolated µs (median)")  # fmt: skip
LIMIT_PARTS = ("mj_step", "controller", "pinocchio_update", "contact_check", "qp_build", "qp_solve")
_NOTES = (
    "Tick = wall time of one 1 kHz control tick (state read, estimator, controller, bridge + Pinocchio, "
    "QP build + solve, physics step, contact check), median over the episode. Real-time factor = "
    "simulated time / wall time of the whole episode loop (also counts the per-tick trace copy and the "
    "fall checks). In the loop = median of each part of the tick timed inside the episode "
    "(`tick_<part>_us` in steps.parquet): controller = state read + estimator + controller + gait "
    "schedule; model = MuJoCo->Pinocchio state + Pinocchio terms; filter = QP build + backend + "
    "fallback policy; physics = mj_step + contact check. Isolated = the same code timed alone in a "
    "tight loop on the final state (2000 calls), mj_step over the plant states and torques of 1000 "
    "consecutive walking ticks replayed in order, the QP solve over the QPs of those ticks replayed in order "
    "(warm-started tick to tick as in the loop; re-solving one QP would start from its own answer, stepping "
    "one state again and again drifts away from the loop's states); the difference is what interleaving "
    "costs (caches). The nominal-only loop's parts "
    "are those it runs (no Pinocchio update, no QP). "
    "Sum-of-parts limit = control period / (the isolated parts summed, mj_step once per physics step): the "
    "real-time factor of a loop that costs nothing but its parts; share of limit = real-time factor / limit. "
    "Other processes on the machine inflate all numbers alike.\n"
)


def sum_of_parts_limit(isolated: dict[str, float], control_dt_s: float, physics_per_tick: int) -> float:
    """Real-time factor of a tick costing only its isolated parts (see the notes)."""
    parts = {k: v for k, v in isolated.items() if k in LIMIT_PARTS}
    total_us = sum(parts.values()) + parts.get("mj_step", 0.0) * (physics_per_tick - 1)
    return control_dt_s * 1e6 / total_us if total_us > 0 else float("nan")


COLD_PARTS = ("controller", "pinocchio_update", "qp_build")  # idempotent calls: timed twice in a row


def cold_vs_warm(built: Built) -> dict[str, tuple[float, float]]:
    """{part: (median µs of its call in the loop, median µs of the same call repeated at once)} from one more
    (instrumented, untimed) run of the episode: the controller, the Pinocchio update and (with a filter) the
    QP build are called twice in a row on every tick, the same code on the same data, so the second call
    finds its code and data in the caches the rest of the tick evicts; mj_step: its call in the loop vs
    :func:`part_costs`' tight loop (measured separately). The gap is the cost of interleaving the parts, which no
    glue-code cut removes."""
    e = built.episode
    calls = {"controller": (e.controller, "compute"), "pinocchio_update": (e.model, "update")}
    if built.filter is not None:
        calls["qp_build"] = (built.filter, "build")
    else:
        del calls["pinocchio_update"]
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in calls}
    times["mj_step"] = []

    def twice(label, fn):
        def call(*args):
            t0 = time.perf_counter()
            fn(*args)
            t1 = time.perf_counter()
            out = fn(*args)
            times[label].append((t1 - t0, time.perf_counter() - t1))
            return out
        return call

    step = mujoco.mj_step

    def timed_step(m, d):
        t0 = time.perf_counter()
        step(m, d)
        times["mj_step"].append((time.perf_counter() - t0, float("nan")))

    for label, (obj, name) in calls.items():
        setattr(obj, name, twice(label, getattr(obj, name)))
    analyse, e.s = e.s.analyse, replace(e.s, analyse=False)
    mujoco.mj_step = timed_step
    try:
        e.run()
    finally:
        mujoco.mj_step = step
        e.s = replace(e.s, analyse=analyse)
        for obj, name in calls.values():
            delattr(obj, name)  # the instance attribute: the method again
    medians = {k: np.median(np.array(v[1:]) * 1e6, axis=0) for k, v in times.items() if v}  # (n, 2) -> (2,)
    return {k: (float(m[0]), float(m[1])) for k, m in medians.items()}


def back_to_back(built: Built, wall_per_tick_us: float, n: int = REPLAY_TICKS) -> dict[str, Any]:
    """The limit's parts replayed on ``n`` of the loop's walking ticks (:mod:`taslel_bench.qp.tick_replay`,
    one more run of the episode records them): the sums of their medians [µs] alone and back to back with no
    glue (mj_step x physics steps per tick, as the limit), the share alone / back to back (the most a loop
    with no glue could reach) and alone / the loop's wall per tick ``wall_per_tick_us``. {} when the episode
    walks too briefly to record 10 ticks; {"ticks": 0, "error": why} when the replay fails (a run that ends
    early, answers or states that differ from the loop's)."""
    e = built.episode
    n = min(n, round(e.s.duration_s / e.s.control_dt_s) - AFTER_STAND_TICKS - 1)  # walking ticks left to record
    if n < 10:
        return {}
    try:
        alone, back, worst = replay(built, record_ticks(built, n))
    except RuntimeError as exc:
        return {"ticks": 0, "error": f"not replayed: {exc}"}
    ppt = e.physics_per_tick

    def total(parts: dict[str, np.ndarray]) -> float:
        return sum(float(np.median(x)) * (ppt if p == "mj_step" else 1) for p, x in parts.items())

    a, b = total(alone), total(back)
    return {"ticks": n, "alone": a, "back to back": b, "share back to back": a / b, "wall": wall_per_tick_us,
            "share loop": a / wall_per_tick_us, "u error": worst["u_nm"] if built.filter is not None else float("nan")}


# each timed part of the loop's tick (TICK_PARTS) and the isolated parts it contains
ISOLATED_IN_PART = {"controller": ("controller",), "model": ("pinocchio_update",),
                    "filter": ("qp_build", "qp_solve"), "physics": ("mj_step", "contact_check")}


def wall_accounting(wall_per_tick_us: float, tick_mean_us: float, parts_mean_us: dict[str, float],
                    isolated: dict[str, float], physics_per_tick: int) -> dict[str, float]:
    """Where the loop's wall time per tick goes, as means [µs] (the real-time factor is a mean):
    ``isolated`` = the sum-of-parts limit's parts; ``<part> excess`` = the part's mean in the loop minus the
    isolated parts it contains (its glue code and running with caches the rest of the tick evicted);
    ``outside the tick`` = wall time per tick minus the mean tick (trace copy, end checks, loop). The
    entries after ``wall`` add up to it."""
    excess, iso_total = {}, 0.0
    for part in TICK_PARTS:
        if part not in parts_mean_us:
            continue
        iso = sum(isolated.get(k, 0.0) * (physics_per_tick if k == "mj_step" else 1)
                  for k in ISOLATED_IN_PART[part])  # fmt: skip
        iso_total += iso
        excess[f"{part} excess"] = parts_mean_us[part] - iso
    return {"wall": wall_per_tick_us, "isolated": iso_total, **excess,
            "outside the tick": wall_per_tick_us - tick_mean_us}


def main(argv: list[str] | None = None) -> None:
    """Run each loop, print the table and, with ``--out``, write it as markdown with a figure. A loop (or a
    run of ``--main``) on a busy machine (:class:`taslel_bench.util.machine.CpuShare`) is named; the
    markdown is then refused (exit 1) unless ``--allow-busy``, and carries the note when allowed."""
    args = _parse_args(argv)
    load_before = os.getloadavg()[0]
    rows, busy = [], []
    for label, extra in _loop_configs(args.solvers, args.formulations, args.controllers, args.robot):
        with CpuWatch() as watch:
            rows.append(_run_loop(label, extra, args))
        assert watch.result is not None  # set when the with block ends
        if watch.result.busy_reason:
            busy.append(f"{label}: {watch.result.busy_reason}")
    main_rtf = main_command(args.main, busy) if args.main else {}
    _print_table(rows, args)
    if main_rtf:
        print(_main_text(args.main, main_rtf))
    note = busy_note(busy)
    if note:
        print(note)
    if args.out is not None:
        if note and not args.allow_busy:
            raise SystemExit(f"error: {note}; {args.out} not written: its numbers would measure the other work "
                             f"on this machine, not the code. Rerun on a quiet machine, or pass --allow-busy to "
                             f"write it with this note")
        _write_markdown(rows, args, load_before, main_rtf, note)


def busy_note(busy: list[str]) -> str:
    """One line naming the loops measured on a busy machine ("" if none)."""
    return f"machine busy during the measurement ({'; '.join(busy)})" if busy else ""


def main_command(solvers: str, busy: list[str] | None = None) -> dict[str, float]:
    """Run ``python -m taslel_bench -m solver=<solvers>`` (the default config otherwise; its jobs run in
    parallel) into a temporary sweep folder; {solver: real-time factor of its run}. Its runs on a busy
    machine are appended to ``busy``."""
    import pandas as pd

    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "taslel_bench", "-m", f"solver={solvers}", "progress=false",
               f"hydra.sweep.dir={tmp}"]  # fmt: skip
        subprocess.run(cmd, check=True, capture_output=True, text=True)
        table = pd.read_parquet(Path(tmp) / "summary.parquet")
    if busy is not None and "machine_busy" in table:
        busy += [f"main command {r['solver']}: {r['machine_busy_reason']}" for _, r in table.iterrows()
                 if bool(r["machine_busy"])]
    return {str(r["solver"]): float(r["real_time_factor"]) for _, r in table.iterrows()}


def _main_text(solvers: str, rtf: dict[str, float]) -> str:
    runs = ", ".join(f"{s} {v:.1f}x" for s, v in sorted(rtf.items()))
    return (f"Main command `python -m taslel_bench -m solver={solvers}` (default config, its two jobs in parallel "
            f"on the machine's cores): real-time factor per run: {runs}.")


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line: episode duration [s], solvers, formulations, scenario, markdown output file."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=5.0, help="walking time per episode [s]")
    ap.add_argument("--solvers", default="daqp,osqp,clarabel,qpsolvers:osqp",
                    help="comma-separated solver options (qpsolvers:<name>: the per-call route)")
    ap.add_argument("--formulations", default="full,condensed",
                    help="filter.formulation values to run for each solver (full, condensed)")
    ap.add_argument("--scenario", default="flat")
    ap.add_argument("--controllers", default="trot",
                    help="comma-separated nominal controllers: trot, policy (the robot's shipped policy)")
    ap.add_argument("--robot", default="a1", help="conf/robot/<robot>.yaml")
    ap.add_argument("--override", action="append", default=[],
                    help="a config override added to every loop (repeatable), e.g. --override estimator=fixed")
    ap.add_argument("--out", type=Path, default=None, help="also write the table as markdown to this file")
    ap.add_argument("--cold", action="store_true",
                    help="also time idempotent parts twice in a row in one more run (cost of interleaving)")
    ap.add_argument("--main", default="", help="also run the main command with these solvers, e.g. osqp,clarabel")
    ap.add_argument("--allow-busy", action="store_true",
                    help="write --out even when the machine was busy during a loop (the file then says so)")
    return ap.parse_args(argv)


def _loop_configs(solvers: str, formulations: str, controllers: str = "trot", robot: str = "a1"
                  ) -> list[tuple[str, list[str]]]:
    """(label, config overrides) of each loop, per nominal controller (comma-separated ``controllers``): the
    nominal-only loop, then the filter with each solver (comma-separated ``solvers``) in each formulation
    (comma-separated ``formulations``). A label names the controller when there is more than one."""
    loops = []
    names = [c for c in controllers.split(",") if c]
    for controller in names:
        pick = ["controller=policy", f"policy={robot}_walk"] if controller == "policy" else [
            f"controller={controller}"]
        prefix = f"{controller}: " if len(names) > 1 else ""
        loops += [(f"{prefix}nominal only", [*pick, "filter.enabled=false"])] + [
            (f"{prefix}filter ({form}) + {s}", [*pick, *_solver_overrides(s), f"filter.formulation={form}"])
            for s in solvers.split(",") if s
            for form in formulations.split(",") if form
        ]
    return loops


def _solver_overrides(name: str) -> list[str]:
    """``solver=<name>``, or for ``qpsolvers:<name>`` the per-call route's two overrides."""
    if name.startswith("qpsolvers:"):
        return ["solver=qpsolvers", f"solver.name={name.removeprefix('qpsolvers:')}"]
    return [f"solver={name}"]


def _run_loop(label: str, extra: list[str], args: argparse.Namespace) -> tuple:
    """Run one episode with the overrides ``extra``. Returns the row (label, median tick [µs], real-time
    factor, sum-of-parts limit, status, fell, {part: median µs in the loop}, {part: median µs in isolation},
    :func:`wall_accounting`, :func:`cold_vs_warm` and :func:`back_to_back`, both {} without ``--cold``)."""
    cfg = compose([f"robot={args.robot}", f"duration={args.duration}", f"scenario={args.scenario}", "progress=false",
                   *args.override, *extra])
    built = Built(cfg)
    res = built.episode.run()
    tr = res.traced()
    n = tr.n
    rtf = n * 1e-3 * (1000.0 / float(cfg.control_rate_hz)) / res.wall_time_s
    in_loop = {part: float(np.median(tr.tick_parts_us[:n, j])) for j, part in enumerate(TICK_PARTS)}
    if built.filter is None:
        del in_loop["model"], in_loop["filter"]
    parts_mean = {part: float(np.mean(tr.tick_parts_us[:n, j])) for j, part in enumerate(TICK_PARTS)
                  if part in in_loop}  # fmt: skip
    wall_us, tick_mean_us = res.wall_time_s / n * 1e6, float(np.mean(tr.tick_us[:n]))
    isolated = part_costs(built, tr)
    ppt = built.episode.physics_per_tick
    limit = sum_of_parts_limit(isolated, 1.0 / float(cfg.control_rate_hz), ppt)
    accounting = wall_accounting(wall_us, tick_mean_us, parts_mean, isolated, ppt)
    cold = cold_vs_warm(built) if args.cold else {}
    back = back_to_back(built, wall_us) if args.cold else {}
    return (label, float(np.median(tr.tick_us[:n])), rtf, limit, res.status, res.fell, in_loop, isolated,
            accounting, cold, back)


def _fmt_parts(parts: dict[str, float]) -> str:
    """{part: µs} as ``part 12.3, ...``."""
    return ", ".join(f"{k} {v:.1f}" for k, v in parts.items())


def _print_table(rows: list[tuple], args: argparse.Namespace) -> None:
    """The rows as a rich table on the console."""
    table = Table(title=f"tick cost, {args.scenario}, {args.duration} s walk, 1 kHz control "
                  f"({platform.processor() or platform.machine()}, {os.cpu_count()} cores)")
    for col in _COLUMNS:
        table.add_column(col)
    for label, tick, rtf, limit, status, fell, in_loop, isolated, *_ in rows:
        table.add_row(label, f"{tick:.1f}", f"{rtf:.1f}x", f"{limit:.1f}x", f"{rtf / limit:.2f}", status, str(fell),
                      _fmt_parts(in_loop), _fmt_parts(isolated))  # fmt: skip
    Console(width=220).print(table)
    print(_accounting_text(rows))
    if args.cold:
        print(_cold_text(rows))
        print(_back_to_back_text(rows))


def _accounting_text(rows: list[tuple]) -> str:
    """The :func:`wall_accounting` of each loop as a markdown table (mean µs per tick)."""
    keys = list(dict.fromkeys(k for r in rows for k in r[8]))
    cells = [(r[0], *(f"{r[8][k]:.1f}" if k in r[8] else "-" for k in keys)) for r in rows]
    head = ("Where the wall time per tick goes (means, µs; `isolated` = the limit's parts, `<part> excess` = "
            "the part in the loop minus its isolated parts: glue code and caches the rest of the tick evicted, "
            "`outside the tick` = trace copy, end checks, loop; they add up to `wall`):\n")
    return head + markdown_table(cells, ("loop", *keys), fmt=str).rstrip("\n")


def _cold_text(rows: list[tuple]) -> str:
    """The :func:`cold_vs_warm` of each loop as a markdown table."""
    cells = []
    for r in rows:
        for part, (first, second) in r[9].items():
            warm = r[7].get("mj_step", float("nan")) if part == "mj_step" else second
            cells.append((r[0], part, f"{first:.1f}", f"{warm:.1f}", f"{first - warm:.1f}"))
    head = ("Interleaving (`--cold`): each call in the loop vs the same call repeated at once (mj_step: vs its "
            "isolated tight loop), median µs:\n")
    return head + markdown_table(cells, ("loop", "part", "in the loop", "warm", "cold penalty"), fmt=str).rstrip("\n")


DISTURBED_SHARE = 1.05  # a share above this: the parts alone timed slower than the same parts with more around them


def _disturbed(b: dict[str, Any]) -> str:
    """Empty, or why the row's shares cannot be read: the replay failed, or the parts alone timed slower than
    the same parts back to back or than the whole loop (the machine's speed changed between the runs)."""
    if "error" in b:
        return b["error"]
    over = [k for k in ("share back to back", "share loop") if b[k] > DISTURBED_SHARE]
    return f"{' and '.join(over)} > {DISTURBED_SHARE}: the machine's speed changed between the runs" if over else ""


def _back_to_back_cells(b: dict[str, Any]) -> tuple[str, ...]:
    """The numbers of one :func:`back_to_back` row (dashes when it was not replayed)."""
    if "error" in b:
        return ("-",) * 6
    return (f"{b['alone']:.1f}", f"{b['back to back']:.1f}", f"{b['share back to back']:.2f}", f"{b['wall']:.1f}",
            f"{b['share loop']:.2f}", f"{b['u error']:.1g}" if np.isfinite(b["u error"]) else "-")


def _back_to_back_text(rows: list[tuple]) -> str:
    """The :func:`back_to_back` of each loop as a markdown table."""
    cells = [(r[0], *_back_to_back_cells(b), _disturbed(b)) for r in rows if (b := r[10])]
    n = max((r[10]["ticks"] for r in rows if r[10]), default=0)
    head = (f"Back to back (`--cold`): the limit's parts replayed on {n} of the loop's walking ticks, each part "
            "alone and all of them one after the other with no glue between them (the replay's plant states "
            "checked equal to the loop's, its QP answers' u within `record.reference_tol_nm`: an iterative "
            "solver's first replayed solve starts cold; the largest u difference is its column); sums of the "
            "parts' medians, µs per tick. Share = alone / that column: back to back is the most a loop with no "
            "glue could reach; the gap from there to the loop's wall is the glue's own time:\n")
    cols = ("loop", "parts alone", "back to back", "share back to back", "loop wall per tick (mean)", "share loop",
            "max |u - u_loop| N·m", "check")
    return head + markdown_table(cells, cols, fmt=str).rstrip("\n")


def _write_markdown(rows: list[tuple], args: argparse.Namespace, load_before: float,
                    main_rtf: dict[str, float] | None = None, busy: str = "") -> None:  # fmt: skip
    """Write the rows as markdown to ``args.out`` (with the command, machine, 1-min load average at the
    start ``load_before`` and now, and what the columns mean) and the figure next to it (``.png``)."""
    info = machine_info()
    stamp = datetime.now().isoformat(timespec="seconds")
    load_after = os.getloadavg()[0]
    lines = [
        "# Control-tick cost\n",
        (f"`python -m taslel_bench.bench --duration {args.duration} --solvers {args.solvers} --formulations "
         f"{args.formulations} --scenario {args.scenario}" + (" --cold" if args.cold else "")
         + (f" --main {args.main}" if args.main else "")
         + f"` · {stamp}\n"),
        (f"Machine: {info['cpu']}, {info['cores']} cores, {info['os']}, Python {info['python']}; "
         f"load average during the run (1 min): {load_before:.1f} at start, {load_after:.1f} at end  \n"
         f"Packages: {info['packages']}  \nCode: {info['code']}\n"
         + (f"\n**Disturbed**: {busy} (written with --allow-busy).\n" if busy else "")),
        _NOTES,
    ]
    cells = [(label, f"{tick:.1f}", f"{rtf:.1f}x", f"{limit:.1f}x", f"{rtf / limit:.2f}", status, fell,
              _fmt_parts(in_loop), _fmt_parts(isolated))
             for label, tick, rtf, limit, status, fell, in_loop, isolated, *_ in rows]  # fmt: skip
    lines.append(markdown_table(cells, _COLUMNS, fmt=str).rstrip("\n"))
    lines += ["", _accounting_text(rows)]
    if args.cold:
        lines += ["", _cold_text(rows), "", _back_to_back_text(rows)]
    if main_rtf:
        lines += ["", _main_text(args.main, main_rtf)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure = args.out.with_suffix(".png")
    lines += ["", f"![tick parts in the loop]({figure.name})"]
    atomic_write(figure, lambda p: _plot_parts(rows, args.scenario, p))
    atomic_write(args.out, lambda p: p.write_text("\n".join(lines) + "\n"))
    print(f"wrote {args.out}, {figure}")


def _plot_parts(rows: list, scenario: str, path: Path) -> None:
    """Stacked bars: the median in-loop cost of each tick part per loop, real-time factor on top."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 0.6 * len(rows) + 2.0))
    labels = [r[0] for r in rows]
    left = np.zeros(len(rows))
    for part in TICK_PARTS:
        widths = np.array([r[6].get(part, 0.0) for r in rows])
        ax.barh(labels, widths, left=left, label=part)
        left += widths
    for i, r in enumerate(rows):
        ax.text(left[i] + 3, i, f"{r[2]:.1f}x real time", va="center", fontsize=8)
    ax.axvline(100.0, color="k", lw=0.8, ls="--")
    ax.text(100.0, -0.45, " 100 µs: 10x real time", fontsize=8, va="top")
    ax.invert_yaxis()
    ax.set_xlabel("median wall time per 1 kHz tick, timed inside the loop [µs]")
    ax.set_title(f"where the control tick's time goes ({scenario})")
    ax.set_xlim(0, max(left.max() * 1.35, 120))
    ax.legend(ncol=len(TICK_PARTS), loc="upper center", bbox_to_anchor=(0.5, -0.3), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
