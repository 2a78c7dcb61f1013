"""Record real filter QPs from a closed-loop episode and write the test fixture.

    python -m studies.record_solver_fixture                      # -> tests/data/qps_episode.npz
    python -m studies.record_solver_fixture --seconds 2 --count 100 --mu 0.3 --out /tmp/qps.npz

The A1 trots on the default plant under the nominal controller, its torques filtered by the ID-CBF-QP
(solved by the cross-checked reference, :mod:`solvers.reference`) with a low assumed friction (mu = 0.3, so
pyramid rows bind) and the paper's 8 cm clearance bump z(s) = 0.08 * 16 s²(1 - s)² (so ECBF rows bind in
swing). Every tick's QP is copied; ``--count`` of them are kept: the ticks where ECBF rows, friction rows
or torque limits bind first (spread over the episode), then evenly spaced others.

The episode is the core's one loop (:class:`taslel_bench.api.Episode`, initial state and fall rule of a run
with seed 0); a hook on the filter copies each tick's QP and the solution the reference returned.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from estimators.simple import FixedEstimator
from solvers.reference import reference_backend
from taslel_bench.interfaces import ClearanceProfile, QPProblem
from taslel_bench.record.qpset import active_sets, binding_tags, from_problems
from taslel_bench.record.qpset import save as save_qpset

DEFAULT_PATH = Path(__file__).resolve().parents[1] / "tests" / "data" / "qps_episode.npz"  # the fixture
BUMP_M = 0.08  # [m] obstacle peak of the clearance profile
BUMP = (0.0, 0.0, 16 * BUMP_M, -32 * BUMP_M, 16 * BUMP_M)  # z(s) = 16 h s² (1 - s)²


class _Recorder:
    """The episode's QP hook: a copy of every tick's QP and the solution used."""

    def __init__(self) -> None:
        self.qps: list[QPProblem] = []
        self.xs: list[np.ndarray] = []

    def on_tick(self, k: int, t: float, problem: QPProblem, result) -> None:
        if result.used_fallback or result.solve is None:
            raise RuntimeError(f"reference failed at tick {k}: {result.status}")
        self.qps.append(problem.copy())
        self.xs.append(result.solve.x.copy())


def record_episode(seconds: float, mu: float, backend=None) -> tuple[list[QPProblem], np.ndarray]:
    """Run the core episode loop for ``seconds`` (stand included) at 1 kHz; return every tick's QP (copies)
    and solution x. The filter is the project's (``conf/filter``) with the tight reference backend
    (``solver=reference``) unless ``backend`` is given."""
    from dataclasses import replace

    from taslel_bench import api

    cfg = api.compose(["solver=reference"])
    world = api.StaticWorld(profile=ClearanceProfile(BUMP))
    sf = api.build_safety_filter(cfg, world.terrain, world.profile)
    if backend is not None:
        sf.backend = backend
    controller = api.build_controller(cfg)
    settings = replace(api.episode_settings(cfg), duration_s=seconds - controller.stand_duration_s, analyse=False)
    recorder = _Recorder()
    episode = api.Episode(settings, world, api.build_plant(world), controller, sf, FixedEstimator(mu),
                          np.random.default_rng(0), observers=[api.FilterQPs(recorder)])
    res = episode.run()
    if res.status != "ok" or res.fell:
        raise RuntimeError(f"the fixture episode did not run to its end: {res.message or res.fall_reason}")
    return recorder.qps, np.array(recorder.xs)


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
    tags = [binding(p, x) for p, x in zip(qps, xs, strict=True)]
    keep = select(tags, args.count)
    meta = {
        "seconds": args.seconds, "mu": args.mu, "clearance_coeffs": list(BUMP),
        "reference": reference_backend().describe()["name"], "episode_ticks": len(qps),
        "binding_counts": {f: sum(f in t for t in tags) for f in ("ecbf", "friction", "torque", "none")},
    }  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    run = {"scenario": f"fixture_bump_mu{args.mu:g}", "source": "studies.record_solver_fixture"}
    save_qpset(args.out, from_problems([qps[i] for i in keep], xs[keep], keep, meta, run))
    kept = {f: sum(f in tags[i] for i in keep) for f in ("ecbf", "friction", "torque", "none")}
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} KiB): {len(keep)} QPs, binding {kept}; "
          f"episode: {meta['binding_counts']}")  # fmt: skip


if __name__ == "__main__":
    main()
