"""Per-foot checkpoints on collected window sets, each foot against the friction under it
(``python -m studies.estimator_per_foot_offline CKPT ... --set NAME=PATH.npz ... [--out FILE.md]``).

For every checkpoint and set: the MAE [-] of the raw mean per foot against ``y_foot`` (all feet pooled; the
number comparable to the paper's 0.072 on a constant-friction test split, where every foot stands on the
trunk's friction), the same on loaded feet only (``foot_loaded``), the over-estimation rate (estimate >
truth + 0.05) of the raw mean and of the lower-quantile head per foot, and the MAE and over-estimation rate
of the lowest foot's mean (and lower head) against the trunk label ``y`` (what a single-cone filter would be
given; for a model with one output per window, that output: the per-window scores). A checkpoint with one
output per window is scored with that output for every foot.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np
import torch

from estimators.checkpoint import load_checkpoint
from estimators.data import load_foot_labels, load_windows
from studies.estimator_evaluate import markdown_table, predict_all
from taslel_bench.interfaces import overestimates
from taslel_bench.util.machine import machine_info


def per_foot(a: np.ndarray | None, n: int) -> np.ndarray | None:
    """(N, 4): a per-foot output as is, a single output repeated for the four feet."""
    if a is None:
        return None
    return a.reshape(n, -1) if a.size == 4 * n else np.repeat(a.reshape(n, 1), 4, axis=1)


def score(mean: np.ndarray, lower: np.ndarray | None, y_foot: np.ndarray, loaded: np.ndarray,
          y: np.ndarray) -> dict[str, float]:
    """Per-foot scores of (N, 4) estimates against (N, 4) labels (see the module doc)."""
    err = np.abs(mean - y_foot)
    out = {"windows": float(len(y)), "mae_foot": float(err.mean()),
           "mae_loaded": float(err[loaded].mean()) if loaded.any() else float("nan"),
           "over_mean": float(overestimates(mean, y_foot).mean()),
           "over_lower": float(overestimates(lower, y_foot).mean()) if lower is not None else float("nan"),
           "mae_lowest_vs_trunk": float(np.abs(mean.min(1) - y).mean()),
           "over_lowest_vs_trunk": float(overestimates(mean.min(1), y).mean()),
           "over_lower_lowest_vs_trunk": (float(overestimates(lower.min(1), y).mean()) if lower is not None
                                          else float("nan"))}
    return out


def evaluate(ckpt: str, path: Path) -> dict[str, float]:
    model, _ = load_checkpoint(ckpt)
    model.eval()
    X, y, _, _ = load_windows(path, filter_mu=bool(getattr(model.cfg, "filter_mu_input", False)))
    y_foot = load_foot_labels(path)
    with np.load(path) as f:
        loaded = f["foot_loaded"].astype(bool) if "foot_loaded" in f.files else np.ones_like(y_foot, bool)
    with torch.no_grad():
        mean, _, lower = predict_all(model, X)
    return score(per_foot(mean, len(y)), per_foot(lower, len(y)), y_foot, loaded, y)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoints", nargs="+", help="shipped names or paths without suffix")
    ap.add_argument("--set", action="append", required=True, metavar="NAME=PATH.npz")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None, help="the rows as a JSON list")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    sets = dict(s.split("=", 1) for s in a.set)
    rows = []
    for ck in a.checkpoints:
        for name, p in sets.items():
            r = evaluate(ck, Path(p))
            rows.append({"checkpoint": Path(ck).name, "set": name, **r})
            print(rows[-1], flush=True)
    if a.json is not None:
        import json

        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(rows, indent=1))
    if a.out is not None:
        import pandas as pd

        cmd = "python -m studies.estimator_per_foot_offline " + " ".join(shlex.quote(x) for x in sys.argv[1:])
        text = (f"# Per-foot estimates on window sets\n\n{markdown_table(pd.DataFrame(rows))}\n\n"
                f"Command: `{cmd}`\n\nMachine: {machine_info()}\n")
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)


if __name__ == "__main__":
    main()
