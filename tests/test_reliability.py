"""Reliability: nothing lost, nothing stale, nothing silent. One test per fault class
and per example of the reliability work; each failed on the code before it (see studies/notes/reliability.md).

Classes: (1) stale results reported as current, (2) two writers in one folder, (3) results replaced
without a copy, (4) a sweep or report that ends without its table or with exit 0, (5) sizing and messages.
The sweep with a killed worker, a corrupted folder and a full disk is in tests/test_reliability_sweep.py."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from taslel_bench.config.validate import ConfigError
from taslel_bench.plant.mjcf_files import mjcf_files
from taslel_bench.record import run_files
from taslel_bench.record.run_lock import LOCK_NAME, RunFolderLocked
from taslel_bench.sim import identity
from taslel_bench.sim.build import Built
from taslel_bench.sim.episode import Episode
from taslel_bench.sim.run import config_sha256, estimator_files, record_job_error, run
from taslel_bench.sweep import aggregate as aggregate_module
from taslel_bench.sweep import callback as callback_module
from taslel_bench.sweep.aggregate import collect
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
CHECKPOINTS = ROOT / "estimators" / "checkpoints"
TINY = ["duration=0.2", "progress=false", "record.mcap=false"]
TETRA_OBJ = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def menagerie_like_scene(folder: Path) -> Path:
    """``scene.xml`` that ``<include>``s ``robot.xml`` (the harness's A1, as MuJoCo Menagerie splits its
    models), whose trunk carries a visual mesh ``assets/tetra.obj`` (compiler meshdir)."""
    from taslel_bench.plant.build import robot_spec

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "assets").mkdir(exist_ok=True)
    (folder / "assets" / "tetra.obj").write_text(TETRA_OBJ)
    xml = robot_spec().to_xml()
    xml = re.sub(r"<compiler ([^/]*)/>", r'<compiler \1 meshdir="assets"/>\n  <asset><mesh name="tetra" '
                                         r'file="tetra.obj"/></asset>',
                 xml, count=1)
    xml = xml.replace('<site name="imu"/>', '<site name="imu"/>\n      <geom type="mesh" mesh="tetra" contype="0" '
                                            'conaffinity="0" density="0" group="3"/>', 1)  # fmt: skip
    (folder / "robot.xml").write_text(xml)
    (folder / "scene.xml").write_text('<mujoco model="scene">\n  <include file="robot.xml"/>\n</mujoco>\n')
    return folder / "scene.xml"


@pytest.fixture
def no_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    def simulated(self: Episode, *args: object, **kwargs: object) -> None:
        raise AssertionError("Episode.run was called: the bad value was simulated")

    monkeypatch.setattr(Episode, "run", simulated)


# ------------------------------------------------------------------ (1) stale results reported as current


def test_identity_covers_included_files_and_meshes(tmp_path):
    """Changing the included robot (or its mesh) changes the run's hash, so the old result is not skipped."""
    scene = menagerie_like_scene(tmp_path / "scene")
    cfg = compose_cfg([f"robot.plant_mjcf={scene}", *TINY])
    before = config_sha256(cfg)
    robot = tmp_path / "scene" / "robot.xml"
    robot.write_text(robot.read_text().replace('mass="6.001"', 'mass="7.001"'))
    after_robot = config_sha256(cfg)
    (tmp_path / "scene" / "assets" / "tetra.obj").write_text(TETRA_OBJ.replace("0.1 0 0", "0.2 0 0"))
    after_mesh = config_sha256(cfg)
    assert len({before, after_robot, after_mesh}) == 3


def test_listed_plant_files_are_all_mujoco_needs(tmp_path):
    """Independent check of :func:`mjcf_files`: a copy holding only the listed files (same layout) compiles,
    and it lists the include and the mesh under meshdir."""
    scene = menagerie_like_scene(tmp_path / "scene")
    files = mjcf_files(scene)
    assert [p.relative_to(scene.parent.resolve()).as_posix() for p in files] == \
        ["scene.xml", "robot.xml", "assets/tetra.obj"]
    copy = tmp_path / "copy"
    for p in files:
        dest = copy / p.relative_to(scene.parent.resolve())
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(p, dest)
    import mujoco

    assert mujoco.MjSpec.from_file(str(copy / "scene.xml")).compile().nmesh == 1


