"""Experiment trackers: ``tracker=mlflow`` logs a sweep to MLflow when it ends (the sweep callback), one MLflow
run per run folder under a parent run for the sweep. Off by default (``tracker=none``); the run folders are
the same with or without it (the ``tracker`` group is left out of each run's config.yaml and config hash).

Per run: params = the run's overrides (``scenario.friction``, ``seed``, ...) and its axes; metrics = every
number of its summary.json (booleans as 0/1); tags = ``status``, ``verdict`` (``safe``/``unsafe`` from the
summary's ``safe`` key when it has one, else ``n/a``), ``unsafe_reasons``, ``fell``, ``git_commit``,
``git_dirty``, ``run_dir``, ``config_sha256``; artifacts = summary.json, config.yaml, events.json
(``tracker.artifacts`` has ``summary``); episode.mcap and video.mp4 by path (a tag with the absolute path) or
copied (``tracker.large_files: path | artifact | none``). The sweep's parent run: the sweep folder, counts,
and as artifacts report.md, table.csv, summary.parquet (``report``) and the figures and still strips
(``figures``). Logging the same sweep folder again adds only the runs not logged yet (same run folder and
config hash).

Store: embedded, no server: ``tracker.uri`` (default ``sqlite:///<cwd>/outputs/mlflow.db``), artifacts under
``tracker.artifact_root`` (default ``<cwd>/outputs/mlflow-artifacts``). View: ``mlflow ui --backend-store-uri
sqlite:///outputs/mlflow.db``. ``python -m taslel_bench.sweep.trackers <sweep folder>`` logs an existing folder.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from taslel_bench.record import run_files
from taslel_bench.sweep.aggregate import SUMMARY_TABLE, parse_overrides

KINDS = ("none", "mlflow")
LARGE_FILES = ("path", "artifact", "none")
ARTIFACT_SETS = ("summary", "report", "figures")
RUN_ARTIFACTS = (run_files.SUMMARY, "config.yaml", run_files.EVENTS)
LARGE = ("episode.mcap", "video.mp4")
SWEEP_ARTIFACTS = ("report.md", "table.csv", "table.tex", SUMMARY_TABLE)
TAG_KEYS = ("status", "unsafe_reasons", "fell", "fall_reason", "git_commit", "git_dirty", "config_sha256", "scenario",
            "solver", "estimator", "message")  # fmt: skip
MAX_PARAM_CHARS = 6000  # MLflow's limit on a param value


def default_store(cwd: Path | None = None) -> tuple[str, Path]:
    """(tracking URI, artifact folder) of the embedded store under ``<cwd>/outputs/``."""
    out = (Path(cwd) if cwd is not None else Path.cwd()).resolve() / "outputs"
    return f"sqlite:///{out / 'mlflow.db'}", out / "mlflow-artifacts"


def check_settings(settings) -> None:
    """Refuse a bad ``tracker.*`` value naming it (before any run of the sweep)."""
    from taslel_bench.util.fields import choice, fail

    choice("tracker.name", settings.get("name", "none"), KINDS)
    choice("tracker.large_files", settings.get("large_files", "path"), LARGE_FILES)
    for item in settings.get("artifacts", []) or []:
        if item not in ARTIFACT_SETS:
            raise fail("tracker.artifacts", list(settings.get("artifacts")), f"items must be among "
                                                                             f"{', '.join(ARTIFACT_SETS)}")


def log_sweep(settings, sweep_dir: Path, frame: pd.DataFrame | None = None) -> str | None:
    """Log the sweep folder with the tracker of ``settings`` (the ``tracker`` config group); returns the
    parent run's id, or None for ``tracker=none``."""
    if settings is None or settings.get("name", "none") == "none":
        return None
    check_settings(settings)
    frame = pd.read_parquet(Path(sweep_dir) / SUMMARY_TABLE) if frame is None else frame
    return MlflowSweepLogger(settings).log(Path(sweep_dir), frame)


