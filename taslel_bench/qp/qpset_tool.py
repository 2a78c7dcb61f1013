"""``python -m taslel_bench.qpset info|merge``: inspect a QP test set, or merge the ``qps.npz`` files of a sweep
(optionally with the tight reference solution of every QP, for :mod:`taslel_bench.qp.replay`)."""

from __future__ import annotations

import argparse
import os
import sys
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
    try:
        if args.cmd == "info":
            print(describe(qpset.load(args.path)))
            return
        _merge(args)
    except qpset.QPSetError as exc:  # one line naming the file, before any work on the other files
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


def check_output(out: Path) -> None:
    """Refuse an output path that cannot be written (before merging): its folder must exist and be
    writable, and it must not be a folder."""
    folder = out.parent if str(out.parent) else Path(".")
    if out.is_dir():
        raise qpset.QPSetError(f"--out {out}: is a folder; give the path of the .npz file to write")
    if not folder.is_dir():
        raise qpset.QPSetError(f"--out {out}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise qpset.QPSetError(f"--out {out}: folder {folder} is not writable")


def _merge(args: argparse.Namespace) -> None:
    check_output(args.out)
    for p in args.paths:
        if not p.exists():
            raise qpset.QPSetError(f"{p}: no such file or folder")
    files = qpset.find_sets(args.paths)
    if not files:
        raise qpset.QPSetError(f"no {qpset.FILENAME} under {', '.join(map(str, args.paths))} (run with "
                               f"record.qps=true)")
    sets = [qpset.load(f) for f in files]  # every file checked before any work
    qs = qpset.merge(sets, {"merged_from": [str(f) for f in files]})
    if args.reference:
        reference_solutions(qs)
    try:
        qpset.save(args.out, qs)
    except OSError as exc:  # e.g. a full disk: name the output, not the temporary file
        raise qpset.QPSetError(f"--out {args.out}: could not be written ({exc.strerror or exc})") from None
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.1f} MB)\n{describe(qs)}")


if __name__ == "__main__":
    main()
