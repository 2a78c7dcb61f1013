"""A job's outcome wins over an old folder: a job that could not run is an error row naming its folder and
why, even when the folder holds an old summary; a summary of another identity is never this run's row.
Each test failed on the main of before."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

from taslel_bench.sweep.aggregate import collect

ROOT = Path(__file__).resolve().parent.parent
FAULTS = Path(__file__).resolve().parent / "fault_injection"
TINY = ["duration=0.2", "progress=false", "record.mcap=false"]


def sweep(folder: Path, seeds: str, faults: str = "") -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(FAULTS), str(ROOT)]), "TASLEL_FAULTS": faults}
    cmd = [sys.executable, "-m", "taslel_bench", "-m", f"seed={seeds}", *TINY, f"hydra.sweep.dir={folder}"]
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False)


def test_a_job_that_cannot_write_its_folder_is_an_error_row_not_the_old_summary(tmp_path):
    folder = tmp_path / "sweep"
    first = sweep(folder, "0")
    assert first.returncode == 0, first.stderr[-2000:]
    out = sweep(folder, "0,1", "eacces=seed=0")
    assert out.returncode == 1, out.stdout[-2000:] + out.stderr[-2000:]
    table = pd.read_parquet(folder / "summary.parquet")
    row = table[table["seed"] == 0].iloc[0]
    assert row["status"] == "error" and "Permission denied" in row["message"]
    assert "seed=0" in row["message"] and "not this job's result" in row["message"]  # names the folder, says why
    assert (table[table["seed"] == 1]["status"] == "ok").all()


def _finished(folder: Path, sha: str) -> None:
    folder.mkdir(parents=True)
    pd.DataFrame({"t_s": [0.0]}).to_parquet(folder / "steps.parquet")
    size = (folder / "steps.parquet").stat().st_size
    summary = {"status": "ok", "seed": 0, "config_sha256": sha, "result_files": {"steps.parquet": size}}
    (folder / "summary.json").write_text(json.dumps(summary))


def test_a_folder_summary_of_another_identity_is_not_reported_as_the_job(tmp_path):
    run_dir = tmp_path / "seed=0"
    _finished(run_dir, "a" * 64)
    known = {str(run_dir.absolute()): {"status": "ok", "seed": 0, "config_sha256": "b" * 64}}
    row = collect(tmp_path, known).iloc[0]
    assert row["status"] == "error" and "another identity" in row["message"] and "aaaaaaaaaaaa" in row["message"]
    same = {str(run_dir.absolute()): {"status": "ok", "seed": 0, "config_sha256": "a" * 64}}
    assert collect(tmp_path, same).iloc[0]["status"] == "ok"  # the job's own result (e.g. reused) stays ok