def test_changed_included_robot_reruns_instead_of_skipping(tmp_path):
    scene = menagerie_like_scene(tmp_path / "scene")
    cfg = compose_cfg([f"robot.plant_mjcf={scene}", *TINY])
    first = run(cfg, tmp_path / "run")
    robot = tmp_path / "scene" / "robot.xml"
    robot.write_text(robot.read_text().replace('mass="6.001"', 'mass="7.001"'))
    second = run(cfg, tmp_path / "run")
    assert "skipped" not in second and second["config_sha256"] != first["config_sha256"]
    assert second["plant_total_mass_kg"] == pytest.approx(first["plant_total_mass_kg"] + 1.0)
    assert (tmp_path / "run" / second["superseded"] / "summary.json").is_file()  # the old result kept


def _checkpoint_copy(folder: Path, name: str = "mlp") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for suffix in (".pt", ".json"):
        shutil.copy(CHECKPOINTS / f"{name}{suffix}", folder / f"{name}{suffix}")
    return folder / name


def test_checkpoint_with_nan_weights_is_refused_naming_file_and_tensor(tmp_path, no_episode):
    ckpt = _checkpoint_copy(tmp_path / "ckpt")
    state = torch.load(ckpt.with_suffix(".pt"), weights_only=True)
    key = next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)
    state[key].view(-1)[0] = float("nan")
    torch.save(state, ckpt.with_suffix(".pt"))
    with pytest.raises(ConfigError) as err:
        run(compose_cfg(["estimator=mlp", f"estimator.checkpoint={ckpt}", *TINY]), tmp_path / "run")
    message = str(err.value)
    assert "estimator.checkpoint" in message and str(ckpt.with_suffix(".pt")) in message and key in message
    assert "non-finite" in message and not (tmp_path / "run").exists()


def test_identity_covers_the_estimators_checkpoint_files(tmp_path):
    """Same path, other content (e.g. retrained weights or metadata): another hash."""
    ckpt = _checkpoint_copy(tmp_path / "ckpt")
    cfg = compose_cfg(["estimator=mlp", f"estimator.checkpoint={ckpt}", *TINY])
    built = Built(cfg)
    files = estimator_files(built)
    assert sorted(p.name for p in files) == ["mlp.json", "mlp.pt"]
    before = config_sha256(cfg, files)
    meta = json.loads(ckpt.with_suffix(".json").read_text())
    meta["retrained"] = True
    ckpt.with_suffix(".json").write_text(json.dumps(meta))
    assert config_sha256(cfg, files) != before


def test_identity_covers_the_drop_detectors_checkpoint(tmp_path):
    """A drop detector's own checkpoint (no short-window model is shipped: one stands in) is an input too."""
    from types import SimpleNamespace

    built = Built(compose_cfg(["estimator=mlp", *TINY]))
    short = _checkpoint_copy(tmp_path / "short", "attention_step")
    built.estimator.detector = SimpleNamespace(files=(short.with_suffix(".pt"), short.with_suffix(".json")))
    files = estimator_files(built)
    assert short.with_suffix(".pt") in files and short.with_suffix(".json") in files
    before = config_sha256(compose_cfg(TINY), files)
    short.with_suffix(".json").write_text("{}")
    assert config_sha256(compose_cfg(TINY), files) != before


def test_identity_covers_the_code_by_content_and_git_is_information_only(monkeypatch):
    """The code's identity is its content (tests/test_reliability_identity.py edits code); the git commit is
    recorded for people but a commit of the same content is the same code."""
    cfg = compose_cfg(TINY)
    before = config_sha256(cfg)
    assert "taslel_bench.filter.safety_filter" in identity.code_modules(identity.ENTRY_MODULES)
    from taslel_bench.util import provenance

    provenance.code_version.cache_clear()
    monkeypatch.setattr(provenance, "_git", lambda *args: "0" * 40)  # another commit, same content
    try:
        assert provenance.code_version()["git_commit"] == "0" * 40 and config_sha256(cfg) == before
    finally:
        provenance.code_version.cache_clear()


