"""The one-command data-set recipe (estimators.datasets): every command parses, seeds are distinct, merges
read collections made before them; a scaled-down run makes the folders and skips them the second time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from estimators import datasets


def test_every_recipe_command_parses_and_seeds_are_distinct(tmp_path: Path) -> None:
    from estimators.collect import _parser

    seen: list[str] = []
    seeds = []
    for entry in datasets.RECIPE:
        module, argv = datasets.command(entry, tmp_path, 2, 1.0)
        if module == "estimators.collect":
            a = _parser().parse_args(argv)
            assert a.seed == entry.seed and a.out == tmp_path / entry.name
            assert sum((a.train, a.val, a.test, a.shifted)) == sum(entry.counts.values()) > 0
            seeds.append(entry.seed)
        else:
            assert set(entry.sources) <= set(seen), entry.name  # sources come earlier in the recipe
        seen.append(entry.name)
    assert len(seeds) == len(set(seeds)) and len(seen) == len(set(seen))
    assert "r8_patch_train" in seen and "estimators_f_big5" in seen
    with pytest.raises(ValueError, match="unknown data set"):
        datasets.select(["nope"])


def test_every_training_set_has_a_validation_split() -> None:
    """estimators.train needs a val split: every merge takes it from its first source, and a collection with
    a training split that is trained on alone (r8_patch_train) has its own."""
    entries = {e.name: e for e in datasets.RECIPE}
    for e in datasets.RECIPE:
        if isinstance(e, datasets.Merge):
            assert entries[e.sources[0]].counts.get("val", 0) > 0, e.name
    assert entries["r8_patch_train"].counts["val"] > 0


def test_scaled_collection_has_one_episode_per_split(tmp_path: Path) -> None:
    entry = datasets.select(["estimators_f"])[0]
    argv = entry.argv(tmp_path, 1, 1e-6)
    assert argv[argv.index("--train") + 1] == "1" and argv[argv.index("--shifted") + 1] == "1"


@pytest.mark.slow
def test_scaled_make_writes_and_resumes(tmp_path: Path) -> None:
    names = ["r8_patch_shiftval", "r7_vlow_shiftval"]
    made = datasets.make(tmp_path, names, workers=1, scale=0.004)
    assert made == ["r7_vlow_shiftval", "r8_patch_shiftval"]  # recipe order
    man = json.loads((tmp_path / "r8_patch_shiftval" / "manifest.json").read_text())
    assert man["seed"] == 41 and man["patch_fraction"] == 1.0 and man["splits"]["shifted"]["episodes_with_patch"] == 2
    assert datasets.make(tmp_path, names, workers=1, scale=0.004) == []  # both exist: skipped
    with pytest.raises(FileNotFoundError, match="sources not made"):
        datasets.make(tmp_path, ["estimators_f_big4"], workers=1, scale=0.004)
