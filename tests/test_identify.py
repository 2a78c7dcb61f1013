"""Identification of the controller's model (``python -m taslel_bench.identify``) and ``model.from``: on a short
recorded run of a plant with known joint damping, mujoco.sysid recovers it; the model file it writes is loaded by
``model=identified model.from=<file>`` into the controller's model; a missing or malformed file is refused naming
``model.from`` and the file."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

pytest.importorskip("mujoco.sysid.report.builder", reason='needs the extra mujoco[sysid] (".[identify]")')

from taslel_bench.config.model_file import load_model_file  # noqa: E402 - after the skip
from taslel_bench.config.settings import model_options  # noqa: E402
from taslel_bench.identify.__main__ import main as identify_main  # noqa: E402
from taslel_bench.identify.fit import FitSettings, identify  # noqa: E402
from taslel_bench.identify.runs import load_run  # noqa: E402
from taslel_bench.sim.build import Built  # noqa: E402
from taslel_bench.sim.run import run  # noqa: E402
from tests.conftest import compose_cfg  # noqa: E402
from tests.test_faults import assert_refused, no_episode  # noqa: E402, F401 - fixture

DAMPING = 0.8  # [N·m·s/rad] the plant's, added to every leg joint
PLANT = ["scenario=perturbed", f"scenario.joint_damping={DAMPING}", "scenario.joint_frictionloss=0",
         "scenario.motor_strength_scale=1", "scenario.actuator_delay_steps=0"]


@pytest.fixture(scope="module")
def damped_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recorded run: 0.5 s stand, 0.6 s of trot on the damped plant, the nominal trot alone."""
    folder = tmp_path_factory.mktemp("identify") / "damped"
    summary = run(compose_cfg([*PLANT, "duration=0.6", "filter.enabled=false", "record.mcap=false"]), folder)
    assert summary["status"] != "error" and not summary["fell"]  # degraded: the URDF model's residual alarm
    return folder


def test_sensors_are_the_recorded_state(damped_run: Path) -> None:
    """The identification model's sensordata is [qpos, qvel]: a recorded row is sysid's measured signal as is."""
    data = load_run(damped_run)
    m = data.spec.compile()
    d = mujoco.MjData(m)
    for k in (data.walk_from, len(data.t_s) - 1):
        d.qpos[:], d.qvel[:] = data.qpos[k], data.qvel[k]
        mujoco.mj_forward(m, d)
        assert np.abs(d.sensordata - np.concatenate([data.qpos[k], data.qvel[k]])).max() < 1e-12


def test_recovers_the_joint_damping_of_the_plant(damped_run: Path) -> None:
    data = load_run(damped_run)
    assert data.plant["joint_damping"] == DAMPING and data.walking_s == pytest.approx(0.6, abs=0.002)
    fit = identify([data], FitSettings(max_walk_s=0.4), output=None)
    assert fit.windows == 20 and fit.walking_s == pytest.approx(0.4)
    assert fit.value["joint_damping"][0] == pytest.approx(DAMPING, rel=0.01)
    assert abs(fit.value["armature"][0]) < 1e-4 and abs(fit.value["joint_frictionloss"][0]) < 0.01
    assert fit.value["trunk_mass_scale"][0] == pytest.approx(1.0, abs=0.01)
    assert np.abs(fit.value["trunk_com_shift_m"]).max() < 1e-3
    assert fit.interval["joint_damping"][0] < 0.01 * DAMPING  # the interval says it is identified
    assert fit.rms_after["joint_velocity_radps"] < 1e-3 * fit.rms_before["joint_velocity_radps"]


def test_the_model_file_reaches_the_controller_model(damped_run: Path, tmp_path: Path, no_episode: None,  # noqa: F811
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "damped.yaml"
    assert identify_main([str(damped_run), "--out", str(out), "--max-walk", "0.2", "--no-html"]) == 0
    assert "joint_damping" in capsys.readouterr().out
    assert (tmp_path / "damped.report.md").is_file() and (tmp_path / "damped.fit.json").is_file()
    values = load_model_file(out)
    assert values["joint_damping"] == pytest.approx(DAMPING, rel=0.01)
    cfg = compose_cfg([*PLANT, "model=identified", f"model.from={out}", "filter.enabled=false"])
    options = model_options(cfg)
    assert options.joint_damping == values["joint_damping"] and options.implicit_damping_dt_s == 0.001
    model = Built(cfg).episode.model
    assert np.allclose(model.joint_damping, values["joint_damping"])
    assert np.allclose(np.array(model.model.armature)[6:], values["armature"] + 0.001 * values["joint_damping"])


@pytest.mark.parametrize(("text", "expected"), [
    (None, "no such file"),
    ("model: [1\n", "not readable as YAML"),
    ("joint_damping: 1.5\n", "must hold one mapping, `model:`"),
    ("model:\n  joint_dampin: 1.5\n", "model.joint_dampin: unknown key"),
    ("model:\n  joint_damping: -1\n", "model.joint_damping=-1"),
    ("model:\n  trunk_com_shift_m: [0.0, 0.0]\n", "model.trunk_com_shift_m"),
    ("model:\n  implicit_damping_dt_s: 5\n", "model.implicit_damping_dt_s=5"),
])
def test_a_missing_or_malformed_model_file_is_refused(tmp_path: Path, no_episode: None,  # noqa: F811
                                                      text: str | None, expected: str) -> None:
    file = tmp_path / "model.yaml"
    if text is not None:
        file.write_text(text)
    assert_refused(["model=identified", f"model.from={file}"], tmp_path / "run", f"model.from='{file}'", expected)


def test_model_from_is_required_and_not_contradicted(tmp_path: Path, no_episode: None) -> None:  # noqa: F811
    assert_refused(["model=identified"], tmp_path / "a", "model.from=", "add model.from=<file>")
    file = tmp_path / "model.yaml"
    file.write_text("model:\n  joint_damping: 1.5\n")
    assert_refused(["model=identified", f"model.from={file}", "model.joint_damping=1.0"], tmp_path / "b",
                   "model.joint_damping=1.0", "set by model.from=")
    same = compose_cfg(["model=identified", f"model.from={file}", "model.joint_damping=[1.5,1.5,1.5,1.5,1.5,1.5,"
                        "1.5,1.5,1.5,1.5,1.5,1.5]"])
    assert model_options(same).joint_damping == 1.5


def test_identify_refuses_a_folder_that_is_not_a_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert identify_main([str(tmp_path), "--out", str(tmp_path / "m.yaml")]) == 2
    assert f"{tmp_path}: not a run folder (no config.yaml)" in capsys.readouterr().err