@pytest.mark.parametrize(
    ("overrides", "field", "reason"),
    [
        (["filter.start_time=3600", "duration=0.5"], "filter.start_time", "never run"),
        (["filter.start_time=1.0", "duration=0.5"], "filter.start_time", "ends at 1 s"),
        (["record.qps=true", "filter.enabled=false"], "record.qps", "no QP to record"),
    ],
)
def test_meaningless_combination_is_refused_with_the_reason(overrides, field, reason, tmp_path, no_episode):
    with pytest.raises(ConfigError) as err:
        run(compose_cfg([*overrides, "progress=false"]), tmp_path / "run")
    assert str(err.value).startswith(f"{field}=") and reason in str(err.value)


# ------------------------------------------------------------------------- (2) two writers, one folder


def test_run_refuses_a_folder_that_a_live_process_writes(tmp_path, no_episode):
    out = tmp_path / "run"
    out.mkdir()
    (out / "episode.partial.mcap").write_bytes(b"being written")
    holder = subprocess.Popen(
        [sys.executable, "-c", ("import sys; from taslel_bench.record.run_lock import RunLock; "
         f"l = RunLock(r'{out}').acquire(); print('held', flush=True); sys.stdin.read()")],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(RunFolderLocked, match=rf"pid {holder.pid} on {socket.gethostname()}"):
            run(compose_cfg(TINY), out)
        assert (out / "episode.partial.mcap").read_bytes() == b"being written"  # its live file was not moved
        assert not (out / "superseded").exists()
        # in a sweep the error is reported without touching that folder either
        summary = record_job_error(out, {}, compose_cfg(TINY), RunFolderLocked("locked"))
        assert summary["status"] == "error" and not (out / "summary.json").exists()
    finally:
        holder.kill()
        holder.wait()


def test_stale_lock_of_a_dead_process_is_taken_over_and_said(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "run"
    out.mkdir()
    (out / LOCK_NAME).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(), "started": "x"}))
    summary = run(compose_cfg(TINY), out)
    assert summary["status"] == "ok" and f"pid {dead.pid}" in summary["stale_lock_taken_over"]
    assert not (out / LOCK_NAME).exists()  # released at the end


@pytest.mark.parametrize(
    ("sweep", "first", "second"),
    [
        (["seed=0,0"], "#0 (seed=0", "#1 (seed=0"),
        (["record.mcap=true,false"], "#0 (record.mcap=True", "#1 (record.mcap=False"),
        (["hydra/launcher=ray", "seed=0,0"], "#0 (seed=0", "#1 (seed=0"),
    ],
    ids=["seed=0,0", "record.mcap=true,false", "ray seed=0,0"],
)
def test_sweep_mapping_two_jobs_to_one_folder_is_refused_before_it_starts(sweep, first, second, tmp_path):
    cmd = [sys.executable, "-m", "taslel_bench", "-m", *sweep, *TINY[:2], f"hydra.sweep.dir={tmp_path}"]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert out.returncode == 2, out.stderr[-2000:]
    assert first in out.stderr and second in out.stderr and "would write the same run folder" in out.stderr
    assert not [p for p in tmp_path.iterdir() if p.is_dir()]  # no job ran


# ----------------------------------------------------------------------- (3) results replaced without a copy


@pytest.fixture
def finished_run(tmp_path) -> tuple[Path, dict]:
    out = tmp_path / "run"
    return out, run(compose_cfg(TINY), out)


def _rerun_moves(out: Path, damaged: str) -> dict:
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    summary = run(compose_cfg(TINY), out)
    assert "skipped" not in summary and damaged in summary["superseded"]
    moved = out / summary["superseded"]
    assert sorted(p.name for p in moved.iterdir()) == sorted(before)  # every old file kept, none overwritten
    assert all((moved / name).read_bytes() == data for name, data in before.items())
    assert summary["superseded_files"] == ",".join(sorted(before)) and summary["superseded_why"]
    return summary


def test_truncated_summary_is_superseded_not_overwritten(finished_run):
    out, _ = finished_run
    (out / "summary.json").write_text((out / "summary.json").read_text()[:200])
    assert "truncated" in _rerun_moves(out, "incomplete-summary-unreadable")["superseded_why"]


