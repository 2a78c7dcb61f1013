"""Model mismatch is measured: the controller model's residual against what the plant did is ~0 when the
plant is the URDF, grows with each injected mismatch and vanishes again when the model is told; alarms
degrade such runs; the robust option tightens the rows it says it tightens."""

from __future__ import annotations

import numpy as np
import pytest

from taslel_bench.filter.robust import DisturbanceObserver, RobustMargin, RobustSettings
from taslel_bench.metrics.health import HealthLimits
from taslel_bench.metrics.residuals import residual_metrics
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg

PLANT = ["scenario=perturbed", "scenario.joint_damping=0", "scenario.joint_frictionloss=0",
         "scenario.motor_strength_scale=1.0", "scenario.actuator_delay_steps=0"]  # fmt: skip


def residual_summary(tmp_path, *overrides: str) -> dict:
    return run(compose_cfg(["duration=0.8", "progress=false", "record.mcap=false", *PLANT, *overrides]), tmp_path)


@pytest.mark.parametrize("filter_on", [True, False])
def test_residual_is_zero_when_the_plant_is_the_urdf(tmp_path, filter_on):
    s = residual_summary(tmp_path, f"filter.enabled={str(filter_on).lower()}")
    assert s["residual_trunk_force_n_rms"] < 1e-9 and s["residual_trunk_torque_nm_rms"] < 1e-9
    assert s["residual_joint_nm_rms"] < 1e-9 and s["residual_alarm_rate"] == 0.0 and s["status"] == "ok"


@pytest.mark.parametrize(
    ("plant", "group", "at_least"),
    [
        ("scenario.joint_damping=1.5", "residual_joint_nm_rms", 2.0),
        ("scenario.armature=0.01", "residual_joint_nm_rms", 0.5),
        ("scenario.joint_frictionloss=0.2", "residual_joint_nm_rms", 0.1),
        ("scenario.trunk_mass_scale=0.724", "residual_trunk_force_n_rms", 5.0),
        ("scenario.trunk_com_shift_m=[0.02,0,0]", "residual_trunk_torque_nm_rms", 0.5),
        ("scenario.motor_strength_scale=0.8", "residual_joint_nm_rms", 1.0),
    ],
)
def test_residual_grows_with_each_injected_mismatch(tmp_path, plant, group, at_least):
    s = residual_summary(tmp_path, plant)
    assert s[group] > at_least


@pytest.mark.parametrize(
    ("plant", "model"),
    [
        (["scenario.armature=0.01"], ["model.armature=0.01"]),
        (["scenario.joint_damping=1.5"], ["model.joint_damping=1.5", "model.implicit_damping_dt_s=0.001"]),
        (["scenario.trunk_mass_scale=0.724", "scenario.trunk_com_shift_m=[0.02,0,0]"],
         ["model.trunk_mass_scale=0.724", "model.trunk_com_shift_m=[0.02,0,0]"]),
    ],
)
def test_residual_vanishes_when_the_model_is_told(tmp_path, plant, model):
    s = residual_summary(tmp_path, *plant, *model)
    assert max(s["residual_trunk_force_n_rms"], s["residual_trunk_torque_nm_rms"], s["residual_joint_nm_rms"]) < 1e-8


def test_unknown_damping_is_a_model_error_not_a_broken_guarantee(tmp_path):
    """The residual alarm is model error (model_error_reasons, an alarm event); the run degrades only where the
    filter's guarantee broke, or with health.model_error_degrades=true (the rule before the guarantee checks)."""
    s = residual_summary(tmp_path, "scenario.joint_damping=1.5")
    assert s["residual_alarm_rate"] > 0.5 and "residual_alarm_rate" in s["model_error_reasons"]
    assert s["status"] == "ok" and "residual_alarm_rate" not in s["degraded_reasons"]
    events = (tmp_path / "events.json").read_text()
    assert '"kind": "alarm"' in events and "model residual" in events
    s = residual_summary(tmp_path / "degrades", "scenario.joint_damping=1.5", "health.model_error_degrades=true")
    assert s["status"] == "degraded" and "residual_alarm_rate" in s["degraded_reasons"]


def test_residual_metrics_are_absent_before_the_residuals_are_computed():
    built = Built(compose_cfg(["duration=0.05", "progress=false", "filter.enabled=false"]))
    trace = built.episode.run().trace
    trace.model_residual = np.zeros((0, 18))  # as if the computation had failed
    assert residual_metrics(trace, 0, HealthLimits()) == {}


class _Row:
    """A barrier family's arrays for one foot (what RobustMargin reads)."""

    def __init__(self) -> None:
        self.h_e = np.full(4, np.nan)
        self.psi_planned = np.full(4, np.nan)


