"""Merge the training splits of several collections (``python -m estimators.merge --out DIR BASE EXTRA ...``).

The first folder (``BASE``) provides val / test / shifted unchanged (symlinked); the training split is the
concatenation of every folder's ``train.npz`` with episode ids offset so they stay unique. Extra folders
must come from a different collection seed, so their episodes are new draws, never copies of val/test.
``--drop-filtered DIR ...`` keeps only the nominal-controller training episodes of those folders (e.g. a
collection whose filter's mu was tied to the true friction, before training a model that reads the
filter's mu as an input).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from estimators.randomisation import PATCH_COLUMNS

PER_WINDOW = ("X", "y", "window_filtered", "y_foot", "foot_loaded")  # arrays with one row per window
PER_EPISODE = ("params", "fell", "filtered", "filter_mu", "patch")  # arrays with one row per episode


def _nominal_episodes(f: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The arrays of a training split restricted to its nominal-controller episodes, ids renumbered 0..n-1."""
    keep_ep = ~np.asarray(f["filtered"], bool)
    new_id = np.cumsum(keep_ep) - 1
    keep_w = keep_ep[f["episode"]]
    out = {k: f[k] for k in f}
    for k in PER_WINDOW:
        if k in f:
            out[k] = f[k][keep_w]
    out["episode"] = new_id[f["episode"][keep_w]].astype(f["episode"].dtype)
    for k in PER_EPISODE:
        if k in f:
            out[k] = f[k][keep_ep]
    return out


def _check_drop_folders(dirs: list[Path], drop_filtered: list[Path] | None) -> set[Path]:
    """The resolved ``drop_filtered`` folders; ValueError if one of them is not among ``dirs``."""
    drop = {d.resolve() for d in (drop_filtered or [])}
    if unknown := drop - {d.resolve() for d in dirs}:
        raise ValueError(f"--drop-filtered folders {sorted(map(str, unknown))} are not among the merged ones")
    return drop


def _read_manifests(dirs: list[Path]) -> tuple[list[dict], list[int]]:
    """The manifests of ``dirs`` and their collection seeds; ValueError if two collections share a seed."""
    manifests = [json.loads((d / "manifest.json").read_text()) for d in dirs]
    seeds = [m["seed"] for m in manifests]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"collections must have distinct seeds, got {seeds}")
    return manifests, seeds


def _shared_filter_keys(dirs: list[Path]) -> list[str]:
    """The optional per-episode / per-window records (filter flags, per-foot labels, patches) that every
    folder's ``train.npz`` holds."""
    optional = ("filtered", "window_filtered", "filter_mu", "y_foot", "foot_loaded", "patch")
    have = []
    for d in dirs:
        with np.load(d / "train.npz") as f:
            have.append(set(f.files))
    return [k for k in optional if all(k in h for h in have)]


def _load_training(d: Path, drop: set[Path]) -> tuple[dict[str, np.ndarray], dict[str, int] | None]:
    """The arrays of ``d/train.npz`` and, if ``d`` is in ``drop``, restricted to its nominal-controller
    episodes with the counts left out (``{"episodes": ..., "windows": ...}``; None: nothing dropped)."""
    with np.load(d / "train.npz") as fz:
        f = {k: fz[k] for k in fz.files}
    if d.resolve() not in drop:
        return f, None
    if "filtered" not in f:
        raise ValueError(f"{d}/train.npz has no per-episode 'filtered' record to drop by")
    n_ep, n_w = len(f["params"]), len(f["y"])
    f = _nominal_episodes(f)
    return f, {"episodes": n_ep - len(f["params"]), "windows": n_w - len(f["y"])}


def _concatenate_training(dirs: list[Path], drop: set[Path]
                          ) -> tuple[dict[str, np.ndarray], np.ndarray, dict[str, dict[str, int]]]:
    """(merged training arrays, param_columns, dropped counts per folder name): every folder's training
    split in order, episode ids offset by the episodes of the folders before it."""
    parts: dict[str, list[np.ndarray]] = {"X": [], "y": [], "episode": [], "params": [], "fell": []}
    keep = _shared_filter_keys(dirs)
    parts.update({k: [] for k in keep})
    offset = 0
    dropped: dict[str, dict[str, int]] = {}
    for d in dirs:
        f, n_dropped = _load_training(d, drop)
        if n_dropped is not None:
            dropped[str(d)] = n_dropped
        for k in keep:
            parts[k].append(f[k])
        parts["X"].append(f["X"])
        parts["y"].append(f["y"])
        parts["episode"].append(f["episode"] + offset)
        parts["params"].append(f["params"])
        parts["fell"].append(f["fell"])
        cols = f["param_columns"]
        offset += len(f["params"])
    return {k: np.concatenate(v) for k, v in parts.items()}, cols, dropped