def test_deleted_steps_parquet_is_superseded_not_overwritten(finished_run):
    out, _ = finished_run
    (out / "steps.parquet").unlink()
    assert "steps.parquet" in _rerun_moves(out, "incomplete-missing-steps.parquet")["superseded_why"]


def test_truncated_steps_parquet_is_superseded(finished_run):
    out, _ = finished_run
    data = (out / "steps.parquet").read_bytes()
    (out / "steps.parquet").write_bytes(data[: len(data) // 2])
    _rerun_moves(out, "incomplete-size-steps.parquet")


def test_killed_run_with_a_final_mcap_is_superseded(tmp_path):
    out = tmp_path / "run"
    run(compose_cfg([*TINY[:2], "record.mcap=true"]), out)
    (out / "summary.json").unlink()  # killed after episode.mcap was renamed, before summary.json
    summary = run(compose_cfg([*TINY[:2], "record.mcap=true"]), out)
    assert (out / summary["superseded"] / "episode.mcap").is_file() and (out / "episode.mcap").is_file()


def test_old_traceback_does_not_stay_in_a_folder_that_is_now_ok(tmp_path):
    out = tmp_path / "run"
    cfg = compose_cfg(TINY)
    try:
        raise RuntimeError("first attempt failed")
    except RuntimeError as exc:
        record_job_error(out, {}, cfg, exc)
    assert (out / "traceback.txt").is_file()
    summary = run(cfg, out)
    assert summary["status"] == "ok" and not (out / "traceback.txt").exists()
    assert (out / summary["superseded"] / "traceback.txt").is_file()


def test_stray_result_file_makes_the_set_incomplete(finished_run):
    out, _ = finished_run
    (out / "traceback.txt").write_text("from another attempt")
    _rerun_moves(out, "incomplete-extra-traceback.txt")


# ------------------------------------------------------------- (4) a sweep that ends without its table


def _sweep_of_three(tmp_path: Path) -> Path:
    sweep = tmp_path / "sweep"
    for seed in (0, 1, 2):
        run(compose_cfg([*TINY, f"seed={seed}"]), sweep / f"seed={seed}")
    return sweep


def test_report_never_crashes_on_bad_runs_and_names_the_file(tmp_path, capsys):
    from taslel_bench.sweep.report import main as report_main

    sweep = _sweep_of_three(tmp_path)
    steps = sweep / "seed=0" / "steps.parquet"
    steps.write_bytes(steps.read_bytes()[:5000])  # truncated (ArrowInvalid before)
    (sweep / "seed=1" / "config.yaml").write_text("scenario: [unclosed\n  : :")  # yaml ParserError before
    (sweep / "seed=2" / "summary.json").write_text("[1, 2, 3]\n")  # a JSON list (TypeError before)
    with pytest.raises(SystemExit) as exited:
        report_main([str(sweep)])
    assert exited.value.code == 1
    table = pd.read_parquet(sweep / "summary.parquet")
    assert len(table) == 3 and (table["status"] == "error").all()
    messages = dict(zip(table["run_dir"], table["message"], strict=True))
    assert str(steps) in messages["seed=0"]
    assert str(sweep / "seed=1" / "config.yaml") in messages["seed=1"]
    assert str(sweep / "seed=2" / "summary.json") in messages["seed=2"]
    assert (sweep / "report.md").is_file() and "Runs that ended in an error" in (sweep / "report.md").read_text()


def test_report_exit_codes(tmp_path):
    from taslel_bench.sweep.report import main as report_main

    sweep = _sweep_of_three(tmp_path)
    with pytest.raises(SystemExit) as ok:
        report_main([str(sweep)])
    with pytest.raises(SystemExit) as bad_input:
        report_main([str(tmp_path / "nothing")])
    assert (ok.value.code, bad_input.value.code) == (0, 2)


class _Cfg(dict):
    """The part of the sweep config the callback reads."""

    def __init__(self, sweep: Path) -> None:
        from omegaconf import OmegaConf

        super().__init__()
        self.node = OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}, "tracker": None})


