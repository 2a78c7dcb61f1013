"""``python -m taslel_bench.qpset info|merge``: inspect a QP test set, or merge the ``qps.npz`` files of a sweep
(optionally with the tight reference solution of every QP, for :mod:`taslel_bench.qp.replay`)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from taslel_bench.qp.replay import reference_solutions
from taslel_bench.record import qpset


def describe(qs: qpset.QPSet) -> str:
    scen = qs.scenario()
    lines = [f"{len(qs)} QPs, {len(qs.runs)} runs, {len(qs.groups)} layouts"]
    for s in sorted(set(scen)):
        sel = scen == s
        lines.append(f"  {s or '?'}: {int(sel.sum())} QPs")
    for gi, g in enumerate(qs.groups):
        lines.append(f"  layout {gi}: n={g.P.shape[0]} m_eq={g.A_pattern.shape[0]} m_in={g.G_pattern.shape[0]}, "
                     f"{g.members.size} QPs, x_ref known for {int(np.isfinite(g.x_ref[:, 0]).sum())}")  # fmt: skip
    fails = int(np.sum(qs.status != "solved"))
    lines.append(f"  filter status not solved: {fails}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="QP test sets: info / merge")
    sub = ap.add_subparsers(dest="cmd", required=True)
    info = sub.add_parser("info")
    info.add_argument("path", type=Path)
    mg = sub.add_parser("merge", help="merge qps.npz files (or folders holding them, e.g. a sweep)")
    mg.add_argument("paths", type=Path, nargs="+")
    mg.add_argument("-o", "--out", type=Path, required=True)
    mg.add_argument("--reference", action="store_true",
                    help="store the tight reference (conf/solver/reference.yaml) of every QP in the set")
    args = ap.parse_args(argv)
    if args.cmd == "info":
        print(describe(qpset.load(args.path)))
        return
    files = qpset.find_sets(args.paths)
    if not files:
        raise SystemExit(f"no {qpset.FILENAME} under {', '.join(map(str, args.paths))} (run with record.qps=true)")
    qs = qpset.merge((qpset.load(f) for f in files), {"merged_from": [str(f) for f in files]})
    if args.reference:
        reference_solutions(qs)
    qpset.save(args.out, qs)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.1f} MB)\n{describe(qs)}")


if __name__ == "__main__":
    main()