def test_adaptive_margin_grows_with_the_realised_shortfall_only():
    settings = RobustSettings(enabled=True, ecbf_margin_mps2=1.0, adaptive_gain=2.0, adaptive_time_constant_s=0.01,
                              max_margin_mps2=30.0)  # fmt: skip
    margin, row = RobustMargin(settings, alpha2=20.0, control_dt_s=1e-3), _Row()
    assert margin.ecbf_margin_mps2 == 1.0
    for _ in range(200):  # the foot's condition was planned 10 m/s² above what it realises
        row.h_e[0], row.psi_planned[0] = 0.0, 10.0
        margin.remember([row])
        margin.observe([row])  # h_e did not change: psi_realised = 0
    assert margin.ecbf_margin_mps2 == pytest.approx(1.0 + 2.0 * 10.0, rel=1e-3)
    for _ in range(200):  # realised better than planned: no shortfall, the running RMS decays
        row.psi_planned[0] = -5.0
        margin.remember([row])
        margin.observe([row])
    assert margin.ecbf_margin_mps2 < 1.01
    assert RobustMargin(RobustSettings(enabled=False, ecbf_margin_mps2=5.0), 20.0, 1e-3).ecbf_margin_mps2 == 0.0


def test_disturbance_observer_learns_a_swing_leg_torque_and_applies_it_only_in_swing():
    """Joint 0 (FL hip) gets an extra -3 N·m the model does not know: while FL swings the estimate converges
    to it; over stance ticks it is neither updated (contact-plan errors) nor applied."""
    obs, dt = DisturbanceObserver(0.005, 1e-3, 18), 1e-3
    mass, h, u, v = np.eye(18), np.zeros(18), np.zeros(12), np.zeros(18)
    extra = np.r_[np.zeros(6), -3.0, np.zeros(11)]
    swing_fl = np.array([False, True, True, True])
    for _ in range(100):
        obs.remember(v, mass, h, u, np.zeros(18), swing_fl)
        v = v + dt * (extra + np.r_[np.zeros(6), 0.0, 50.0, np.zeros(10)])  # FL thigh row: stance-like noise
        obs.update(v, swing_fl)
    assert obs.d_hat[6] == pytest.approx(-3.0, rel=1e-3)
    assert obs.d_hat[7] == pytest.approx(50.0, rel=1e-3)  # same leg (FL swings): its thigh row is learnt too
    assert np.abs(obs.d_hat[9:]).max() == 0.0  # stance legs: nothing applied
    all_stance = np.ones(4, bool)
    obs.remember(v, mass, h, u, np.zeros(18), all_stance)
    obs.update(v + dt * 100.0, all_stance)
    assert obs.estimate[6] == pytest.approx(-3.0, rel=1e-3) and np.all(obs.d_hat == 0.0)


def test_robust_option_tightens_the_ecbf_rows_by_its_margin():
    base = ["scenario=obstacle", "duration=0.8", "progress=false", "record.mcap=false"]
    plain = Built(compose_cfg(base)).episode.run().trace
    fixed = Built(compose_cfg([*base, "filter.robust.enabled=true", "filter.robust.ecbf_margin_mps2=30"]))
    tight = fixed.episode.run().trace
    assert np.all(plain.ecbf_margin_mps2[: plain.n] == 0.0) and np.all(tight.ecbf_margin_mps2[: tight.n] == 30.0)
    # the planned condition of every swing foot the QP solved is >= the margin
    psi = tight.barriers["clearance"].psi_planned_mps2[: tight.n]
    assert np.nanmin(psi) >= 30.0 - 1e-6
    assert np.nanmin(plain.barriers["clearance"].psi_planned_mps2[: plain.n]) < 30.0


@pytest.mark.parametrize("case", ["none", "damping", "armature", "frictionloss", "mass", "com", "lossy", "combined"])
def test_mismatch_preset_cases_compose_and_the_matched_model_copies_the_plant(case):
    plant_fields = ("joint_damping", "armature", "joint_frictionloss", "trunk_mass_scale", "trunk_com_shift_m")
    nominal = compose_cfg(["+experiment=mismatch", f"+mismatch_plant={case}", "+mismatch_filter=nominal"])
    matched = compose_cfg(["+experiment=mismatch", f"+mismatch_plant={case}", "+mismatch_filter=matched"])
    assert list(nominal.scenario.coefficients) == [0.0, 0.0, 1.28, -2.56, 1.28]
    perturbed = {k: nominal.scenario[k] for k in plant_fields}
    assert (case == "none") == (perturbed == {"joint_damping": 0.0, "armature": 0.0, "joint_frictionloss": 0.0,
                                              "trunk_mass_scale": 1.0, "trunk_com_shift_m": [0.0, 0.0, 0.0]})
    for key in plant_fields:
        assert matched.model[key] == matched.scenario[key] and nominal.model[key] in (0.0, 1.0, [0.0, 0.0, 0.0])
    assert matched.model.implicit_damping_dt_s == pytest.approx(1.0 / matched.physics_rate_hz)
