"""tracker=mlflow: a 2-run sweep logged to an embedded SQLite store and read back through mlflow.search_runs;
the run folders are the same with or without the tracker."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mlflow
import pytest
from omegaconf import OmegaConf

from taslel_bench.sim.run import config_sha256, run
from taslel_bench.sweep.aggregate import aggregate
from taslel_bench.sweep.report import write_report
from taslel_bench.sweep.trackers import check_settings, log_sweep
from taslel_bench.util.fields import ConfigError
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["duration=0.1", "progress=false", "filter.enabled=false"]


def _settings(tmp_path: Path, **extra) -> dict:
    return {"name": "mlflow", "uri": f"sqlite:///{tmp_path / 'mlflow.db'}",
            "artifact_root": str(tmp_path / "artifacts"), "experiment": "test_sweep",
            "artifacts": ["summary", "report", "figures"], "large_files": "path", **extra}  # fmt: skip


def _two_run_sweep(sweep: Path) -> None:
    for seed in (0, 1):
        overrides = [*SHORT, f"seed={seed}"]
        run(compose_cfg(overrides), sweep / f"seed={seed}", {"scenario": "flat", "solver": "none"}, [f"seed={seed}"])
    write_report(sweep, aggregate(sweep))


def test_a_two_run_sweep_is_logged_and_read_back(tmp_path):
    sweep = tmp_path / "sweep"
    _two_run_sweep(sweep)
    frame = aggregate(sweep)
    settings = _settings(tmp_path)
    parent = log_sweep(settings, sweep, frame)
    mlflow.set_tracking_uri(settings["uri"])
    runs = mlflow.search_runs(experiment_names=["test_sweep"], output_format="list")
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == parent]
    assert {r.info.run_id for r in runs} == {parent, *(r.info.run_id for r in children)} and len(children) == 2
    for child in children:
        summary = json.loads((sweep / child.data.tags["run_dir"] / "summary.json").read_text())
        assert child.data.params["seed"] == str(summary["seed"])
        assert child.data.metrics["distance_m"] == pytest.approx(summary["distance_m"])
        assert child.data.metrics["fell"] == float(summary["fell"])
        assert child.data.tags["status"] == summary["status"] and child.data.tags["git_commit"] == summary["git_commit"]
        assert child.data.tags["verdict"] == (
            "n/a" if "safe" not in summary else ("safe" if summary["safe"] else "unsafe")
        )
        assert Path(child.data.tags["episode_mcap_path"]).is_file()
        names = {a.path for a in mlflow.MlflowClient(settings["uri"]).list_artifacts(child.info.run_id)}
        assert {"summary.json", "config.yaml", "events.json"} <= names
    parent_run = mlflow.MlflowClient(settings["uri"]).get_run(parent)
    assert parent_run.data.metrics["runs"] == 2.0 and parent_run.data.tags["sweep_dir"] == str(sweep.resolve())
    assert "report.md" in {a.path for a in mlflow.MlflowClient(settings["uri"]).list_artifacts(parent)}
    again = log_sweep(settings, sweep, frame)  # the callback run twice on one folder: nothing is duplicated
    assert again == parent
    assert len(mlflow.search_runs(experiment_names=["test_sweep"], output_format="list")) == 3


def test_the_tracker_is_not_part_of_a_run(tmp_path):
    plain, tracked = compose_cfg(SHORT), compose_cfg([*SHORT, "tracker=mlflow"])
    assert tracked.tracker.name == "mlflow" and plain.tracker.name == "none"
    assert config_sha256(plain) == config_sha256(tracked)
    run(tracked, tmp_path)
    assert "tracker" not in OmegaConf.load(tmp_path / "config.yaml")


def test_bad_tracker_values_are_refused_naming_the_field():
    with pytest.raises(ConfigError, match="tracker.large_files='copy': valid: path, artifact, none"):
        check_settings({"name": "mlflow", "large_files": "copy"})
    with pytest.raises(ConfigError, match="tracker.name='wandb'"):
        check_settings({"name": "wandb"})


@pytest.mark.slow
def test_a_real_sweep_with_the_tracker_gives_the_same_run_folders(tmp_path):
    """``python -m taslel_bench -m ... tracker=mlflow``: the callback logs it; the same folders as without."""
    folders = {}
    for name, extra in (("plain", []), ("tracked", ["tracker=mlflow", f"tracker.uri=sqlite:///{tmp_path / 'm.db'}",
                                                     f"tracker.artifact_root={tmp_path / 'art'}"])):  # fmt: skip
        sweep = tmp_path / name
        cmd = [sys.executable, "-m", "taslel_bench", "-m", "seed=0,1", *SHORT, "hydra.launcher.n_jobs=1",
               f"hydra.sweep.dir={sweep}", *extra]  # fmt: skip
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
        assert proc.returncode == 0, proc.stderr[-3000:]
        folders[name] = sorted(p.parent.name for p in sweep.glob("*/summary.json"))
        if extra:
            assert "tracker mlflow: 2 runs under parent run" in proc.stdout
    assert folders["plain"] == folders["tracked"] and len(folders["plain"]) == 2
    mlflow.set_tracking_uri(f"sqlite:///{tmp_path / 'm.db'}")
    assert len(mlflow.search_runs(experiment_names=["taslel_bench"], output_format="list")) == 3
