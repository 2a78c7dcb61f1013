"""Closed loop: short episodes through the real config tree, faults, falls and bad input."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pandas as pd
import pytest
from hydra.errors import ConfigCompositionException, MissingConfigException
from omegaconf import OmegaConf

from taslel_bench.config.validate import ConfigError, validate
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg


def short(*extra: str) -> list[str]:
    return ["duration=1.0", "progress=false", "record.mcap=false", *extra]


def test_short_walk_writes_run_folder(tmp_path):
    cfg = compose_cfg(short("filter.enabled=false"))
    summary = run(cfg, tmp_path, {"scenario": "flat"})
    assert summary["status"] == "ok" and summary["fell"] is False
    assert summary["mean_speed_mps"] > 0.1
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    for key in ("fell", "time_to_fall_s", "status", "distance_m", "mean_speed_mps", "tick_us_median",
                "real_time_factor"):
        assert key in on_disk
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    assert len(steps) == summary["ticks"] == 1500  # 0.5 s stand + 1.0 s walk at 1 kHz
    assert steps["t_s"].dtype == np.float64 and steps["FL_stance"].dtype == bool
    assert np.allclose(np.diff(steps["t_s"]), 1e-3)
    # nominal only: no model or filter work in the tick
    assert (steps["tick_model_us"] == 0).all() and (steps["tick_filter_us"] == 0).all()


def test_rerun_skips_completed_and_force_reruns(tmp_path):
    cfg = compose_cfg(short("filter.enabled=false", "duration=0.2"))
    first = run(cfg, tmp_path)
    again = run(cfg, tmp_path)
    assert again.get("skipped") is True and again["ticks"] == first["ticks"]
    forced = run(compose_cfg(short("filter.enabled=false", "duration=0.2", "force=true")), tmp_path)
    assert "skipped" not in forced


def test_control_rate_below_physics_rate(tmp_path):
    cfg = compose_cfg(short("filter.enabled=false", "control_rate_hz=500", "duration=0.5"))
    summary = run(cfg, tmp_path)
    assert summary["ticks"] == 500 and summary["status"] == "ok"


def test_no_gains_falls_with_time_to_fall(tmp_path):
    cfg = compose_cfg(short("filter.enabled=false", "controller.kp=0", "controller.kd=0", "duration=2"))
    summary = run(cfg, tmp_path)
    assert summary["fell"] is True and 0 < summary["time_to_fall_s"] < 2.5
    assert summary["status"] == "ok"
    events = json.loads((tmp_path / "events.json").read_text())
    assert any(e["kind"] == "fall" for e in events)


def test_nan_state_ends_with_error_not_crash(tmp_path):
    cfg = compose_cfg(short("filter.enabled=false"))
    built = Built(cfg)

    def poison(model, data, t):
        if t >= 0.3:
            data.qvel[0] = np.nan

    built.scenario.on_tick = poison
    res = built.episode.run()
    assert res.status == "error" and "non-finite" in res.message
    assert abs(res.trace.n * 1e-3 - 0.301) < 2e-3


def test_exception_in_episode_is_recorded(tmp_path):
    cfg = compose_cfg(short("filter.enabled=false"))
    built = Built(cfg)

    def explode(model, data, t):
        if t >= 0.2:
            raise RuntimeError("scenario exploded")

    built.scenario.on_tick = explode
    res = built.episode.run()
    assert res.status == "error" and "scenario exploded" in res.message and "traceback" in res.extras


def test_filter_in_the_loop_short(tmp_path):
    cfg = compose_cfg(short("solver=daqp"))
    summary = run(cfg, tmp_path, {"solver": "daqp"})
    assert summary["status"] == "ok" and not summary["fell"]
    assert summary["qp_failed_rate"] == 0.0 and summary["qp_solves"] == summary["ticks"]
    assert summary["grf_mae_z_n_stance"] < 3.0  # the stance set; over every loaded contact it is larger
    # the tick's parts, timed in the loop, add up to the tick; the filter part contains build + solve
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    parts = steps[["tick_controller_us", "tick_model_us", "tick_filter_us", "tick_physics_us"]].to_numpy()
    assert np.all(parts > 0.0)
    assert np.allclose(parts.sum(axis=1), steps["tick_us"], rtol=1e-9, atol=1e-6)
    assert np.all(steps["tick_filter_us"] >= steps["qp_build_us"] + steps["qp_solve_us"] - 1e-6)


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("duration=-1", "duration"),
        ("scenario.friction=0", "scenario.friction"),
        ("control_rate_hz=300", "control_rate_hz"),
        ("controller.duty=1.5", "controller.duty"),
        ("filter.fallback=pray", "filter.fallback"),
        ("controller.stand_height=0.6", "controller.stand_height"),
    ],
)
def test_bad_values_are_refused_naming_the_field(override, field):
    cfg = compose_cfg([override])
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        validate(cfg)


def test_bad_value_refused_before_simulating(tmp_path):
    cfg = compose_cfg(["duration=-1"])
    with pytest.raises(ConfigError):
        run(cfg, tmp_path)
    assert not (tmp_path / "steps.parquet").exists()


def test_unknown_group_option_lists_valid_ones():
    with pytest.raises((MissingConfigException, ConfigCompositionException)) as err:
        compose_cfg(["scenario=moon"])
    assert "flat" in str(err.value) and "low_friction" in str(err.value)


def test_friction_check_catches_misconfigured_floor():
    """A scenario that claims mu = 0.3 but leaves the feet on the default 1.0 floor is refused."""
    cfg = compose_cfg(["scenario=low_friction", "scenario.friction=0.3"])
    from scenarios.flat import FlatGround
    from taslel_bench.interfaces import Plane, Terrain

    class LiarPlane(Plane):
        def add_to(self, spec, body, name, rng):  # forgets to set the floor friction
            return None

    class Liar(FlatGround):
        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.terrain = Terrain((LiarPlane(self.friction),))

    OmegaConf.set_struct(cfg, False)
    cfg.scenario["_target_"] = f"{__name__}.LiarForTest"
    globals()["LiarForTest"] = Liar
    from taslel_bench.sim.build import FrictionMismatch

    with pytest.raises(FrictionMismatch, match="0.3"):
        Built(cfg)


def test_plant_gets_configured_friction():
    built = Built(compose_cfg(["scenario=low_friction", "scenario.friction=0.35", "filter.enabled=false"]))
    assert built.friction_checked and all(abs(p - 0.35) < 1e-12 for _, p, _ in built.friction_checked)
    assert built.mj_model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_flat_trot_10s_no_fall(tmp_path, seed):
    """Issue bar: flat ground, 0.4 m/s commanded, 10 s, filter off -> no fall, >= 0.25 m/s."""
    cfg = compose_cfg(["duration=10", "progress=false", "record.mcap=false", "filter.enabled=false",
                       "controller.speed=0.4", f"seed={seed}"])
    summary = run(cfg, tmp_path)
    assert summary["status"] == "ok" and summary["fell"] is False
    assert summary["mean_speed_mps"] >= 0.25


def test_settle_time_after_friction_change():
    from taslel_bench.metrics.summary import settle_time

    t = np.arange(0, 2, 0.01)
    mu = np.where(t < 1.0, 0.8, 0.2)
    hat = np.where(t < 1.3, 0.8, 0.21)  # reacts 0.3 s after the change
    assert settle_time(t, mu, hat) == pytest.approx(0.3, abs=0.011)
    assert np.isnan(settle_time(t, np.full_like(t, 0.5), np.full_like(t, 0.5)))
    assert settle_time(t, mu, np.full_like(t, 0.8)) == np.inf


def test_one_sided_estimator_metrics_startup_and_time_to_safe():
    from taslel_bench.metrics.summary import estimator_safety_metrics, time_to_safe

    t = np.arange(0, 2, 0.01)
    mu = np.where(t < 1.0, 0.8, 0.2)
    ready = t >= 0.5  # prior for the first 0.5 s
    hat = np.where(t < 0.5, 0.5, np.where(t < 1.3, 0.6, 0.18))  # over on the 0.2 floor until 1.3 s
    m = estimator_safety_metrics(t, mu, hat, ready)
    assert m["estimator_startup_s"] == pytest.approx(0.5)
    assert m["estimator_startup_overestimate_rate"] == 0.0  # 0.5 under 0.8
    assert m["estimator_low_overestimate_rate"] == pytest.approx(0.3)  # 30 of the 100 ticks on 0.2
    assert m["estimator_time_to_safe_s"] == pytest.approx(0.3, abs=0.011)
    assert m["estimator_useful_rate"] == 1.0  # 0.6 >= 0.5 - 0.1 on 0.8, 0.18 >= 0.2 - 0.1 on 0.2
    assert m["estimator_notready_after_startup_s"] == 0.0
    assert np.isnan(time_to_safe(t, np.full_like(t, 0.2), hat))  # no drop
    assert time_to_safe(t, mu, np.full_like(t, 0.8)) == np.inf
    always = estimator_safety_metrics(t, mu, np.full_like(t, 0.2), np.ones_like(t, bool))
    assert always["estimator_startup_s"] == 0.0 and np.isnan(always["estimator_startup_overestimate_rate"])
    assert always["estimator_useful_rate"] == pytest.approx(0.0 + 0.5)  # 0.2 < 0.4 on 0.8; useful on 0.2


class _RecordingEstimator:
    """A fixed estimate that changes every tick (so a stale value would show) and keeps what it was given."""

    name = "recording"

    def __init__(self) -> None:
        self.seen: list[tuple[float, float]] = []  # (t [s], obs.filter_mu [-])
        self.reported: list[float] = []

    def reset(self) -> None:
        self.seen.clear()
        self.reported.clear()

    def step(self, obs):
        from taslel_bench.interfaces import FrictionEstimate

        self.seen.append((obs.t_s, obs.filter_mu))
        mu = 0.6 + 0.1 * (len(self.seen) % 3)
        self.reported.append(mu)
        return FrictionEstimate(mu=mu)


@pytest.mark.parametrize("filter_on", [True, False])
def test_estimator_sees_the_mu_the_filter_used_on_the_previous_tick(filter_on):
    """Proprioception.filter_mu at tick k is the mu the filter got at tick k - 1 (the tick whose torque
    tau_joints holds); NaN on the first tick, before filter.start_time and without a filter."""
    over = ["solver=daqp", "filter.start_time=0.1"] if filter_on else ["filter.enabled=false"]
    built = Built(compose_cfg(short("duration=0.1", *over)))
    est = _RecordingEstimator()
    built.episode.estimator = est
    res = built.episode.run()
    assert res.status == "ok"
    t = np.array([s[0] for s in est.seen])
    seen = np.array([s[1] for s in est.seen])
    assert len(seen) > 200 and np.isnan(seen[0])
    if not filter_on:
        assert np.isnan(seen).all()
        return
    start = 0.1
    before = t <= start + 1e-9  # tick k sees tick k-1: the first filtered tick (t = 0.1) is seen at 0.101
    assert np.isnan(seen[before]).all()
    np.testing.assert_array_equal(seen[~before], np.array(est.reported)[:-1][~before[1:]])


def test_does_nothing_tells_empty_hooks_from_working_ones():
    from taslel_bench.sim.episode import does_nothing

    def empty(model, data, t):
        """Only a docstring."""

    def returns_none(model, data, t):
        return None

    def works(model, data, t):
        data.qvel[0] = 0.0

    def returns_value(model, data, t):
        return 1

    assert does_nothing(empty) and does_nothing(returns_none)
    assert not does_nothing(works) and not does_nothing(returns_value) and not does_nothing(print)

