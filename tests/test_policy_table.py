"""The policy study's report section on a synthetic sweep frame: the side-by-side table and the target sentences."""

from __future__ import annotations

import pandas as pd
import pytest

from taslel_bench.sweep.policy_table import fisher_p, is_policy_study, policy_section, target_sentences, world_of


def _run(world, controller, variant, *, fell=False, safe=True, distance=4.0, speed=0.5, torque=0.5, trips=0,
         friction=""):  # fmt: skip
    return {"robot": "a1", "scenario": world, "scenario.friction": friction, "controller": controller,
            "filter_variant": variant, "status": "ok", "fell": fell, "safe": safe and not fell,
            "unsafe_reasons": "fell: at 3 s" if fell else "", "distance_m": distance, "mean_speed_mps": speed,
            "intervention_nm_mean": torque, "trips": trips, "tick_us_median": 50.0}


def _frame() -> pd.DataFrame:
    rows = []
    for controller in ("trot", "policy"):
        for variant in ("nominal", "paper", "terrain"):
            rows += [_run("flat", controller, variant, torque=0.0 if variant == "nominal" else 0.6) for _ in range(2)]
            # steps: the terrain filter adds a fall to the trot, nothing to the policy
            fell = controller == "trot" and variant == "terrain"
            rows += [_run("steps", controller, variant, fell=fell), _run("steps", controller, variant)]
            rows += [_run("low_friction", controller, variant, friction="0.3", safe=variant != "nominal")
                     for _ in range(2)]
    return pd.DataFrame(rows)


def test_world_names_carry_the_swept_friction():
    assert list(world_of(_frame()).unique()) == ["flat", "steps", "low_friction 0.3"]


def test_targets_say_met_or_missed_with_the_numbers():
    frame = _frame()
    assert is_policy_study(frame)
    text = "\n".join(target_sentences(frame, "a1"))
    assert "**met**: the policy alone on flat ground: 0 falls in 2 runs, mean forward speed 0.500 m/s" in text
    assert "**met**: minimally invasive, policy + terrain filter on flat ground: mean intervention 0.60 N·m" in text
    assert ("**missed**: do no harm, trot + terrain filter vs trot alone over 3 worlds: worse on steps "
            "(falls 1 vs 0") in text
    assert "**met**: do no harm, policy + terrain filter vs policy alone over 3 worlds: no world worse" in text
    assert ("**met**: helps on slippery ground, policy + terrain filter: unsafe runs vs alone: "
            "low_friction 0.3: 0 vs 2 (p 0.33)") in text  # 0 of 2 against 2 of 2: tables 0 and 2 of C(4,2)=6, 1/3
    assert ("**missed**: helps on rough ground, policy + terrain filter: fewer falls, or fewer trips with no more "
            "falls and no shorter walk, than alone on 0 of 1 worlds") in text


def test_fisher_p_against_hypergeometric_sums():
    """The two-sided p is the sum of the hypergeometric probabilities no larger than the table's: 4 of 10 against 3
    of 10 is 1 (every table is as likely or likelier); 0 of 10 against 5 of 10 is 2 x C(10,5)/C(20,5) = 0.0325."""
    from math import comb

    assert fisher_p(4, 10, 3, 10) == 1.0
    assert fisher_p(0, 10, 5, 10) == pytest.approx(2 * comb(10, 5) / comb(20, 5))


def test_fewer_trips_after_an_earlier_fall_is_no_help():
    rows = [_run("steps", "policy", "nominal", trips=8) for _ in range(2)]
    rows += [_run("steps", "policy", "terrain", trips=1, fell=True) for _ in range(2)]
    text = "\n".join(target_sentences(pd.DataFrame(rows), "a1"))
    assert "**missed**: helps on rough ground, policy + terrain filter" in text


def test_fewer_trips_on_a_shorter_walk_is_no_help():
    """Equal falls, fewer trips, but the filtered runs walked half as far (the filter held the robot back)."""
    rows = [_run("steps", "policy", "nominal", trips=8, fell=True, distance=1.2) for _ in range(2)]
    rows += [_run("steps", "policy", "terrain", trips=1, fell=True, distance=0.6) for _ in range(2)]
    text = "\n".join(target_sentences(pd.DataFrame(rows), "a1"))
    assert "**missed**: helps on rough ground, policy + terrain filter" in text and "(none;" in text
    rows = [_run("steps", "policy", "nominal", trips=8, fell=True, distance=1.2) for _ in range(2)]
    rows += [_run("steps", "policy", "terrain", trips=1, fell=True, distance=1.2) for _ in range(2)]
    text = "\n".join(target_sentences(pd.DataFrame(rows), "a1"))
    assert "than alone on 1 of 1 worlds (steps;" in text


def test_section_has_one_table_per_robot():
    section = policy_section(_frame())
    assert section.count("### a1") == 1 and "| low_friction 0.3 | policy | terrain | 2/2 |" in section
    assert policy_section(_frame().assign(controller="trot")) == ""


def test_every_terrain_preset_gets_its_own_target_sentences():
    """The report judges each terrain-filter column the sweep ran (`terrain`, `release`, `bounded`, `guarded`)."""
    frame = _frame()
    guarded = frame[frame["filter_variant"] == "terrain"].assign(filter_variant="guarded")
    text = "\n".join(target_sentences(pd.concat([frame, guarded], ignore_index=True), "a1"))
    for variant in ("terrain", "guarded"):
        assert f"do no harm, trot + {variant} filter vs trot alone over 3 worlds" in text
        assert f"helps on slippery ground, policy + {variant} filter" in text
    assert "release filter" not in text  # a column the sweep did not run gets no sentence
