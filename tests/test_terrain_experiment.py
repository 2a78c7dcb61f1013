"""+experiment=terrain (the terrain study): the preset composes into the 7 x 3 x 2 x 10 sweep it promises, every
combination validates and builds its scenario, the lossy plant reaches the terrain worlds (and the URDF plant
is untouched), and the report's side-by-side table and target sentences come out of a sweep's rows."""

from __future__ import annotations

import itertools

import mujoco
import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from taslel_bench.config.axes import build_axis
from taslel_bench.config.validate import validate
from taslel_bench.sim.build import build_plant
from taslel_bench.sweep import terrain_table
from tests.conftest import CONF_DIR, compose_cfg

WORLDS = ["flat", "low_friction", "logs", "steps", "rough", "slope", "friction_patch"]


def _sweeper_params() -> dict[str, list[str]]:
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["+experiment=terrain"], return_hydra_config=True)
    return {k: str(v).split(",") for k, v in cfg.hydra.sweeper.params.items()}


def test_sweep_axes_are_the_issue_28_grid():
    params = _sweeper_params()
    assert params["scenario"] == WORLDS
    assert params["+filter_variant"] == ["nominal", "paper", "terrain"]
    assert params["+mismatch_plant"] == ["none", "lossy"]
    assert params["seed"] == [str(s) for s in range(10)]
    assert np.prod([len(v) for v in params.values()]) == 420


def test_every_combination_composes_validates_and_builds_its_scenario():
    params = _sweeper_params()
    keys = [k for k in params if k != "seed"]
    for values in itertools.product(*(params[k] for k in keys)):
        overrides = ["+experiment=terrain", *(f"{k}={v}" for k, v in zip(keys, values, strict=True))]
        cfg = compose_cfg(overrides)
        validate(cfg)
        scenario = build_axis(cfg, "scenario")
        assert scenario.name == cfg.scenario.name
        variant = dict(zip(keys, values, strict=True))["+filter_variant"]
        assert bool(cfg.filter.enabled) == (variant != "nominal"), overrides
        assert (cfg.filter.get("friction_cone") == "terrain") == (variant == "terrain"), overrides


def test_paper_variant_is_the_paper_filter_unchanged():
    paper = compose_cfg(["+experiment=terrain", "+filter_variant=paper"]).filter
    default = compose_cfg([]).filter  # filter=id_cbf_qp
    assert paper == default


def _joint_damping(model: mujoco.MjModel) -> np.ndarray:
    return model.dof_damping[6:].copy()


@pytest.mark.parametrize("world", ["logs", "rough"])
def test_lossy_plant_reaches_terrain_worlds_and_none_leaves_the_plant_as_is(world):
    def plant(extra):
        cfg = compose_cfg([f"scenario={world}", *extra])
        return build_plant(build_axis(cfg, "scenario"))

    bare, none, lossy = plant([]), plant(["+mismatch_plant=none"]), plant(["+mismatch_plant=lossy"])
    assert np.allclose(_joint_damping(lossy), 1.5) and np.allclose(lossy.dof_frictionloss[6:], 0.2)
    assert np.allclose(lossy.dof_armature[6:], 0.01)
    for field in ("dof_damping", "dof_frictionloss", "dof_armature", "body_mass", "body_ipos", "body_inertia",
                  "geom_size", "geom_pos", "hfield_data"):
        assert np.array_equal(getattr(bare, field), getattr(none, field)), field


def test_unknown_plant_field_on_a_terrain_world_is_a_clear_error():
    cfg = compose_cfg(["scenario=steps", "+scenario.joint_dampin=1.0"])
    with pytest.raises(Exception, match="scenario.joint_dampin"):
        build_axis(cfg, "scenario")


def _row(world, variant, plant="none", **metrics):
    base = {"scenario": world, "filter_variant": variant, "mismatch_plant": plant, "status": "ok", "fell": False,
            "safe": True, "unsafe_reasons": "", "trips": 0, "distance_m": 3.0, "grf_mae_z_n": 1.5,
            "sliding_distance_m": 1.0, "friction_cone_edge_rate": 0.02, "touchdown_slip_mps_mean": 0.3,
            "tick_us_median": 100.0, "tick_filter_us_median": 50.0, "filter_relaxed_ticks": 0, "duration_s": 10.0,
            "solver": "daqp", "filter_enabled": variant != "nominal"}  # fmt: skip
    return {**base, **metrics}