def test_failing_report_at_the_end_of_a_sweep_exits_non_zero_with_one_line(tmp_path, monkeypatch, capsys):
    sweep = _sweep_of_three(tmp_path)

    def broken(*args, **kwargs):
        raise RuntimeError("figure backend exploded")

    monkeypatch.setattr(callback_module, "write_report", broken)
    callback_module.SweepCallback().on_multirun_end(_Cfg(sweep).node)  # never raises (Hydra would only warn)
    err = capsys.readouterr()
    assert callback_module.exit_code() == 1 and "figure backend exploded" in err.err
    assert "3 runs (0 with errors)" in err.out  # the table is still printed


def test_full_disk_at_the_end_of_a_sweep_exits_non_zero_with_one_line(tmp_path, monkeypatch, capsys):
    sweep = _sweep_of_three(tmp_path)

    def full(path, frame):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(aggregate_module.run_files, "write_parquet", full)
    callback_module.SweepCallback().on_multirun_end(_Cfg(sweep).node)
    err = capsys.readouterr()
    assert callback_module.exit_code() == 1
    lines = [line for line in err.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: disk full") and "summary.parquet" in lines[0]


def test_a_sweep_with_an_error_run_exits_1_and_all_ok_exits_0(tmp_path, capsys):
    sweep = _sweep_of_three(tmp_path)
    callback_module.SweepCallback().on_multirun_end(_Cfg(sweep).node)
    assert callback_module.exit_code() == 0
    summary = json.loads((sweep / "seed=1" / "summary.json").read_text())
    summary["status"] = "degraded"
    run_files.write_json(sweep / "seed=1" / "summary.json", summary)
    callback_module.SweepCallback().on_multirun_end(_Cfg(sweep).node)
    assert callback_module.exit_code() == 1


def test_a_full_disk_error_names_the_result_file_not_the_temporary_one(tmp_path):
    def full(tmp: Path) -> None:
        tmp.write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "Error writing bytes to file")  # as pyarrow raises it: no file name

    with pytest.raises(OSError) as err:
        run_files.atomic_write(tmp_path / "steps.parquet", full)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(tmp_path / "steps.parquet")
    assert list(tmp_path.iterdir()) == []  # the partial temporary file is removed


def test_job_that_could_not_write_its_folder_still_has_a_row(tmp_path):
    """The launcher's record of a job whose folder holds no summary (full disk) is the table's row."""
    sweep = _sweep_of_three(tmp_path)
    lost = sweep / "seed=3"
    (lost / ".hydra").mkdir(parents=True)
    (lost / ".hydra" / "config.yaml").write_text("seed: 3\n")
    known = {str(lost.absolute()): {"status": "error", "message": "disk full: steps.parquet", "seed": 3}}
    frame = collect(sweep, known)
    assert len(frame) == 4 and frame.loc[frame["seed"] == 3, "message"].iloc[0] == "disk full: steps.parquet"


