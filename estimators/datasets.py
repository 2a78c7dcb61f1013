"""Every data set the estimator results use, made by one command from fixed seeds
(``python -m estimators.datasets --root DIR``).

Each entry of :data:`RECIPE` is one ``python -m estimators.collect`` or ``python -m estimators.merge`` call
with its seed; the folders land in ``--root`` under the entry's name (the names the READMEs and
``results/estimators*`` commands use). Entries whose folder already holds a ``manifest.json`` are skipped
(a stopped run resumes; ``--force`` remakes them). ``--only NAME ...`` makes some (and the collections the
merges among them read, which must exist or be selected); ``--list`` prints the commands without running
them; ``--scale f`` multiplies every episode count by f (at least 1 episode per non-empty split: quick
checks of the recipe, never a results data set).

The collection filter setting ``F`` of rounds 3-8: 40 % of the episodes with the safety filter in the loop,
its friction the true one x U(0.6, 1.1).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path

F = ("--filter-fraction", "0.4", "--filter-mu-scale", "0.6", "1.1")
SPLITS = ("train", "val", "test", "shifted")


@dataclass(frozen=True)
class Collection:
    """One ``estimators.collect`` call: episode counts per split, the seed and the other arguments."""

    name: str
    seed: int
    counts: dict[str, int]
    args: tuple[str, ...] = F
    used_by: str = ""

    def argv(self, root: Path, workers: int, scale: float) -> list[str]:
        out = ["--out", str(root / self.name), "--seed", str(self.seed), "--workers", str(workers)]
        for split in SPLITS:
            n = self.counts.get(split, 0)
            out += [f"--{split}", str(0 if n == 0 else max(1, math.ceil(n * scale)))]
        return out + list(self.args)


@dataclass(frozen=True)
class Merge:
    """One ``estimators.merge`` call: the training splits of ``sources`` (the first gives val/test/shifted)."""

    name: str
    sources: tuple[str, ...]
    used_by: str = ""
    drop_filtered: tuple[str, ...] = field(default=())

    def argv(self, root: Path) -> list[str]:
        out = ["--out", str(root / self.name), *(str(root / s) for s in self.sources)]
        if self.drop_filtered:
            out += ["--drop-filtered", *(str(root / s) for s in self.drop_filtered)]
        return out


R34 = "training / evaluation (results/estimators/report.md)"
R7 = "per-band targets (results/estimators/targets_offline.md)"
R8 = "surface patches (drops and rises, per-foot labels)"
FR = "--friction-range"
PATCHES = ("--patch-fraction", "1.0")

RECIPE: tuple[Collection | Merge, ...] = (
    Collection("estimators_f", 0, {"train": 800, "val": 150, "test": 150, "shifted": 150}, used_by=R34),
    Collection("estimators_f_extra", 1, {"train": 1600}, used_by=R34),
    Collection("estimators_f_extra2", 2, {"train": 2400}, used_by=R34),
    Collection("estimators_f_corner", 3, {"train": 2400}, ("--plant-beta", "0.4", *F), used_by=R34),
    Collection("estimators_f_corner2", 4, {"train": 1800}, ("--plant-beta", "0.4", *F), used_by=R34),
    Collection("estimators_f_more5", 9, {"train": 2400}, ("--plant-beta", "0.4", *F), used_by=R34),
    Collection("estimators_shiftval", 11, {"shifted": 150}, used_by=R34),
    Merge("estimators_f_big4", ("estimators_f", "estimators_f_extra", "estimators_f_extra2", "estimators_f_corner",
                                "estimators_f_corner2"), used_by="mlp"),
    Merge("estimators_f_big5", ("estimators_f", "estimators_f_extra", "estimators_f_extra2", "estimators_f_corner",
                                "estimators_f_corner2", "estimators_f_more5"), used_by=R34),
    Collection("r7_low_shiftval", 31, {"shifted": 400}, (FR, "0.1", "0.5", *F), used_by=R7),
    Collection("r7_low_test", 32, {"test": 400, "shifted": 400}, (FR, "0.1", "0.5", *F), used_by=R7),
    Collection("r7_mid_shiftval", 33, {"shifted": 200}, (FR, "0.5", "0.8", *F), used_by=R7),
    Collection("r7_mid_test", 34, {"test": 200, "shifted": 200}, (FR, "0.5", "0.8", *F), used_by=R7),
    Collection("r7_vlow_test", 35, {"test": 300, "shifted": 300}, (FR, "0.1", "0.3", *F), used_by=R7),
    Collection("r7_vlow_shiftval", 36, {"shifted": 300}, (FR, "0.1", "0.3", *F), used_by=R7),
    # floors with a strip of other friction across the path (drops and rises, 0.1-1.2)
    # (a val split of its own: the set can be trained on alone; it was missing before)
    Collection("r8_patch_train", 40, {"train": 2400, "val": 300}, ("--patch-fraction", "0.7", *F), used_by=R8),
    Collection("r8_patch_shiftval", 41, {"shifted": 300}, (*PATCHES, *F), used_by=R8),
    Collection("r8_patch_test", 42, {"test": 300, "shifted": 300}, (*PATCHES, *F), used_by=R8),
    Collection("r8_lowpatch_test", 43, {"test": 200, "shifted": 200},
               (FR, "0.1", "0.4", *PATCHES, "--patch-friction", "0.1", "0.4", *F), used_by=R8),
    Merge("r8_train", ("estimators_f", "estimators_f_extra", "estimators_f_extra2", "estimators_f_corner",
                       "estimators_f_corner2", "estimators_f_more5", "r8_patch_train"), used_by=R8),
    # retraining on this machine: the patch episodes beside the first collection (3 200 training
    # episodes; val/test/shifted of estimators_f)
    Merge("r8_train_small", ("estimators_f", "r8_patch_train"), used_by=R8),
)


def select(names: list[str] | None) -> list[Collection | Merge]:
    """The recipe entries named (all when None), in recipe order; ValueError naming an unknown one."""
    known = {e.name for e in RECIPE}
    if names and (bad := sorted(set(names) - known)):
        raise ValueError(f"unknown data set(s) {bad}; known: {sorted(known)}")
    return [e for e in RECIPE if not names or e.name in names]


def command(entry: Collection | Merge, root: Path, workers: int, scale: float) -> tuple[str, list[str]]:
    """(module, argv) of one entry."""
    if isinstance(entry, Collection):
        return "estimators.collect", entry.argv(root, workers, scale)
    return "estimators.merge", entry.argv(root)


def make(root: Path, names: list[str] | None = None, workers: int = 2, scale: float = 1.0,
         force: bool = False, dry_run: bool = False) -> list[str]:
    """Make the selected data sets under ``root``; returns the names made (or, with ``dry_run``, printed)."""
    from estimators import collect, merge

    if not scale > 0:
        raise ValueError(f"scale must be > 0, got {scale!r}")
    made = []
    for entry in select(names):
        module, argv = command(entry, root, workers, scale)
        done = (root / entry.name / "manifest.json").exists()
        if dry_run:
            print(f"python -m {module} {' '.join(argv)}" + ("   # exists" if done else ""))
            made.append(entry.name)
            continue
        if done and not force:
            print(f"{entry.name}: exists, skipped")
            continue
        missing = [s for s in getattr(entry, "sources", ()) if not (root / s / "manifest.json").exists()]
        if missing:
            raise FileNotFoundError(f"merge {entry.name}: sources not made yet: {missing} (under {root})")
        print(f"== {entry.name} ({entry.used_by})", flush=True)
        (collect if module == "estimators.collect" else merge).main(argv)
        made.append(entry.name)
    return made


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", type=Path, default=Path("outputs/data"), help="folder of the data sets")
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME", help="make only these data sets")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scale", type=float, default=1.0, help="x every episode count (recipe checks only)")
    ap.add_argument("--force", action="store_true", help="remake data sets that exist")
    ap.add_argument("--list", action="store_true", help="print the commands, run nothing")
    a = ap.parse_args(argv)
    make(a.root, a.only, a.workers, a.scale, a.force, a.list)


if __name__ == "__main__":
    main()
