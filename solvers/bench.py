"""Quick table: every QP backend on recorded filter QPs (not a test). The full benchmark (cold / warm /
persistent modes, settings profiles, correctness checked against the reference, deadline misses, report) is
``python -m taslel_bench.replay <QP set>``; this script is the fast look at one set in episode order.

    python -m solvers.bench                       # the fixture (tests/data/qps_episode.npz)
    python -m solvers.bench --episode 2           # a fresh 2 s closed-loop episode, every tick in order
    python -m solvers.bench --only osqp_persistent daqp_persistent --repeat 5

Backends come from ``conf/solver/*.yaml`` (the settings a sweep would use). Per backend, the QPs are solved
in episode order after a ``reset()`` (so persistent backends warm start from the previous tick), ``repeat``
times; each QP's time is the minimum over the repeats. Columns: solve time median / p99 [µs] (the solver
call: ``solve_time_s``), harness overhead median [µs] (``overhead_s``: conversions + answer check), setup
part median [µs], median iterations, failed QPs, and the max |u - u_ref| [N·m] over solved QPs.
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

import numpy as np

from taslel_bench.interfaces import QPBackend, QPProblem

CONF_DIR = Path(__file__).resolve().parent.parent / "conf" / "solver"


def configured_backends(only: list[str] | None = None) -> dict[str, QPBackend]:
    """Instantiate ``conf/solver/<name>.yaml`` for every name (all files when ``only`` is None)."""
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    out = {}
    for f in sorted(CONF_DIR.glob("*.yaml")):
        if only is None or f.stem in only:
            out[f.stem] = instantiate(OmegaConf.load(f))
    return out


def run_backend(backend: QPBackend, problems: list[QPProblem], x_ref: np.ndarray, repeat: int) -> dict:
    u = problems[0].layout["u"]
    times = np.full((repeat, len(problems)), np.inf)
    overhead, setup, iters, err, failed = [], [], [], [], 0
    for r in range(repeat):
        backend.reset()
        for i, p in enumerate(problems):
            sol = backend.solve(p)
            times[r, i] = sol.solve_time_s
            if r:
                continue
            overhead.append(getattr(sol, "overhead_s", float("nan")))
            setup.append(sol.setup_time_s)
            iters.append(np.nan if sol.iterations is None else sol.iterations)
            if sol.ok:
                err.append(float(np.max(np.abs(sol.x[u] - x_ref[i, u]))))
            else:
                failed += 1
    t = times.min(axis=0) * 1e6
    return {
        "median_us": float(np.median(t)),
        "p99_us": float(np.percentile(t, 99)),
        "overhead_us": float(np.nanmedian(overhead) * 1e6),
        "setup_us": float(np.median(setup) * 1e6),
        "iters": float(np.nanmedian(iters)) if not np.all(np.isnan(iters)) else float("nan"),
        "failed": failed,
        "max_du": max(err) if err else float("nan"),
    }


def settings_line(backend: QPBackend) -> str:
    d = backend.describe()
    if "primary" in d:
        return f"{d['primary']['name']} checked by {d['secondary']['name']}, agree {d['agree_u_nm']:g} N·m"
    extra = {k: d[k] for k in ("warm_start", "backend", "presolve") if k in d}
    return f"{d.get('package')} {d.get('version')} {d.get('settings')} {extra or ''}".strip()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episode", type=float, default=0.0, help="record a fresh episode of this many seconds")
    ap.add_argument("--fixture", type=Path, default=None, help="any QP set (taslel_bench.record.qpset); default: the fixture")
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    if args.episode > 0:
        from solvers.record_fixture import record_episode

        problems, x_ref = record_episode(args.episode, mu=0.3)
        source = f"fresh {args.episode:g} s episode, {len(problems)} consecutive QPs (mu 0.3, 8 cm ECBF bump)"
    else:
        from solvers.fixture import DEFAULT_PATH, load

        qs = load(args.fixture or DEFAULT_PATH)
        problems, x_ref = qs.problems, qs.x_ref
        source = f"fixture {args.fixture or DEFAULT_PATH.name}, {len(problems)} QPs"
    print(f"# QP backends on {source}; {platform.processor() or platform.machine()}, repeat {args.repeat}")
    head = f"{'backend':<18} {'med µs':>8} {'p99 µs':>8} {'ovh µs':>7} {'setup µs':>8} {'iters':>5} {'fail':>4} {'max|du| N·m':>11}"
    print(head)
    print("-" * len(head))
    backends = configured_backends(args.only)
    for name, backend in backends.items():
        r = run_backend(backend, problems, x_ref, args.repeat)
        print(f"{name:<18} {r['median_us']:8.0f} {r['p99_us']:8.0f} {r['overhead_us']:7.0f} {r['setup_us']:8.0f} "
              f"{r['iters']:5.0f} {r['failed']:4d} {r['max_du']:11.1e}")  # fmt: skip
    print("\nsettings:")
    for name, backend in backends.items():
        print(f"  {name:<18} {settings_line(backend)}")


if __name__ == "__main__":
    main()
