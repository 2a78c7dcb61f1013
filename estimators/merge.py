"""Merge the training splits of several collections (``python -m estimators.merge --out DIR BASE EXTRA ...``).

The first folder (``BASE``) provides val / test / shifted unchanged (symlinked); the training split is the
concatenation of every folder's ``train.npz`` with episode ids offset so they stay unique. Extra folders
must come from a different collection seed, so their episodes are new draws, never copies of val/test.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def merge(out: Path, base: Path, extras: list[Path]) -> dict[str, object]:
    """Write ``out/train.npz`` + links to base's other splits + ``manifest.json``; returns the manifest."""
    out.mkdir(parents=True, exist_ok=True)
    manifests = [json.loads((d / "manifest.json").read_text()) for d in [base, *extras]]
    seeds = [m["seed"] for m in manifests]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"collections must have distinct seeds, got {seeds}")
    parts: dict[str, list[np.ndarray]] = {"X": [], "y": [], "episode": [], "params": [], "fell": []}
    optional = ("filtered", "window_filtered", "filter_mu")  # per-episode / per-window filter flags
    have = []
    for d in [base, *extras]:
        with np.load(d / "train.npz") as f:
            have.append(set(f.files))
    keep = [k for k in optional if all(k in h for h in have)]
    parts.update({k: [] for k in keep})
    offset = 0
    for d in [base, *extras]:
        with np.load(d / "train.npz") as f:
            for k in keep:
                parts[k].append(f[k])
            parts["X"].append(f["X"])
            parts["y"].append(f["y"])
            parts["episode"].append(f["episode"] + offset)
            parts["params"].append(f["params"])
            parts["fell"].append(f["fell"])
            cols = f["param_columns"]
            offset += len(f["params"])
    np.savez_compressed(out / "train.npz", **{k: np.concatenate(v) for k, v in parts.items()}, param_columns=cols)
    for split in ("val", "test", "shifted"):
        link = out / f"{split}.npz"
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to((base / f"{split}.npz").resolve())
    man = dict(manifests[0])
    man["merged_from"] = [str(d) for d in [base, *extras]]
    man["merged_seeds"] = seeds
    # what each collection contributed to the training split (plant draws: uniform or edge-weighted)
    man["sources"] = [
        {"dir": str(d), "seed": m["seed"], "train_episodes": m["splits"].get("train", {}).get("episodes", 0),
         "plant_beta": m.get("plant_beta", 1.0), "env_steps_per_s": m["env_steps_per_s"]}
        for d, m in zip([base, *extras], manifests)
    ]
    man["env_steps"] = sum(m["env_steps"] for m in manifests)
    man["wall_time_s"] = sum(m["wall_time_s"] for m in manifests)
    man["env_steps_per_s"] = man["env_steps"] / man["wall_time_s"]
    train = dict(man["splits"]["train"])
    for m in manifests[1:]:
        for k in ("episodes", "windows", "episodes_fallen", "env_steps", "episodes_filtered", "windows_filtered",
                  "episodes_fallen_filtered", "filter_fallback_ticks"):
            if k in train and k in m["splits"]["train"]:
                train[k] += m["splits"]["train"][k]
    man["splits"] = {**man["splits"], "train": train}
    (out / "manifest.json").write_text(json.dumps(man, indent=2))
    return man


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("base", type=Path)
    ap.add_argument("extras", type=Path, nargs="+")
    a = ap.parse_args(argv)
    man = merge(a.out, a.base, a.extras)
    print(f"train: {man['splits']['train']['episodes']} episodes, {man['splits']['train']['windows']} windows -> {a.out}")


if __name__ == "__main__":
    main()
