"""Over-estimation judged per foot: the summary's ``estimator_overestimate_rate`` against an independent
recomputation from ``steps.parquet`` (each foot's estimate and the friction under it, the filter's planned
forces against the true cone), and the plan beyond the cone counted whatever the estimate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from taslel_bench.metrics.summary import foot_overestimates
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg


def test_foot_overestimates_counts_the_band_and_the_plan_beyond_the_cone() -> None:
    mu_hat = np.array([[0.2, 0.2, 0.31, 0.2]])
    mu_foot = np.array([[0.15, 0.3, 0.25, 0.2]])
    beyond = np.array([[True, False, False, False]])
    # foot 0: inside the band (0.2 <= 0.15 + 0.05) but planned beyond the cone; foot 2: 0.31 > 0.25 + 0.05
    assert foot_overestimates(mu_hat, mu_foot, beyond).tolist() == [[True, False, True, False]]


def _recomputed(steps: pd.DataFrame) -> float:
    """Loaded foot-ticks (plant: contact-frame normal force >= 1 N; filter: planned normal >= 1 N) whose
    estimate is over the friction under the foot by > 0.05 or whose planned force leaves the true cone (flat
    floor: the normal is world z)."""
    over, judged = [], []
    for leg in quad.LEGS:
        lam = steps[[f"{leg}_grf_filter_{ax}_w_n" for ax in "xyz"]].to_numpy()
        lam = np.nan_to_num(lam)
        mu = steps[f"{leg}_mu_foot"].to_numpy()
        filter_loaded = lam[:, 2] >= 1.0
        loaded = (steps[f"{leg}_contact_frame_fn_n"].to_numpy() >= 1.0) | filter_loaded
        beyond = filter_loaded & (np.hypot(lam[:, 0], lam[:, 1]) > mu * lam[:, 2] * (1 + 1e-6))
        over.append((steps[f"{leg}_mu_hat_foot"].to_numpy() > mu + 0.05) | beyond)
        judged.append(loaded)
    o, j = np.stack(over, 1), np.stack(judged, 1)
    return float(o[j].mean())


@pytest.mark.parametrize(("estimator", "over_min", "over_max"), [("fixed", 0.05, 1.0), ("oracle", 0.0, 0.0)])
def test_summary_rate_is_the_per_foot_recomputation(tmp_path: Path, estimator: str, over_min: float,
                                                    over_max: float) -> None:
    """mu = 0.15 under filter=terrain: the safe floor 0.2 is inside the 0.05 band, so the trunk rate is 0, yet
    it plans forces the ground cannot hold; the per-foot oracle never does."""
    cfg = compose_cfg(["filter=terrain", f"estimator={estimator}", "scenario=flat", "scenario.friction=0.15",
                       "duration=2.5", "record.mcap=false", "progress=false"])
    summary = run(cfg, tmp_path)
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    rate = summary["estimator_overestimate_rate"]
    assert rate == pytest.approx(_recomputed(steps), abs=1e-12)
    assert over_min <= rate <= over_max
    assert summary["estimator_overestimate_rate_trunk"] == 0.0


@pytest.mark.parametrize("estimator", ["oracle", "fixed", "slip_fixed", "fixed_lowest"])
def test_terrain_estimator_experiment_builds_each_of_its_estimators(estimator: str) -> None:
    """``+experiment=estimators_terrain`` runs filter=terrain with each estimator of its sweep, and
    ``slip_terrain_<model>`` puts a learned model under slip_fixed's caps."""
    from omegaconf import OmegaConf

    from taslel_bench.config.compose import CONF_DIR
    from taslel_bench.sim.build import Built

    sweep = OmegaConf.load(Path(CONF_DIR) / "experiment" / "estimators_terrain.yaml").hydra.sweeper.params
    assert estimator in str(sweep.estimator).split(",")
    cfg = compose_cfg(["+experiment=estimators_terrain", f"estimator={estimator}", "scenario=low_friction"])
    assert cfg.filter.friction_cone == "terrain"
    Built(cfg)
    learned = compose_cfg(["estimator=slip_terrain_mlp"]).estimator
    slip = compose_cfg(["estimator=slip_fixed"]).estimator
    assert learned.base.variant == "mlp" and learned.detector == slip.detector and learned.floor_mu == slip.floor_mu


def test_foot_time_to_safe_is_the_slowest_foot_and_chunk_invariant() -> None:
    """Foot 0 meets a new surface at tick 3 and is over-estimated until tick 6; foot 1 meets it at tick 4, safe at
    once; feet 2 and 3 stay on their surface. Fed whole or in chunks of 2: (6 - 3) ticks x dt."""
    from taslel_bench.metrics.summary import FootTimeToSafe

    n = 10
    mu = np.full((n, 4), 0.8)
    mu[3:, 0] = 0.2
    mu[4:, 1] = 0.2
    loaded = np.ones((n, 4), bool)
    loaded[5, 0] = False  # an unloaded tick does not count as safe
    over = np.zeros((n, 4), bool)
    over[3:6, 0] = True
    over[6, 0] = False
    values = []
    for step in (n, 2):
        f = FootTimeToSafe()
        for k in range(0, n, step):
            f.feed(mu[k : k + step], loaded[k : k + step], over[k : k + step], k)
        values.append(f.value(0.001))
    assert values == [pytest.approx(0.003), pytest.approx(0.003)]
    never = FootTimeToSafe()
    never.feed(mu, loaded, np.ones((n, 4), bool), 0)
    assert never.value(0.001) == np.inf
    same = FootTimeToSafe()
    same.feed(np.full((n, 4), 0.8), loaded, over, 0)
    assert np.isnan(same.value(0.001))


def test_summary_foot_time_to_safe_matches_steps_parquet(tmp_path: Path) -> None:
    """A drop 0.8 -> 0.2 under filter=terrain, the 0.2 floor with slip caps over a 0.3 base: the summary's
    per-foot time to safe against its recomputation from steps.parquet."""
    cfg = compose_cfg(["filter=terrain", "estimator=slip_fixed", "estimator.base.mu=0.3", "scenario=friction_patch",
                       "scenario.change_at_m=0.25", "duration=3.5", "record.mcap=false", "progress=false"])
    summary = run(cfg, tmp_path)
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    dt = float(steps["t_s"].iloc[1] - steps["t_s"].iloc[0])
    worst = -1.0
    for leg in quad.LEGS:
        lam = np.nan_to_num(steps[[f"{leg}_grf_filter_{ax}_w_n" for ax in "xyz"]].to_numpy())
        mu = steps[f"{leg}_mu_foot"].to_numpy()
        filter_loaded = lam[:, 2] >= 1.0
        loaded = (steps[f"{leg}_contact_frame_fn_n"].to_numpy() >= 1.0) | filter_loaded
        beyond = filter_loaded & (np.hypot(lam[:, 0], lam[:, 1]) > mu * lam[:, 2] * (1 + 1e-6))
        over = (steps[f"{leg}_mu_hat_foot"].to_numpy() > mu + 0.05) | beyond
        new = np.flatnonzero(loaded & (np.abs(mu - mu[0]) > 1e-9))
        if not len(new):
            continue
        ok = np.flatnonzero(loaded[new[0]:] & ~over[new[0]:])
        worst = max(worst, ok[0] * dt if len(ok) else np.inf)
    assert worst >= 0.0  # the front feet reach the patch in this run
    assert summary["estimator_time_to_safe_foot_s"] == pytest.approx(worst, abs=1e-12)
