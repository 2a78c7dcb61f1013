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
