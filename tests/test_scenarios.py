"""Every scenario builds, passes the friction check and runs briefly; scenario-specific physics checks."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import pytest

from taslel_bench.plant.build import robot_spec
from taslel_bench.plant.contacts import measure_contact_friction
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from tests.conftest import CONF_DIR, compose_cfg

SCENARIOS = sorted(p.stem for p in (Path(CONF_DIR) / "scenario").glob("*.yaml"))


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_every_scenario_builds_and_runs(scenario, tmp_path):
    summary = run(compose_cfg([f"scenario={scenario}", "duration=0.4", "progress=false", "record.mcap=false"]),
                  tmp_path, {"scenario": scenario})
    assert summary["qp_failed_rate"] == 0.0
    assert summary["status"] == "ok", summary["message"] + summary["degraded_reasons"]
    if scenario in ("payload", "perturbed", "stress"):  # the plant is not the controller's model: model error says so
        assert "residual_alarm_rate" in summary["model_error_reasons"]
    else:
        assert summary["model_error_reasons"] == ""


def test_friction_patch_changes_the_friction_the_feet_get():
    built = Built(compose_cfg(["scenario=friction_patch", "scenario.change_at_m=0.1", "filter.enabled=false"]))
    m, d = built.mj_model, built.episode.d
    d.qpos[0] = 0.6  # move the standing robot onto the second patch
    mujoco.mj_forward(m, d)
    frictions = [mu for _, mu in measure_contact_friction(m, d)]
    assert frictions and np.allclose(frictions, 0.2)
    assert built.scenario.terrain.friction_at(np.array([0.6, 0.0])) == 0.2


def test_push_moves_the_trunk_sideways(tmp_path):
    base = ["duration=1.0", "progress=false", "record.mcap=false", "filter.enabled=false"]
    quiet = run(compose_cfg(base), tmp_path / "quiet")
    pushed = run(compose_cfg([*base, "scenario=push", "scenario.pushes=[{t_s: 0.8, force_n: [0, 80, 0], duration_s: "
                                                      "0.1}]"]),
                 tmp_path / "pushed")
    assert quiet["status"] == "ok" and quiet["residual_alarm_rate"] == 0.0
    # the push is a force the controller's model does not know: the residual sees 80 N during it, only then
    steps = pd.read_parquet(tmp_path / "pushed" / "steps.parquet")
    during = (steps["t_s"] >= 0.8) & (steps["t_s"] < 0.9)
    assert steps.loc[during, "residual_trunk_force_n"].median() == pytest.approx(80.0, rel=1e-6)
    assert steps.loc[~during, "residual_trunk_force_n"].max() < 1e-6
    assert pushed["status"] == "ok" and "residual_alarm_rate" in pushed["model_error_reasons"]
    vy_quiet = pd.read_parquet(tmp_path / "quiet" / "steps.parquet")["base_vy_w_mps"].abs().max()
    vy_pushed = pd.read_parquet(tmp_path / "pushed" / "steps.parquet")["base_vy_w_mps"].max()
    # 8 N·s on a 13.7 kg robot: up to ~0.58 m/s if nothing resisted; the legs resist part of it
    assert vy_pushed > vy_quiet + 0.15


def test_payload_is_in_the_plant_only():
    nominal = Built(compose_cfg(["filter.enabled=false"]))
    heavy = Built(compose_cfg(["scenario=payload", "filter.enabled=false"]))
    trunk = mujoco.mj_name2id(heavy.mj_model, mujoco.mjtObj.mjOBJ_BODY, "trunk")
    ratio = heavy.mj_model.body_mass[trunk] / nominal.mj_model.body_mass[trunk]
    assert ratio == pytest.approx(1.25, rel=1e-3)
    assert heavy.episode.model.total_mass_kg == pytest.approx(nominal.episode.model.total_mass_kg)


def test_actuator_delay_holds_commands_back():
    built = Built(compose_cfg(["scenario=perturbed", "scenario.actuator_delay_steps=3", "filter.enabled=false"]))
    d, sc = built.episode.d, built.scenario
    sent = []
    for k in range(6):
        d.ctrl[:] = k
        sc.on_tick(built.mj_model, d, k * 1e-3)
        sent.append(d.ctrl[0])
    assert sent == [0, 0, 0, 0, 1, 2]


def test_plant_mjcf_override_runs_and_bad_model_is_named(tmp_path):
    xml = tmp_path / "a1_other.xml"
    xml.write_text(robot_spec().to_xml())
    summary = run(compose_cfg([f"robot.plant_mjcf={xml}", "duration=0.3", "progress=false", "record.mcap=false"]),
                  tmp_path / "run")
    assert summary["status"] == "ok"
    broken = tmp_path / "broken.xml"
    broken.write_text(xml.read_text().replace('name="RL_foot"', 'name="RL_toe"'))
    with pytest.raises(ValueError, match="sphere geom RL_foot"):
        Built(compose_cfg([f"robot.plant_mjcf={broken}", "filter.enabled=false"]))
