"""The episode in chunks (record.chunk_ticks): the same summary and steps.parquet whatever the chunk size,
the trace holds one chunk, steps.parquet never half-written under its name, long runs accepted."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from pandas.testing import assert_frame_equal

from taslel_bench.config.validate import ConfigError, memory_estimate_gb, validate
from taslel_bench.metrics.stream import ExactSum, Onsets, Reducer, Touchdowns
from taslel_bench.metrics.windows import worst_window_rate
from taslel_bench.record.steps_writer import StepsWriter
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg

# measured on the machine's clock, not by the physics: they differ between any two runs
TIMING = ("wall_time_s", "real_time_factor", "warmup_s", "recording_s", "reference_s", "residuals_s",
          "memory_peak_gb", "result_files", "tick_us_median", "tick_us_p99", "qp_solve_us_median",
          "qp_solve_us_p99", "qp_solve_us_max", "qp_build_us_median", "qp_deadline_miss_rate",
          "qp_solve_over_1ms_rate", "git_dirty", "memory_estimate_gb")  # the estimate depends on the chunk size


def _timing(key: str) -> bool:
    return key in TIMING or (key.startswith("tick_") and key.endswith("_us_median")) or key.startswith("machine_")


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


@pytest.mark.parametrize("scenario", ["obstacle", "low_friction"])
def test_chunk_size_changes_no_summary_number_and_no_step(tmp_path, scenario):
    over = [f"scenario={scenario}", "duration=1.2", "progress=false", "record.mcap=true"]
    whole = run(compose_cfg([*over, "record.chunk_ticks=null"]), tmp_path / "whole")
    chunked = run(compose_cfg([*over, "record.chunk_ticks=300"]), tmp_path / "chunked")
    assert whole["status"] != "error" and whole["ticks"] > 4 * 300
    keys = set(whole) | set(chunked)
    differ = [k for k in sorted(keys) if not _timing(k) and not _same(whole.get(k), chunked.get(k))]
    assert differ == [], {k: (whole.get(k), chunked.get(k)) for k in differ}
    assert len(keys) > 150
    steps = [pd.read_parquet(tmp_path / d / "steps.parquet") for d in ("whole", "chunked")]
    assert list(steps[0].columns) == list(steps[1].columns) and len(steps[0]) == whole["ticks"]
    for col in steps[0].columns:
        if not col.startswith("tick_") and col not in ("qp_solve_us", "qp_solve_cpu_us", "qp_build_us"):
            assert np.array_equal(steps[0][col].to_numpy(), steps[1][col].to_numpy(), equal_nan=True), col
    events = [json.loads((tmp_path / d / "events.json").read_text()) for d in ("whole", "chunked")]
    assert events[0] == events[1]


def test_exact_sum_does_not_depend_on_the_grouping():
    rng = np.random.default_rng(1)
    x = rng.normal(size=20_000) * 10.0 ** rng.integers(-12, 12, 20_000)
    whole, parts = ExactSum(), ExactSum()
    whole.add(x)
    for part in np.array_split(x, 29):
        parts.add(part)
    exact = float(sum(map(Fraction, x.tolist())) / x.size)  # the mean, rounded once
    assert whole.divided(x.size) == parts.divided(x.size) == exact
    with_nan = ExactSum()
    with_nan.add(np.array([1.0, np.nan]))
    assert math.isnan(with_nan.divided(2))


def test_window_onsets_and_touchdowns_carried_across_chunks():
    rng = np.random.default_rng(2)
    bad, judged = rng.random((900, 4)) < 0.1, rng.random((900, 4)) < 0.8
    mask = rng.random((900, 4)) < 0.3
    acc = Reducer()
    onsets, touchdowns = Onsets(3), Touchdowns(5)
    got_on, got_td = [], []
    for a, b in ((0, 7), (7, 300), (300, 301), (301, 900)):
        acc.window("w", bad[a:b] & judged[a:b], judged[a:b], 250)
        got_on.append(onsets(mask[a:b]))
        got_td.append(touchdowns(mask[a:b]))
    assert acc.result()["w"] == worst_window_rate(bad & judged, judged, 250)
    assert np.array_equal(np.concatenate(got_on), Onsets(3)(mask))
    assert np.array_equal(np.concatenate(got_td), Touchdowns(5)(mask))
    short = Reducer()  # shorter than the window: one window
    short.window("w", bad[:100] & judged[:100], judged[:100], 250)
    assert short.result()["w"] == worst_window_rate(bad[:100] & judged[:100], judged[:100], 250)


def test_steps_writer_never_leaves_a_half_written_table_under_its_name(tmp_path):
    writer = StepsWriter(tmp_path / "steps.parquet")
    writer.append(pd.DataFrame({"t_s": [0.0, 0.001]}))
    assert not (tmp_path / "steps.parquet").exists() and writer.tmp.exists()  # a kill now leaves the temp file
    writer.append(pd.DataFrame({"t_s": [0.002]}))
    writer.finish()
    assert pd.read_parquet(tmp_path / "steps.parquet")["t_s"].tolist() == [0.0, 0.001, 0.002]
    assert not writer.tmp.exists()


def test_steps_writer_buffers_chunks_into_row_groups_of_the_set_size(tmp_path):
    """Row groups of at least ``row_group_bytes`` (the writer's memory grows per row group, not per row);
    the rows and their order are those appended, whatever the grouping."""
    frames = [pd.DataFrame({"t_s": np.arange(k, k + 100) * 1e-3, "x": np.arange(k, k + 100, dtype=float)})
              for k in range(0, 1000, 100)]  # 10 chunks of 1600 bytes
    for row_group_bytes, groups in ((1, 10), (3000, 5), (10**9, 1)):
        path = tmp_path / f"steps_{row_group_bytes}.parquet"
        writer = StepsWriter(path, row_group_bytes=row_group_bytes)
        for f in frames:
            writer.append(f)
        writer.finish()
        assert pq.ParquetFile(path).metadata.num_row_groups == groups
        assert_frame_equal(pd.read_parquet(path), pd.concat(frames, ignore_index=True))


def test_an_hour_is_accepted_by_default_and_a_whole_trace_hour_is_refused():
    hour = compose_cfg(["duration=3600"])
    validate(hour)
    assert memory_estimate_gb(hour) < 4.0
    with pytest.raises(ConfigError, match="record.chunk_ticks"):
        validate(compose_cfg(["duration=3600", "record.chunk_ticks=null"]))
    with pytest.raises(ConfigError, match="record.chunk_ticks"):
        validate(compose_cfg(["record.chunk_ticks=0"]))


def test_percentiles_exact_up_to_the_cap_then_from_a_fixed_size_histogram(monkeypatch):
    from taslel_bench.metrics import stream

    monkeypatch.setattr(stream, "EXACT_QUANTILE_VALUES", 1000)
    rng = np.random.default_rng(3)
    worlds = {  # signs, zeros, a heavy tail, values spanning 1e-9 .. 1e6
        "normal": rng.normal(0.02, 0.01, 20_000),
        "mixed": np.concatenate([rng.normal(0.0, 1.0, 9000), np.zeros(2000), -rng.lognormal(0, 3, 9000)]),
        "tail": rng.lognormal(3.0, 2.5, 20_000),
    }
    for name, x in worlds.items():
        acc = stream.Reducer()
        for part in np.array_split(x, 40):  # chunks of 500: exact for 2 chunks, then the histogram
            acc.pct("p99", part, 99)
            acc.median("p50", part)
            if name == "normal":
                sizes = [op.pos.nbytes + sum(p.nbytes for p in op.parts) if op.sketched else 0
                         for op in acc.ops.values()]
        got = acc.result()
        assert acc.sketched_keys() == ["p99", "p50"], name
        for key, exact in (("p99", np.percentile(x, 99)), ("p50", np.median(x))):
            scale = max(abs(exact), np.abs(np.sort(x)[[int(0.99 * len(x)) if key == "p99" else len(x) // 2]]).max())
            assert abs(got[key] - exact) <= stream.SKETCH_RELATIVE_ACCURACY * scale * 1.01, (name, key, got[key], exact)
    assert len(set(sizes)) == 1  # the histogram's memory does not grow with the values fed
    small = stream.Reducer()
    small.pct("p95", worlds["tail"][:1000], 95)
    assert small.result()["p95"] == np.percentile(worlds["tail"][:1000], 95) and small.sketched_keys() == []
    nan = stream.Reducer()
    nan.pct("p95", np.r_[worlds["normal"][:5000], np.nan], 95)
    assert math.isnan(nan.result()["p95"])  # a NaN in the stream is a NaN percentile, exact or not


def test_qp_failures_beyond_the_cap_are_counted_not_listed(tmp_path, monkeypatch):
    """A filter that fails on every tick (a failure injected into SafetyFilter.filter: the nominal u passes)
    lists the first failures as events and counts the rest, so an hour of failures does not grow the trace."""
    from dataclasses import replace

    from taslel_bench.filter.safety_filter import SafetyFilter
    from taslel_bench.record import trace

    original = SafetyFilter.filter
    monkeypatch.setattr(SafetyFilter, "filter", lambda self, inputs, u_nom: replace(
        original(self, inputs, u_nom), u=np.array(u_nom, copy=True), used_fallback=True, status="injected"))
    monkeypatch.setattr(trace, "MAX_QP_FAILURE_EVENTS", 5)
    summary = run(compose_cfg(["duration=0.05", "record.mcap=false"]), tmp_path / "run")
    events = json.loads((tmp_path / "run" / "events.json").read_text())
    listed = [e for e in events if e["kind"] == "qp_failure"]
    assert summary["qp_failed"] > 10
    assert len(listed) == 6 and listed[-1]["message"].startswith(f"{summary['qp_failed'] - 5} more QP failures")
