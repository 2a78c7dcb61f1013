"""Runs never lie about completeness: a rerun with another config is not "complete", a killed run leaves a
readable partial MCAP that a rerun puts aside, stale temporary files are removed and named, reports of
sweeps whose every run was killed (or empty folders) do not crash."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from taslel_bench.record.mcap import PARTIAL_NAME, McapStream, read_messages
from taslel_bench.sim.build import Built
from taslel_bench.sim.observers import StreamedChunks
from taslel_bench.sim.run import config_sha256, run
from taslel_bench.sweep.aggregate import aggregate
from taslel_bench.sweep.report import write_report
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent


def short(*extra: str) -> list[str]:
    return ["duration=0.2", "progress=false", "record.mcap=false", "filter.enabled=false", *extra]


def test_rerun_with_another_config_is_not_complete_and_the_old_result_is_kept(tmp_path):
    first = run(compose_cfg(short()), tmp_path)
    again = run(compose_cfg(short()), tmp_path)
    assert again.get("skipped") is True
    other = run(compose_cfg(short("duration=0.3")), tmp_path)
    assert "skipped" not in other and other["ticks"] == first["ticks"] + 100
    moved = tmp_path / other["superseded"]
    assert moved.parent.name == "superseded" and moved.name.endswith(f"config-{first['config_sha256'][:8]}")
    assert json.loads((moved / "summary.json").read_text())["ticks"] == first["ticks"]
    # a recording key changes what the folder holds: not the same run either
    with_mcap = run(compose_cfg(short("duration=0.3", "record.mcap=true")), tmp_path)
    assert "skipped" not in with_mcap and (tmp_path / "episode.mcap").is_file()
    # force reruns the same config, and also puts the old result aside
    forced = run(compose_cfg(short("duration=0.3", "record.mcap=true", "force=true")), tmp_path)
    assert "skipped" not in forced and forced["superseded"].endswith("_forced")


def test_config_hash_covers_the_plant_file_and_ignores_printing(tmp_path):
    mjcf = tmp_path / "a1.xml"
    mjcf.write_text("<mujoco/>")
    cfg = compose_cfg(short(f"robot.plant_mjcf={mjcf}"))
    before = config_sha256(cfg)
    assert config_sha256(compose_cfg(short(f"robot.plant_mjcf={mjcf}", "progress=true", "force=true"))) == before
    mjcf.write_text("<mujoco><option timestep='0.002'/></mujoco>")
    assert config_sha256(cfg) != before


def test_stale_temporary_files_are_removed_and_named(tmp_path):
    (tmp_path / ".summary.json.tmp-4242").write_text("{")
    summary = run(compose_cfg(short()), tmp_path)
    assert summary["stale_files_removed"] == ".summary.json.tmp-4242"
    assert not list(tmp_path.glob(".*.tmp-*"))


def test_streamed_mcap_is_readable_before_it_is_finished(tmp_path):
    """Chunks are flushed as the episode runs: the partial file reads back up to its last chunk, also when
    cut inside a record (a kill during a write)."""
    stream = McapStream(tmp_path)
    sizes: list[int] = []  # file size after each streamed chunk

    def sink(trace, k0, k1):
        stream(trace, k0, k1)
        sizes.append((tmp_path / PARTIAL_NAME).stat().st_size)

    built = Built(compose_cfg(short("duration=1.5")), lambda b: [StreamedChunks(lambda: sink, 1000)], chunk_ticks=500)
    res = built.episode.run()
    assert stream.ticks_written == 2000 and res.trace.n == 2000
    stream.abandon()  # as if killed before close(): no summary section, no rename
    partial = tmp_path / PARTIAL_NAME
    counts = Counter(topic for topic, _, _ in read_messages(partial))
    assert counts["/base_state"] == 2000 and counts["/torques"] == 2000 and "/summary" not in counts
    assert len(sizes) == 4 and sizes == sorted(sizes)
    partial.write_bytes(partial.read_bytes()[: (sizes[2] + sizes[3]) // 2])  # killed while writing chunk 4
    counts = Counter(topic for topic, _, _ in read_messages(partial))
    assert counts["/base_state"] == 1500  # the three complete chunks
    times = [t - stream.start_ns for topic, t, _ in read_messages(partial) if topic == "/base_state"]
    assert times == sorted(times) and times[-1] == round(1.499 * 1e9)  # log time = wall-clock start + simulated time


@pytest.mark.slow
def test_killed_run_leaves_a_partial_mcap_that_a_rerun_puts_aside(tmp_path):
    run_dir = tmp_path / "run"
    cmd = [sys.executable, "-m", "taslel_bench", "duration=30", "progress=false", "filter.enabled=false",
           f"hydra.run.dir={run_dir}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    partial = run_dir / PARTIAL_NAME
    deadline = time.monotonic() + 120
    # wait for two streamed seconds of simulated time and for the steps table's temporary file, which opens at
    # the first chunk (record.chunk_ticks): on a loaded machine the MCAP can show 2 s before that
    while time.monotonic() < deadline:
        streamed = partial.is_file() and sum(t == "/tick" for t, _, _ in read_messages(partial)) >= 200  # 100 Hz
        if streamed and list(run_dir.glob(".steps.parquet.tmp-*")):
            break
        time.sleep(0.5)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (run_dir / "summary.json").exists()
    counts = Counter(topic for topic, _, _ in read_messages(partial))
    assert counts["/tick"] >= 200 and counts["/tick"] % 100 == 0  # whole seconds at record.mcap_rate_hz=100
    assert counts["/tf"] == counts["/tick"] and counts["/scene/robot"] == counts["/tick"] // 100  # the 3D channels too
    # steps.parquet streams into a temporary file (record.chunk_ticks): never a half table under its name
    assert not (run_dir / "steps.parquet").exists() and list(run_dir.glob(".steps.parquet.tmp-*"))
    summary = run(compose_cfg(["duration=0.2", "progress=false", "filter.enabled=false"]), run_dir)
    assert summary["superseded"].endswith("_killed")
    assert summary["stale_files_removed"].startswith(".steps.parquet.tmp-")
    assert (run_dir / summary["superseded"] / PARTIAL_NAME).is_file()
    assert (run_dir / "episode.mcap").is_file() and not partial.exists()


def test_report_of_a_sweep_whose_every_run_was_killed(tmp_path):
    for seed in (0, 1):
        hydra_dir = tmp_path / f"seed={seed}" / ".hydra"
        hydra_dir.mkdir(parents=True)
        (hydra_dir / "config.yaml").write_text(f"seed: {seed}\n")
        (hydra_dir / "overrides.yaml").write_text(f"- seed={seed}\n")
    frame = aggregate(tmp_path)
    assert list(frame["status"]) == ["error", "error"]
    report = write_report(tmp_path, frame).read_text()
    assert "## Runs that ended in an error" in report and "job left no summary.json" in report


def test_report_of_an_empty_folder_says_so(tmp_path):
    out = subprocess.run([sys.executable, "-m", "taslel_bench.report", str(tmp_path)], cwd=ROOT,
                         capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode != 0 and f"no runs in {tmp_path}" in out.stderr