def _sweep(**terrain_metrics) -> pd.DataFrame:
    rows = []
    for world, plant in itertools.product(WORLDS, ("none", "lossy")):
        rows.append(_row(world, "nominal", plant, sliding_distance_m=3.0, touchdown_slip_mps_mean=0.5,
                         tick_us_median=30.0, tick_filter_us_median=0.0))
        rows.append(_row(world, "paper", plant, fell=world == "logs", safe=world != "logs",
                         unsafe_reasons="fell: trunk too low" if world == "logs" else ""))
        rows.append(_row(world, "terrain", plant, **terrain_metrics))
    rows.append({**_row("rough", "terrain"), "status": "error", "message": "killed"})  # a crashed run is counted
    return pd.DataFrame(rows)


def test_table_shows_three_controllers_per_world_and_plant():
    frame = _sweep()
    table = terrain_table.comparison_table(frame, "none")
    assert list(table["world"].unique()) == WORLDS
    assert (table.groupby("world")["controller"].apply(list) == [["nominal", "paper", "terrain"]] * 7).all()
    rough = table[(table["world"] == "rough") & (table["controller"] == "terrain")].iloc[0]
    assert rough["runs"] == "1/2"  # the error row is not dropped
    logs_paper = table[(table["world"] == "logs") & (table["controller"] == "paper")].iloc[0]
    assert logs_paper["falls"] == "1/1" and logs_paper["unsafe"].startswith("1/1 (")
    section = terrain_table.terrain_section(frame)
    assert "### URDF plant" in section and "### lossy plant" in section


def test_target_sentences_say_met_with_numbers():
    sentences = terrain_table.target_sentences(_sweep())
    assert len(sentences) == 7  # logs, steps, rough, slope, flat GRF, mu = 0.2, cost
    assert all(": met" in s for s in sentences), sentences
    assert "sliding 1 m = 33.3 % of nominal 3 m" in sentences[5]


def test_target_sentences_say_missed_when_a_number_misses():
    sentences = terrain_table.target_sentences(_sweep(trips=2, grf_mae_z_n=2.5, friction_cone_edge_rate=0.06,
                                                      tick_us_median=250.0))
    assert all("missed" in s for s in sentences), sentences
    assert "missed (cone edge)" in sentences[5]
    assert "2.50x" in sentences[6]


def test_trip_target_sentences_read_the_trips_with_the_worst_run_and_the_early_touchdowns_beside():
    """The verdict's trips with their mean, largest run and met or missed; the early touchdowns (no trips) beside
    them where the sweep has the key."""
    frame = _sweep(trips=20, touchdowns_early=12, touchdowns_early_beyond_20ms=0.5)
    extra = _row("logs", "terrain", trips=22, touchdowns_early=10, touchdowns_early_beyond_20ms=1.5)
    sentence = terrain_table.target_sentences(pd.concat([frame, pd.DataFrame([extra])]))[0]
    assert sentence.startswith("**logs**") and ": missed: falls 0/2, 3 m;" in sentence, sentence
    assert "trips 21 (at most 22): missed" in sentence, sentence
    assert "early touchdowns (walkable landings in the second half of the swing, no trips) 11 per run, 1 more" \
        in sentence, sentence
    extra = _row("logs", "terrain", trips=2)
    frame = _sweep(trips=0)
    sentence = terrain_table.target_sentences(pd.concat([frame, pd.DataFrame([extra])]))[0]
    assert "trips 1 (at most 2): met on average, not in every run (1 of 2 over)" in sentence, sentence
    assert "early touchdowns" not in sentence
    ok = terrain_table.target_sentences(_sweep(trips=1))[0]
    assert ": met: falls 0/1" in ok and "trips 1 (at most 1): met" in ok, ok


def test_urdf_plant_runs_keep_the_paper_claims_on_one_plant():
    frame = _sweep()
    kept = terrain_table.urdf_plant_runs(frame)
    assert set(kept["mismatch_plant"]) == {"none"} and len(kept) == len(WORLDS) * 3 + 1
