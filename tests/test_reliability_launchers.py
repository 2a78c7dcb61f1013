"""Every launcher ends with its table: a job lost under submitit (its process SIGKILLed) is an error row, the
other jobs' rows are there, the exit code is 1. Failed on the main of before (a traceback, no table)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent
FAULTS = Path(__file__).resolve().parent / "fault_injection"


@pytest.mark.slow
def test_submitit_local_with_a_killed_job_ends_with_its_table(tmp_path):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(FAULTS), str(ROOT)]), "TASLEL_FAULTS": "kill=seed=1"}
    cmd = [sys.executable, "-m", "taslel_bench", "-m", "hydra/launcher=submitit_local", "seed=0,1", "duration=0.2",
           "progress=false", "record.mcap=false", f"hydra.sweep.dir={tmp_path}"]  # fmt: skip
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False)
    assert out.returncode == 1, out.stderr[-3000:]
    table = pd.read_parquet(tmp_path / "summary.parquet")
    rows = {int(s): r for s, r in zip(table["seed"], table.to_dict("records"), strict=True)}
    assert rows[0]["status"] == "ok"
    assert rows[1]["status"] == "error" and "LostJob" in rows[1]["message"] and "seed=1" in rows[1]["message"]
    assert (tmp_path / "report.md").is_file() and "Traceback" not in out.stderr


def _one_run_sweep(folder: Path) -> Path:
    from taslel_bench.sim.run import run
    from tests.conftest import compose_cfg

    run(compose_cfg(["duration=0.2", "progress=false", "record.mcap=false"]), folder / "seed=0")
    return folder


def test_table_files_are_one_set_and_an_incomplete_set_is_told(tmp_path, monkeypatch, capsys):
    from taslel_bench.sweep import report, table_set

    sweep = _one_run_sweep(tmp_path)
    with pytest.raises(SystemExit):
        report.main([str(sweep)])
    assert table_set.set_problem(sweep) == "" and (sweep / table_set.RECORD).is_file()
    old_report = (sweep / "report.md").read_bytes()

    def killed(*args, **kwargs):  # killed after the new summary.parquet, before table.csv and report.md
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "write_report", killed)
    with pytest.raises(KeyboardInterrupt):
        report.main([str(sweep)])
    assert (sweep / "report.md").read_bytes() == old_report  # the old report beside a new summary.parquet...
    problem = table_set.set_problem(sweep)
    assert "table_set.json is missing" in problem  # ...and a reader can tell
    monkeypatch.undo()
    with pytest.raises(SystemExit):
        report.main([str(sweep)])
    assert "note: " in capsys.readouterr().err and table_set.set_problem(sweep) == ""
    (sweep / "table.csv").write_text("edited\n")
    assert "table.csv is not the file of the set" in table_set.set_problem(sweep)