class MlflowSweepLogger:
    """One sweep folder -> a parent MLflow run and one child run per run folder (see the module doc)."""

    def __init__(self, settings) -> None:
        from mlflow import MlflowClient

        uri, root = default_store()
        self.uri = settings.get("uri") or uri
        self.artifact_root = Path(settings.get("artifact_root") or root)
        self.experiment_name = str(settings.get("experiment", "taslel_bench"))
        self.artifacts = set(settings.get("artifacts", ARTIFACT_SETS) or ())
        self.large_files = str(settings.get("large_files", "path"))
        if self.uri.startswith("sqlite:///"):
            Path(self.uri.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
        self.client = MlflowClient(tracking_uri=self.uri)
        self.experiment_id = self._experiment()

    def _experiment(self) -> str:
        found = self.client.get_experiment_by_name(self.experiment_name)
        if found is not None:
            return found.experiment_id
        self.artifact_root.mkdir(parents=True, exist_ok=True)
        return self.client.create_experiment(self.experiment_name, artifact_location=self.artifact_root.as_uri())

    def _find(self, filter_string: str):
        runs = self.client.search_runs([self.experiment_id], filter_string=filter_string, max_results=1)
        return runs[0] if runs else None

    def log(self, sweep_dir: Path, frame: pd.DataFrame) -> str:
        sweep_dir = sweep_dir.resolve()
        parent = self._find(f"tags.taslel_kind = 'sweep' and tags.sweep_dir = '{_quote(str(sweep_dir))}'")
        if parent is None:
            parent = self.client.create_run(self.experiment_id, run_name=sweep_dir.name,
                                            tags={"taslel_kind": "sweep", "sweep_dir": str(sweep_dir)})  # fmt: skip
        pid = parent.info.run_id
        for _, row in frame.iterrows():
            self._log_run(pid, sweep_dir, row)
        self._log_parent(pid, sweep_dir, frame)
        return pid

    def _log_run(self, parent_id: str, sweep_dir: Path, row: pd.Series) -> None:
        run_dir = str(row.get("run_dir", ""))
        sha = str(row.get("config_sha256", ""))
        done = (f"tags.taslel_kind = 'run' and tags.`mlflow.parentRunId` = '{parent_id}' and "
                f"tags.run_dir = '{_quote(run_dir)}' and tags.config_sha256 = '{_quote(sha)}'")  # fmt: skip
        if self._find(done) is not None:
            return
        tags = {"taslel_kind": "run", "mlflow.parentRunId": parent_id, "run_dir": run_dir, "verdict": verdict(row),
                **{k: _text(row.get(k)) for k in TAG_KEYS if _present(row.get(k))}}  # fmt: skip
        run = self.client.create_run(self.experiment_id, run_name=run_dir or None, tags=tags)
        rid = run.info.run_id
        self._batch(rid, metrics_of(row), params_of(row))
        self._run_files(rid, sweep_dir / run_dir)
        self.client.set_terminated(rid, "FAILED" if row.get("status") == "error" else "FINISHED")

    def _batch(self, run_id: str, metrics: dict[str, float], params: dict[str, str]) -> None:
        from mlflow.entities import Metric, Param

        now = int(time.time() * 1000)
        ms = [Metric(k, v, now, 0) for k, v in metrics.items()]
        ps = [Param(k, v) for k, v in params.items()]
        for i in range(0, len(ps), 90):  # MLflow takes at most 100 params per batch
            self.client.log_batch(run_id, params=ps[i : i + 90])
        for i in range(0, len(ms), 900):  # and 1000 metrics
            self.client.log_batch(run_id, metrics=ms[i : i + 900])

    def _run_files(self, run_id: str, run_dir: Path) -> None:
        if "summary" in self.artifacts:
            for name in RUN_ARTIFACTS:
                if (run_dir / name).is_file():
                    self.client.log_artifact(run_id, str(run_dir / name))
        for name in LARGE:
            path = run_dir / name
            if not path.is_file() or self.large_files == "none":
                continue
            if self.large_files == "artifact":
                self.client.log_artifact(run_id, str(path))
            self.client.set_tag(run_id, f"{name.replace('.', '_')}_path", str(path.resolve()))

    def _log_parent(self, pid: str, sweep_dir: Path, frame: pd.DataFrame) -> None:
        status = frame["status"] if "status" in frame else pd.Series(dtype=str)
        finished = frame[status.isin(("ok", "degraded"))] if len(status) else frame.iloc[0:0]
        fell = int(finished["fell"].astype(bool).sum()) if "fell" in finished else 0
        counts = {"runs": float(len(frame)), "errors": float((status == "error").sum()),
                  "degraded": float((status == "degraded").sum()), "falls": float(fell),
                  "fall_rate": fell / len(finished) if len(finished) else math.nan}  # fmt: skip
        self._batch(pid, counts, {})
        if "report" in self.artifacts:
            for name in SWEEP_ARTIFACTS:
                if (sweep_dir / name).is_file():
                    self.client.log_artifact(pid, str(sweep_dir / name))
        if "figures" in self.artifacts:
            for png in sorted(sweep_dir.glob("*.png")):
                self.client.log_artifact(pid, str(png))
            if (sweep_dir / "stills").is_dir():
                self.client.log_artifacts(pid, str(sweep_dir / "stills"), "stills")
        self.client.set_terminated(pid, "FINISHED")


def _quote(text: str) -> str:
    return text.replace("'", "\\'")


def _present(value) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def _text(value) -> str:
    return json.dumps(value) if isinstance(value, bool) else str(value)


def verdict(row: pd.Series | dict) -> str:
    """``safe`` / ``unsafe`` from the summary's ``safe`` key, ``n/a`` when the summary has none."""
    safe = row.get("safe")
    if isinstance(safe, (bool, np.bool_)):
        return "safe" if bool(safe) else "unsafe"
    return "n/a"


def metrics_of(row: pd.Series | dict) -> dict[str, float]:
    """Every number of a summary row (booleans as 0/1; NaN kept: MLflow stores it as NaN)."""
    out = {}
    for key, value in dict(row).items():
        if isinstance(value, (bool, np.bool_)):
            out[key] = float(bool(value))
        elif isinstance(value, (int, float, np.integer, np.floating)):
            out[key] = float(value)
    return out


def params_of(row: pd.Series | dict) -> dict[str, str]:
    """The run's overrides (key without Hydra's +/~) and its axes, as MLflow params."""
    params = {k: str(row.get(k)) for k in ("scenario", "solver", "estimator", "seed") if _present(row.get(k))}
    params.update(parse_overrides(row.get("overrides")))
    return {k: v[:MAX_PARAM_CHARS] for k, v in params.items()}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="Log a sweep folder (its summary.parquet and run folders) to MLflow.")
    ap.add_argument("sweep_dir", type=Path)
    ap.add_argument("--uri", default=None, help="tracking URI (default: sqlite:///<cwd>/outputs/mlflow.db)")
    ap.add_argument("--experiment", default="taslel_bench")
    ap.add_argument("--large-files", default="path", choices=LARGE_FILES)
    args = ap.parse_args(argv)
    if not (args.sweep_dir / SUMMARY_TABLE).is_file():
        raise SystemExit(f"error: no {SUMMARY_TABLE} in {args.sweep_dir} (python -m taslel_bench.report <folder> makes "
                         f"it)")
    settings = {"name": "mlflow", "uri": args.uri, "experiment": args.experiment, "artifacts": list(ARTIFACT_SETS),
                "large_files": args.large_files}  # fmt: skip
    print(f"parent run {log_sweep(settings, args.sweep_dir)} in {settings['uri'] or default_store()[0]}")


if __name__ == "__main__":
    main()
