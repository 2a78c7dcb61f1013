"""Record real filter QPs from a closed-loop episode and write the test fixture.

    python -m solvers.record_fixture                      # -> tests/data/qps_episode.npz
    python -m solvers.record_fixture --seconds 2 --count 100 --mu 0.3 --out /tmp/qps.npz

The A1 trots on the default plant under the nominal controller, its torques filtered by the ID-CBF-QP
(solved by the cross-checked reference, :mod:`solvers.reference`) with a low assumed friction (mu = 0.3, so
pyramid rows bind) and the paper's 8 cm clearance bump z(s) = 0.08 * 16 s²(1 - s)² (so ECBF rows bind in
swing). Every tick's QP is copied; ``--count`` of them are kept: the ticks where ECBF rows, friction rows
or torque limits bind first (spread over the episode), then evenly spaced others.

This script is the one place in ``solvers/`` that drives a closed loop; it does so through the core's
façade for axis packages (:mod:`taslel_bench.api`: config, controller, filter, model, state bridge) and the
plant builder, and stores the set with the core's QP-set tools. The backends only use
:mod:`taslel_bench.interfaces`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from solvers.fixture import DEFAULT_PATH, save
from solvers.reference import reference_backend
from taslel_bench.interfaces import ClearanceProfile, QPProblem
from taslel_bench.record.qpset import active_sets, binding_tags

BUMP_M = 0.08  # [m] obstacle peak of the clearance profile
BUMP = (0.0, 0.0, 16 * BUMP_M, -32 * BUMP_M, 16 * BUMP_M)  # z(s) = 16 h s² (1 - s)²


def record_episode(seconds: float, mu: float, backend=None) -> tuple[list[QPProblem], np.ndarray]:
    """Run the closed loop for ``seconds`` at 1 kHz; return every tick's QP (copies) and solution x.

    The filter is the project's (``conf/filter``) with the tight reference backend (``solver=reference``)
    unless ``backend`` is given."""
    import mujoco

    from taslel_bench import api
    from taslel_bench.plant.build import build_plant
    from taslel_bench.robot import a1

    cfg = api.compose(["solver=reference"])
    sf = api.build_safety_filter(cfg, profile=ClearanceProfile(BUMP))
    if backend is not None:
        sf.backend = backend
    m = build_plant()
    d = mujoco.MjData(m)
    bridge, model = api.StateBridge(m), api.A1Model()
    ctl = api.build_controller(cfg)
    q0 = model.neutral_q()
    q0[2] = ctl.gait.p.stand_height_m + a1.FOOT_RADIUS_M
    q0[7:] = ctl.stand_configuration()
    bridge.qpos_mj(q0, d.qpos)
    mujoco.mj_forward(m, d)
    limit = sf.settings.torque_limit_nm
    q, v = np.zeros(a1.NQ), np.zeros(a1.NV)
    qps, xs = [], []
    for k in range(round(seconds * 1000)):
        t = k * 1e-3
        bridge.state_pin(d.qpos, d.qvel, q, v)
        u_nom = ctl.compute(t, q[7:], v[6:])
        model.update(q, v)
        gs = ctl.gait_state(t)
        qp = sf.build(api.TickInputs(model, v, gs.in_stance, mu, gs.swing_phase, gs.swing_phase_rate), u_nom)
        qps.append(qp.copy())
        sol = sf.backend.solve(qp)
        if not sol.ok:
            raise RuntimeError(f"reference failed at tick {k}: {sol.status}")
        xs.append(sol.x.copy())
        bridge.ctrl_mj(np.clip(sol.x[qp.layout["u"]], -limit, limit), d.ctrl)
        mujoco.mj_step(m, d)
    return qps, np.array(xs)


def binding(problem: QPProblem, x: np.ndarray) -> list[str]:
    """Constraint families that bind at x: "ecbf", "friction" (pyramid sides), "torque" (the core's rule,
    :func:`taslel_bench.record.qpset.binding_tags`, also used for the stored sets)."""
    rows, bounds = active_sets(problem, x)
    return binding_tags(problem.row_labels, rows, bounds, problem.layout)


def select(tags: list[list[str]], count: int) -> np.ndarray:
    """Tick indices: up to count/4 each for ecbf, friction and torque (spread out), then evenly spaced."""
    chosen: set[int] = set()
    for family in ("ecbf", "friction", "torque"):
        idx = [i for i, t in enumerate(tags) if family in t]
        take = min(len(idx), count // 4)
        if take:
            chosen.update(idx[j] for j in np.linspace(0, len(idx) - 1, take).round().astype(int))
    rest = [i for i in range(len(tags)) if i not in chosen]
    take = max(count - len(chosen), 0)
    chosen.update(rest[j] for j in np.linspace(0, len(rest) - 1, take).round().astype(int))
    return np.array(sorted(chosen))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--out", type=Path, default=DEFAULT_PATH)
    args = ap.parse_args(argv)
    qps, xs = record_episode(args.seconds, args.mu)
    tags = [binding(p, x) for p, x in zip(qps, xs)]
    keep = select(tags, args.count)
    meta = {
        "seconds": args.seconds, "mu": args.mu, "clearance_coeffs": list(BUMP),
        "reference": reference_backend().describe()["name"], "episode_ticks": len(qps),
        "binding_counts": {f: sum(f in t for t in tags) for f in ("ecbf", "friction", "torque", "none")},
    }  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    run = {"scenario": f"fixture_bump_mu{args.mu:g}", "source": "solvers.record_fixture"}
    save(args.out, [qps[i] for i in keep], xs[keep], keep, None, meta, run)
    kept = {f: sum(f in tags[i] for i in keep) for f in ("ecbf", "friction", "torque", "none")}
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} KiB): {len(keep)} QPs, binding {kept}; "
          f"episode: {meta['binding_counts']}")  # fmt: skip


if __name__ == "__main__":
    main()