def _write_training(out: Path, merged: dict[str, np.ndarray], cols: np.ndarray) -> None:
    """Write ``out/train.npz`` (whole, then renamed into place)."""
    tmp = out / "train.tmp.npz"  # written whole, then renamed: never a half-written train.npz
    extra = {"patch_columns": np.array(PATCH_COLUMNS)} if "patch" in merged else {}
    np.savez_compressed(tmp, **merged, param_columns=cols, **extra)
    tmp.replace(out / "train.npz")


def _link_base_splits(out: Path, base: Path) -> None:
    """Symlink ``out/{val,test,shifted}.npz`` to the base collection's (replacing old links or files)."""
    for split in ("val", "test", "shifted"):
        link = out / f"{split}.npz"
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to((base / f"{split}.npz").resolve())


def _source_records(dirs: list[Path], manifests: list[dict],
                    dropped: dict[str, dict[str, int]]) -> list[dict]:
    """What each collection contributed to the training split (plant draws: uniform or edge-weighted)."""
    return [
        {"dir": str(d), "seed": m["seed"], "train_episodes": m["splits"].get("train", {}).get("episodes", 0),
         "plant_beta": m.get("plant_beta", 1.0), "env_steps_per_s": m["env_steps_per_s"],
         "filter_fraction": m.get("filter_fraction", 0.0), "filter_mu_scale": m.get("filter_mu_scale"),
         "filter_mu_range": m.get("filter_mu_range"),
         "dropped_filtered": dropped.get(str(d), {"episodes": 0, "windows": 0})}
        for d, m in zip(dirs, manifests, strict=True)
    ]


def _merged_train_summary(manifests: list[dict], merged: dict[str, np.ndarray]) -> dict[str, object]:
    """The manifest entry of the merged training split: simulated totals (env steps, filter fallback ticks)
    summed over the collections, episode / window / fall / filter counts from the merged arrays."""
    train = dict(manifests[0]["splits"]["train"])
    for m in manifests[1:]:  # simulated totals (dropped episodes included: they were run)
        for k in ("env_steps", "filter_fallback_ticks"):
            if k in train and k in m["splits"]["train"]:
                train[k] += m["splits"]["train"][k]
    # what the merged split holds, counted from its arrays
    fell = merged["fell"].astype(bool)
    train.update(episodes=len(merged["params"]), windows=len(merged["y"]), episodes_fallen=int(fell.sum()))
    train.pop("fallen_friction", None)
    train.pop("episodes_fallen_without_windows", None)
    if "filtered" in merged:
        filt = merged["filtered"].astype(bool)
        train.update(episodes_filtered=int(filt.sum()), windows_filtered=int(merged["window_filtered"].sum()),
                     episodes_fallen_filtered=int((fell & filt).sum()))
    return train


def _merged_manifest(dirs: list[Path], manifests: list[dict], seeds: list[int],
                     merged: dict[str, np.ndarray], dropped: dict[str, dict[str, int]]) -> dict[str, object]:
    """The base's manifest with the sources, summed env steps / wall time [s] and the merged train split."""
    man = dict(manifests[0])
    man["merged_from"] = [str(d) for d in dirs]
    man["merged_seeds"] = seeds
    man["sources"] = _source_records(dirs, manifests, dropped)
    man["env_steps"] = sum(m["env_steps"] for m in manifests)
    man["wall_time_s"] = sum(m["wall_time_s"] for m in manifests)
    man["env_steps_per_s"] = man["env_steps"] / man["wall_time_s"]
    man["splits"] = {**man["splits"], "train": _merged_train_summary(manifests, merged)}
    return man


def merge(out: Path, base: Path, extras: list[Path], drop_filtered: list[Path] | None = None) -> dict[str, object]:
    """Write ``out/train.npz`` + links to base's other splits + ``manifest.json``; returns the manifest.
    ``drop_filtered``: folders (among base and extras) whose filtered training episodes are left out."""
    dirs = [base, *extras]
    drop = _check_drop_folders(dirs, drop_filtered)
    out.mkdir(parents=True, exist_ok=True)
    manifests, seeds = _read_manifests(dirs)
    merged, cols, dropped = _concatenate_training(dirs, drop)
    _write_training(out, merged, cols)
    _link_base_splits(out, base)
    man = _merged_manifest(dirs, manifests, seeds, merged, dropped)
    tmp_man = out / "manifest.json.tmp"
    tmp_man.write_text(json.dumps(man, indent=2))
    tmp_man.replace(out / "manifest.json")
    return man


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("base", type=Path)
    ap.add_argument("extras", type=Path, nargs="+")
    ap.add_argument("--drop-filtered", type=Path, nargs="+", default=[], metavar="DIR",
                    help="keep only the nominal-controller training episodes of these folders")
    a = ap.parse_args(argv)
    man = merge(a.out, a.base, a.extras, a.drop_filtered)
    print(f"train: {man['splits']['train']['episodes']} episodes, {man['splits']['train']['windows']} windows -> "
          f"{a.out}")


if __name__ == "__main__":
    main()
