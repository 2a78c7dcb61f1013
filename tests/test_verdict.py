"""The run's verdict (``safe``, ``unsafe_reasons``) beside its health, and the definitions it rests on: contacts
judged in their own frame, trips and strikes from contact onsets, rates over the worst 0.5 s window."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from taslel_bench.config.validate import validate
from taslel_bench.interfaces import OVERESTIMATE_MARGIN
from taslel_bench.metrics.clearance import clearance_metrics, onsets
from taslel_bench.metrics.contacts import contact_metrics
from taslel_bench.metrics.health import HealthLimits, assess
from taslel_bench.metrics.summary import estimator_safety_metrics
from taslel_bench.metrics.verdict import SafetyLimits, judge, reason_tags
from taslel_bench.metrics.windows import worst_window_rate
from taslel_bench.sim.run import run
from taslel_bench.util.fields import ConfigError
from tests.conftest import compose_cfg
from tests.test_metrics import clear_contact, set_contact, synthetic_trace

DT = 1e-3  # [s]


def test_a_fall_with_trips_is_unsafe_with_the_filter_off_while_the_status_stays_ok(tmp_path):
    """Nominal trot into the logs (seed 0 falls on a log): the harness worked (`ok`), the robot did not."""
    cfg = compose_cfg(["scenario=logs", "filter.enabled=false", "duration=7", "progress=false",
                       "record.mcap=false", "seed=0"])
    summary = run(cfg, tmp_path, {"scenario": "logs"})
    assert summary["fell"] is True and summary["trips"] > 0
    assert summary["status"] == "ok"
    assert summary["safe"] is False
    assert {"fell", "tripped"} <= set(reason_tags(summary["unsafe_reasons"]))


def test_a_trip_alone_makes_a_run_unsafe_and_the_same_rules_hold_with_the_filter_on_or_off():
    for filter_on in (False, True):
        tr = synthetic_trace(filter_on=filter_on, n=40)
        tr.obstacle_clearance_m[:] = 0.05
        tr.in_stance[:, 1] = False
        clear_contact(tr, slice(None), 1)
        set_contact(tr, [20, 21], 1, 5.0, obstacle=True)  # a swing foot hits a log
        summary = {"status": "ok", "fell": False, **clearance_metrics(tr, 0, DT), **contact_metrics(tr, 0, DT, 0.2)}
        safe, why = judge(summary, SafetyLimits())
        assert (safe, reason_tags(why)) == (False, ["tripped"]), filter_on
    assert judge({"status": "ok", "fell": False, "trips": 0}, SafetyLimits()) == (True, "")
    assert judge({"status": "error"}, SafetyLimits())[0] is False


def test_a_foot_pressing_on_a_log_flank_is_loaded_and_judged_in_its_contact_frame():
    """80 N along a normal 80 deg from vertical (< 14 N vertical), |f_t| at 0.98 mu f_n: loaded, at the cone
    edge in its frame; world-z judging would call its ratio |f_xy| / f_z > 1 or drop it."""
    tr = synthetic_trace(n=20)
    normal = np.array([-np.sin(np.radians(80)), 0.0, np.cos(np.radians(80))])
    set_contact(tr, slice(None), 0, 80.0, ft=0.98 * 0.5 * 80.0, mu=0.5, normal=normal)
    tr.grf_plant_w[:, 0] = 80.0 * normal  # the world force: 13.9 N vertical
    m = contact_metrics(tr, 0, DT, 0.2)
    assert m["contacts_loaded_flank"] == 20
    assert m["friction_cone_edge_rate"] == pytest.approx(0.25)  # foot 0 of 4 loaded feet, every tick
    assert m["friction_cone_edge_rate_worst_window"] == pytest.approx(0.25)
    # at 0.9 mu it is not at the edge, whatever its world-axes ratio
    set_contact(tr, slice(None), 0, 80.0, ft=0.9 * 0.5 * 80.0, mu=0.5, normal=normal)
    assert contact_metrics(tr, 0, DT, 0.2)["friction_cone_edge_rate"] == 0.0
    # nearly horizontal: 82 N normal, < 1 N vertical, still loaded
    flat_on = np.array([-1.0, 0.0, 0.01])
    set_contact(tr, slice(None), 0, 82.0, normal=flat_on)
    assert contact_metrics(tr, 0, DT, 0.2)["contacts_loaded_flank"] == 20


def test_a_lift_off_from_a_log_is_not_a_trip_and_a_stance_strike_is_counted():
    tr = synthetic_trace(n=60)
    tr.obstacle_clearance_m[:] = 0.05
    # foot 0 stands on a log (ticks 0-29), lifts off at 20: contact continues 3 ticks into swing, at 0 N
    clear_contact(tr, slice(None), 0)
    set_contact(tr, slice(0, 20), 0, 50.0, obstacle=True)
    set_contact(tr, slice(20, 23), 0, 0.0, obstacle=True)
    tr.in_stance[20:, 0] = False
    # ... flickers back for one tick 2 ms later (the same contact), then swings free
    set_contact(tr, [25], 0, 0.0, obstacle=True)
    # foot 2 in stance on the floor is struck by a log's flank at tick 40 (a new contact 60 deg from vertical)
    set_contact(tr, slice(40, 45), 2, 30.0, normal=(-np.sin(np.radians(60)), 0.0, 0.5), obstacle=True, slot=1)
    m = clearance_metrics(tr, 0, DT)
    assert m["foot_trips"] == 0 and m["trips"] == 0
    assert m["stance_flank_strikes"] == 1 and m["stance_obstacle_contacts"] == 1
    # the same foot hitting a log 15 ms after it left it is a trip
    set_contact(tr, slice(40, 42), 0, 5.0, obstacle=True)
    assert clearance_metrics(tr, 0, DT)["foot_trips"] == 1


def test_onsets_need_the_rearm_gap():
    mask = np.array([1, 1, 0, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 1], bool)
    np.testing.assert_array_equal(np.flatnonzero(onsets(mask, 1)), [3, 7, 15])
    np.testing.assert_array_equal(np.flatnonzero(onsets(mask, 3)), [7, 15])


def test_a_local_beyond_cone_episode_crosses_the_windowed_limit():
    """10 s walk, the filter plans forces beyond the true cone on 6.25 % of loaded feet during 1.3 s (the front
    feet on a new surface): pooled 0.81 %, under the 1 % limit; the worst 0.5 s window is 6.25 %."""
    n = 10_000
    tr = synthetic_trace(n=n)
    ticks = np.arange(3000, 4300)
    tr.grf_filter_w[ticks[::4], 0, 0] = 60.0  # |lambda_t| = 60 N > mu lambda_n = 50 N on 1 of 16 foot-ticks
    m = contact_metrics(tr, 0, DT, 0.2)
    assert m["filter_demand_beyond_cone_rate"] == pytest.approx(325 / 40_000)
    assert m["filter_demand_beyond_cone_rate"] < 0.01
    assert m["filter_demand_beyond_cone_rate_worst_window"] == pytest.approx(1 / 16, rel=0.01)
    status, why = assess({"status": "ok", **m}, HealthLimits())
    assert status == "degraded" and "filter_demand_beyond_cone_rate_worst_window" in why
    safe, reasons = judge({"status": "ok", "fell": False, **m}, SafetyLimits())
    assert not safe and reason_tags(reasons) == ["beyond_cone"]


def test_worst_window_rate():
    bad = np.zeros(100)
    judged = np.ones(100)
    bad[10:15] = 1
    assert worst_window_rate(bad, judged, 10) == pytest.approx(0.5)
    assert worst_window_rate(bad, judged, 1000) == pytest.approx(0.05)  # shorter than a window: one window
    assert np.isnan(worst_window_rate(bad, np.zeros(100), 10))


def test_one_over_estimation_predicate_at_the_boundary():
    """mu_hat = mu + margin exactly is not over-estimation, in every rate that uses the predicate."""
    mu = np.full(100, 0.2)
    mu_hat = mu + OVERESTIMATE_MARGIN
    m = estimator_safety_metrics(np.arange(100) * DT, mu, mu_hat, np.ones(100, bool))
    assert m["estimator_low_overestimate_rate"] == 0.0 and m["estimator_ready_overestimate_rate"] == 0.0
    m = estimator_safety_metrics(np.arange(100) * DT, mu, mu_hat + 1e-9, np.ones(100, bool))
    assert m["estimator_low_overestimate_rate"] == 1.0


@pytest.mark.parametrize("override, field", [("safety.trips_max=-1", "safety.trips_max=-1"),
                                             ("safety.cone_edge_rate_worst_window_max=1.5",
                                              "safety.cone_edge_rate_worst_window_max=1.5"),
                                             ("+safety.falls_max=0", "safety.falls_max=0: unknown key")])
def test_a_bad_safety_limit_is_refused_before_simulation(override, field):
    with pytest.raises(ConfigError) as err:
        validate(compose_cfg([override]))
    assert field in str(err.value)


def _fake_runs() -> pd.DataFrame:
    """Finished obstacle runs: nominal ones (unsafe: clearance) and filter-on ones with the ECBF on (safe) or
    off (unsafe), as a sweep over filter.ecbf.enabled=true,false leaves them."""
    import pandas as pd

    rows = []
    for seed in range(2):
        rows.append(dict(scenario="obstacle", filter_enabled=False, seed=seed, status="ok", fell=False,
                         clearance_violation_rate=0.8, safe=False, unsafe_reasons="clearance: x=0.8 > 0.05 (...)",
                         **{"filter.ecbf.enabled": ""}))
        for ecbf, rate in (("true", 0.001), ("false", 0.7)):
            rows.append(dict(scenario="obstacle", filter_enabled=True, seed=seed, status="ok", fell=False,
                             clearance_violation_rate=rate, safe=rate < 0.05,
                             unsafe_reasons="" if rate < 0.05 else "clearance: x=0.7 > 0.05 (...)",
                             **{"filter.ecbf.enabled": ecbf}))
    return pd.DataFrame(rows)


def test_claims_are_split_by_every_filter_override_and_state_the_verdicts():
    from taslel_bench.sweep.claims import paper_claims

    text = paper_claims(_fake_runs())
    assert "Filter-on runs split by `filter.ecbf.enabled`" in text
    assert "### Filter setting `filter.ecbf.enabled=true`" in text
    ecbf_off = text.split("### Filter setting `filter.ecbf.enabled=false`")[1].split("### Filter setting")[0]
    assert "Violation rate 0.8 -> 0.7 of swing ticks" in ecbf_off  # the ECBF-off runs alone, not pooled
    assert "Violation rate 0.8 -> 0.001 of swing ticks" in text
    assert "obstacle: 2/2 (clearance 2) nominal vs 0/2 filtered" in text
    assert "obstacle: 2/2 (clearance 2) nominal vs 2/2 (clearance 2) filtered" in text


def test_the_verdict_table_counts_unsafe_runs_and_reasons_per_group():
    from taslel_bench.sweep.verdict_table import verdict_table

    table = verdict_table(_fake_runs(), ["scenario", "filter_enabled", "filter.ecbf.enabled"])
    got = {(r["filter_enabled"], r["filter.ecbf.enabled"]): (r["unsafe"], r["clearance"], r["fell"])
           for _, r in table.iterrows()}
    assert got == {(False, ""): ("2/2", 2, 0), (True, "false"): ("2/2", 2, 0), (True, "true"): ("0/2", 0, 0)}


def test_the_first_trip_time_is_the_first_counted_onset():
    tr = synthetic_trace(n=60)
    tr.t_s[:60] = np.arange(60) * DT
    tr.obstacle_clearance_m[:] = 0.05
    clear_contact(tr, slice(None), 0)
    set_contact(tr, slice(0, 23), 0, 50.0, obstacle=True)  # lift-off from a log at 20: not a trip
    tr.in_stance[20:, 0] = False
    set_contact(tr, slice(40, 42), 0, 5.0, obstacle=True)  # a trip at 40 ms
    m = clearance_metrics(tr, 0, DT)
    assert m["trips"] == 1 and m["first_trip_s"] == pytest.approx(0.040)


def test_barrier_negative_rate_has_a_worst_window_too():
    tr = synthetic_trace(n=2000)
    tr.in_stance[:, 0] = False
    tr.barriers["clearance"].h_m[:2000, 0] = 0.01
    tr.barriers["clearance"].h_m[100:150, 0] = -0.01  # 50 ms of h < 0 in 2 s of swing
    m = clearance_metrics(tr, 0, DT)
    assert m["barrier_negative_rate"] == pytest.approx(50 / 2000)
    assert m["barrier_negative_rate_worst_window"] == pytest.approx(50 / 500)


def test_reasons_are_values_and_the_summary_keeps_their_tags():
    """The verdict's reasons are typed (tag, key, measured, limit); the text and the tags in the summary come from
    them, and the report counts the tags without parsing the text (older summaries: from the text)."""
    from taslel_bench.metrics.verdict import Reason, reason_tags, reasons

    summary = {"status": "ok", "fell": True, "time_to_fall_s": 3.25, "fall_reason": "trunk height", "trips": 2,
               "friction_cone_edge_rate_worst_window": 0.5}
    found = reasons(summary, SafetyLimits())
    assert [r.tag for r in found] == ["fell", "tripped", "cone_edge"]
    assert found[1] == Reason("tripped", "trips", 2.0, 0.0, found[1].meaning)
    assert found[2].measured == 0.5 and found[2].limit == SafetyLimits().cone_edge_rate_worst_window_max
    assert judge(summary, SafetyLimits())[1] == "; ".join(r.text for r in found)
    assert reason_tags("ignored: text", "fell,tripped") == ["fell", "tripped"]
    assert reason_tags(judge(summary, SafetyLimits())[1]) == ["fell", "tripped", "cone_edge"]


def test_the_summary_is_typed_sections_flattened_once_with_reasons_as_values():
    """summary_sections keeps each key in one section and the reasons as values; summary.json is its flat dict."""
    from taslel_bench.metrics.sections import SECTIONS, RunSummary, Verdict
    from taslel_bench.metrics.summary import summarize, summary_sections
    from taslel_bench.metrics.verdict import Reason
    from taslel_bench.sim.build import Built

    built = Built(compose_cfg(["scenario=logs", "filter.enabled=false", "duration=3", "seed=0"]))
    res = built.episode.run()  # the nominal trot on the logs: trips (and a fall) to judge
    stand_s = built.controller.stand_duration_s
    sections = summary_sections(res, DT, stand_s)
    flat = sections.flat()
    assert flat.keys() == summarize(res, DT, stand_s).keys()
    counts = {}
    for name in SECTIONS:
        for key in sections.section(name):
            counts[key] = counts.get(key, 0) + (name != "verdict" or key != "status")
    assert set(counts) == set(flat) and set(counts.values()) == {1}  # every key in one section (status: outcome)
    assert all(isinstance(r, Reason) for r in sections.verdict.reasons) and "tripped" in flat["unsafe_reason_tags"]
    assert [r.tag for r in sections.verdict.reasons] == flat["unsafe_reason_tags"].split(",")
    assert "trips" in sections.contacts and "qp_solves" in sections.filter and "mean_speed_mps" in sections.locomotion
    clash = RunSummary({"status": "ok"}, Verdict("ok", "", []), locomotion={"status": "walking"})
    with pytest.raises(ValueError, match="two sections"):
        clash.flat()
    with pytest.raises(KeyError, match="sections"):
        clash.section("speed")