def test_single_run_exit_codes(tmp_path):
    bad = subprocess.run([sys.executable, "-m", "taslel_bench", "controller.kp=-1", f"hydra.run.dir={tmp_path}"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)  # fmt: skip
    assert bad.returncode == 2 and "controller.kp=-1" in bad.stderr


# ---------------------------------------------------------------------------------- (5) sizing, messages


def test_an_hour_long_run_with_the_whole_trace_in_memory_is_refused_with_a_memory_estimate(tmp_path, no_episode):
    """record.chunk_ticks=null holds the whole trace (the default chunks accept the hour: tests/test_chunks.py)."""
    with pytest.raises(ConfigError) as err:
        run(compose_cfg(["duration=3600", "progress=false", "record.chunk_ticks=null"]), tmp_path / "run")
    message = str(err.value)
    assert message.startswith("duration=3600") and "GB by estimate" in message and "max_memory_gb=8" in message
    needed = float(message.split("needs ~")[1].split(" GB")[0])
    assert 12 < needed < 18  # 0.40 + 4e-6 x 3,600,500 ticks


def test_memory_estimate_and_peak_are_in_the_summary(finished_run):
    _, summary = finished_run
    assert 0.3 < summary["memory_estimate_gb"] < 0.5 and 0.1 < summary["memory_peak_gb"] < 4


def test_mujoco_compile_error_names_the_field_and_the_missing_file(tmp_path, no_episode):
    scene = menagerie_like_scene(tmp_path / "scene")
    mesh = tmp_path / "scene" / "assets" / "tetra.obj"
    mesh.unlink()
    with pytest.raises(ConfigError) as err:
        Built(compose_cfg([f"robot.plant_mjcf={scene}", *TINY]))
    assert str(err.value).startswith(f"robot.plant_mjcf='{scene}'") and str(mesh.resolve()) in str(err.value)


def test_massless_body_compile_error_names_the_field(tmp_path, no_episode):
    scene = menagerie_like_scene(tmp_path / "scene")
    robot = tmp_path / "scene" / "robot.xml"
    robot.write_text(robot.read_text().replace(
        '<site name="imu"/>', '<site name="imu"/>\n      <body name="loose"><joint type="slide"/></body>', 1))
    with pytest.raises(ConfigError) as err:
        Built(compose_cfg([f"robot.plant_mjcf={scene}", *TINY]))
    message = str(err.value)
    assert message.startswith(f"robot.plant_mjcf='{scene}'") and "mjMINVAL" in message and "<inertial>" in message


def test_unnamed_foot_spheres_get_a_hint(tmp_path, no_episode):
    from taslel_bench.plant.build import robot_spec
    from taslel_bench.robot import quadruped as quad

    spec = robot_spec()
    for element in list(spec.sensors) + list(spec.sites):
        spec.delete(element)
    for foot in quad.FOOT_FRAMES:
        spec.geom(foot).name = ""
    (tmp_path / "a1.xml").write_text(spec.to_xml())
    with pytest.raises(ConfigError) as err:
        Built(compose_cfg([f"robot.plant_mjcf={tmp_path / 'a1.xml'}", *TINY]))
    message = str(err.value)
    assert "4 unnamed sphere geom(s)" in message and f"name these 4 spheres {', '.join(quad.FOOT_FRAMES)}" in message
    assert "FR_calf" in message  # the bodies they are in


def _qpset_tool(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "taslel_bench.qpset", *argv], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, check=False)  # fmt: skip


@pytest.mark.parametrize("kind", ["not a zip", "truncated", "array missing", "pickled"])
def test_qpset_info_answers_a_bad_file_in_one_line_naming_it(kind, tmp_path):
    good = ROOT / "tests" / "data" / "qps_episode.npz"
    bad = tmp_path / "bad.npz"
    if kind == "not a zip":
        bad.write_text("hello")
    elif kind == "truncated":
        bad.write_bytes(good.read_bytes()[:3000])
    elif kind == "array missing":
        with np.load(good) as d:
            np.savez(bad, **{k: d[k] for k in d.files if not k.startswith("g0__P")})
    else:
        np.savez(bad, format=np.array([{"a": 1}], dtype=object))
    out = _qpset_tool("info", str(bad))
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and str(bad) in lines[0] and "Traceback" not in out.stderr


def test_qpset_merge_checks_the_output_path_first(tmp_path):
    good = ROOT / "tests" / "data" / "qps_episode.npz"
    out = _qpset_tool("merge", str(good), "-o", str(tmp_path / "missing" / "merged.npz"))
    assert out.returncode == 2 and str(tmp_path / "missing") in out.stderr and ".tmp-" not in out.stderr


@pytest.mark.parametrize(("override", "field"), [("repeats=0", "repeats"), ("modes=[cold,hot]", "modes"),
                                                 ("profiles=[fast]", "profiles"), ("max_qps=-1", "max_qps")])
def test_replay_checks_settings_before_any_work(override, field, tmp_path, monkeypatch):
    from hydra import compose, initialize_config_dir

    from taslel_bench.qp import replay as replay_module

    def no_work(*args, **kwargs):
        raise AssertionError("replay started before its settings were checked")

    monkeypatch.setattr(replay_module, "replay", no_work)
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="replay", overrides=[f"testset={ROOT / 'tests' / 'data' / 'qps_episode.npz'}",
                                                       override])  # fmt: skip
    with pytest.raises(replay_module.ReplayInputError, match=rf"^{field}="):
        replay_module.run_job(cfg, tmp_path / "out")
    assert not (tmp_path / "out").exists()
