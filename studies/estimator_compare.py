"""Compare friction-estimator checkpoints on named window sets (``python -m studies.estimator_compare``).

For design choices (features, augmentation, data) without touching the test sets: each checkpoint is run
on every ``--set NAME=PATH.npz`` (files written by :mod:`estimators.collect`, any split) and its raw mean
and lower-quantile estimate are scored — MAE [-] and over-estimation rate (estimate > truth + 0.05) on all
windows and on the nominal-controller / filter-in-the-loop windows separately, plus the signed bias in
the lowest (mu < 0.4) and highest (mu >= 0.9) friction bands. The table goes to stdout and, with
``--out``, to a markdown file with the machine and the command.

Example (a shifted *validation* set collected with its own seed, never the shifted test split)::

    python -m estimators.collect --out /work/data/shiftval --train 0 --val 0 --test 0 --shifted 150 --seed 11
    python -m studies.estimator_compare attention_step /work/data/exp/ckpt/E_kin \\
        --set val=/work/data/estimators_f_big/val.npz --set shifted_val=/work/data/shiftval/shifted.npz
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np
import torch

from estimators.checkpoint import load_checkpoint
from estimators.data import load_windows
from studies.estimator_evaluate import markdown_table, predict_all
from taslel_bench.interfaces import OVERESTIMATE_MARGIN
from taslel_bench.util.machine import machine_info

LOW_MU, HIGH_MU = 0.4, 0.9  # [-] friction bands for the signed bias columns


def score(est: np.ndarray, y: np.ndarray, wf: np.ndarray) -> dict[str, float]:
    """MAE / over-estimation rate overall, on nominal and filtered windows, and the band biases."""
    err = est - y
    out: dict[str, float] = {}
    for tag, sel in (("all", np.ones_like(wf)), ("nominal", ~wf), ("filtered", wf)):
        if sel.any():
            out[f"mae[{tag}]"] = float(np.abs(err[sel]).mean())
            out[f"over[{tag}]"] = float((err[sel] > OVERESTIMATE_MARGIN).mean())
    for tag, sel in ((f"bias[mu<{LOW_MU}]", y < LOW_MU), (f"bias[mu>={HIGH_MU}]", y >= HIGH_MU)):
        if sel.any():
            out[tag] = float(err[sel].mean())
    return out


def compare(checkpoints: list[str], sets: dict[str, Path],
            describe: dict[str, str] | None = None) -> list[dict[str, object]]:
    """One row per (checkpoint, set, estimate); ``describe`` = {checkpoint name: what it is} adds a column."""
    # windows with the filter features; predict_all slices them for models that do not read them
    data = {name: load_windows(path, filter_mu=True) for name, path in sets.items()}
    rows: list[dict[str, object]] = []
    for ck in checkpoints:
        model, meta = load_checkpoint(ck)
        training = meta.get("training", {})
        for name, (X, y, _, wf) in data.items():
            mean, _, lower = predict_all(model, X)
            for label, est in (("mean", mean), ("lower", lower)):
                if est is None:
                    continue
                rows.append({"checkpoint": Path(ck).name,
                             **({"what": describe.get(Path(ck).name, "")} if describe else {}),
                             "train windows": training.get("train_windows"), "epochs": training.get("epochs"),
                             "set": name,
                             "estimate": label, **score(np.maximum(est, 0.05) if label == "lower" else est, y, wf)})
    return rows


def cell(column: str, value: object) -> str:
    """Table text of one value: over-estimation rates in %, biases signed, other floats with 4 decimals."""
    if not isinstance(value, float):
        return str(value)
    if column.startswith("over"):
        return f"{100 * value:.1f} %"
    return f"{value:+.3f}" if column.startswith("bias") else f"{value:.4f}"


def markdown(rows: list[dict[str, object]]) -> str:
    import pandas as pd

    cols = list(dict.fromkeys(k for r in rows for k in r))
    return markdown_table(pd.DataFrame([{c: cell(c, r.get(c, "")) for c in cols} for r in rows], columns=cols))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoints", nargs="+", help="shipped names (attention_step) or paths to .pt/.json")
    ap.add_argument("--set", action="append", required=True, metavar="NAME=PATH",
                    help="a window set: name and a collected .npz (repeatable)")
    ap.add_argument("--describe", action="append", default=[], metavar="CHECKPOINT=TEXT",
                    help="what a checkpoint is (a column of the table; repeatable)")
    ap.add_argument("--out", type=Path, default=None, help="markdown file to write")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args(argv)
    sets: dict[str, Path] = {}
    for item in a.set:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise SystemExit(f"--set {item!r}: expected NAME=PATH, e.g. val=/work/data/estimators/val.npz")
        sets[name] = Path(path)
    describe = {}
    for item in a.describe:
        name, sep, text = item.partition("=")
        if not sep:
            raise SystemExit(f"--describe {item!r}: expected CHECKPOINT=TEXT")
        describe[Path(name).name] = text
    torch.set_num_threads(a.threads)
    table = markdown(compare(a.checkpoints, sets, describe))
    print(table)
    if a.out is not None:
        cmd = "python -m studies.estimator_compare " + " ".join(
            shlex.quote(x) for x in (sys.argv[1:] if argv is None else argv)
        )
        info = machine_info()
        head = [
            "# Estimator checkpoints on named window sets", "",
            f"Generated by `{cmd}`.", "",
            "Raw mean and lower-quantile head (floored at 0.05) of each checkpoint; `over`: estimate > truth + "
            f"{OVERESTIMATE_MARGIN}; `bias[...]`: mean signed error (estimate − truth) in that friction band. "
            "Sets: " + ", ".join(f"`{n}` = `{p}`" for n, p in sets.items()) + ".", "",
            "Machine: " + ", ".join(f"{k} {v}" for k, v in info.items()), "", "",
        ]
        a.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = a.out.with_suffix(a.out.suffix + ".tmp")
        tmp.write_text("\n".join(head) + table + "\n")
        tmp.replace(a.out)
        print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
