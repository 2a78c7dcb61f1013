"""Per-foot friction estimates (foot tokens, per-foot heads and labels), the kinematic slip signal and the
slip floor of the in-loop estimator; tiny models and fast_dev_run training only."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

# the estimator modules import torch: they come after the skip
from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS  # noqa: E402
from estimators.models import ModelConfig, build_model, foot_kinematics, slip_features  # noqa: E402
from taslel_bench.interfaces import Proprioception  # noqa: E402

STAND_LEG = [0.0, 0.8, -1.6]  # [rad] hip, thigh, calf of a standing A1 leg


def _stand_sample(qd: np.ndarray | None = None) -> np.ndarray:
    s = np.zeros(N_FEATURES, np.float32)
    s[:12] = STAND_LEG * 4
    if qd is not None:
        s[12:24] = qd
    return s


@pytest.mark.parametrize(("variant", "tokens"), [("attention", "foot"), ("linformer", "foot"), ("mlp", "step")])
def test_per_foot_models_give_one_estimate_per_foot(variant: str, tokens: str) -> None:
    cfg = ModelConfig(variant=variant, tokens=tokens, d_model=16, linformer_k=8, mlp_hidden=[8], per_foot=True,
                      kinematic_features=True, slip_features=True, lower_quantile=0.1)
    model = build_model(cfg)
    mean, log_var, lower = model.predict(torch.randn(3, WINDOW_STEPS, N_FEATURES))
    assert mean.shape == log_var.shape == lower.shape == (3, 4) and (lower <= mean).all()
    assert model.cfg.n_estimates == 4 and model.cfg.per_foot


def test_foot_tokens_see_their_own_leg() -> None:
    """A change in one leg's joints moves the foot tokens of that leg only (before attention mixes them):
    the foot tokenisation gathers each leg's own features."""
    from estimators.models import foot_token_index

    cfg = ModelConfig(variant="attention", tokens="foot", kinematic_features=True, slip_features=True,
                      filter_mu_input=True).validate()
    idx = foot_token_index(cfg)
    assert idx.shape == (4, 9 + 6 + 2 + 2)
    assert set(idx[0, :9].tolist()) == {0, 1, 2, 12, 13, 14, 24, 25, 26}  # FL: q, qdot, tau of its joints
    assert idx[3, -1] == cfg.n_inputs - 1  # the filter features are shared by every foot
    with pytest.raises(ValueError, match="per_foot needs"):
        ModelConfig(variant="attention", tokens="step", per_foot=True).validate()


def test_slip_signal_from_leg_kinematics() -> None:
    """Standing still: no relative foot motion, every foot at the lowest height. FL's thigh swinging
    while the others hold: FL and its trot partner RR see FL's speed relative to RR; FR / RL see none."""
    still = slip_features(torch.from_numpy(_stand_sample()).reshape(1, 1, -1))[0, 0]
    assert torch.allclose(still, torch.zeros(8), atol=1e-5)
    qd = np.zeros(12, np.float32)
    qd[1] = 2.0  # [rad/s] FL thigh
    x = torch.from_numpy(_stand_sample(qd)).reshape(1, 1, -1)
    f = slip_features(x)[0, 0]
    v_fl = foot_kinematics(x)[0, 0, 12:15]
    assert float(f[0]) == pytest.approx(float(v_fl[:2].norm()), rel=1e-5) and float(f[0]) > 0.3
    assert float(f[3]) == pytest.approx(float(f[0]), rel=1e-6)  # RR: the same pair difference
    assert float(f[1]) == pytest.approx(0.0, abs=1e-6) and float(f[2]) == pytest.approx(0.0, abs=1e-6)


def test_fast_dev_run_trains_on_per_foot_labels(tmp_path: Path) -> None:
    pytest.importorskip("lightning")
    from estimators.data import WindowDataModule
    from estimators.train import make_config, train

    rng = np.random.default_rng(0)
    arrays = {}
    for split in ("train", "val", "test"):
        X = rng.normal(size=(32, WINDOW_STEPS, N_FEATURES)).astype(np.float32)
        arrays[split] = (X, rng.uniform(0.1, 1.2, (32, 4)).astype(np.float32))
    cfg = make_config(["estimator=attention", f"runs_dir={tmp_path}", "trainer.fast_dev_run=true", "threads=1",
                       "model.tokens=foot", "model.d_model=16", "model.slip_features=true",
                       "model.kinematic_features=true", "model.lower_quantile=0.1"])
    task, record = train(cfg, datamodule=WindowDataModule(arrays=arrays, batch_size=16))
    assert record["global_steps"] == 1 and task.model.cfg.per_foot


def test_per_foot_labels_load_from_collections(tmp_path: Path) -> None:
    """load_split(per_foot=True) reads y_foot; a collection without it (uniform floor) repeats y."""
    from estimators.data import load_split

    X = np.zeros((2, WINDOW_STEPS, N_FEATURES), np.float32)
    np.savez(tmp_path / "train.npz", X=X, y=np.array([0.5, 0.7], np.float32), episode=np.zeros(2, np.int32),
             y_foot=np.array([[0.5, 0.5, 0.2, 0.2], [0.7] * 4], np.float32))
    assert load_split(tmp_path, "train", per_foot=True)[1][0].tolist() == pytest.approx([0.5, 0.5, 0.2, 0.2])
    np.savez(tmp_path / "val.npz", X=X, y=np.array([0.3, 0.4], np.float32))
    np.testing.assert_allclose(load_split(tmp_path, "val", per_foot=True)[1], [[0.3] * 4, [0.4] * 4], rtol=1e-6)


def _obs(t: float, sample: np.ndarray) -> Proprioception:
    return Proprioception(t, sample[:12].astype(float), sample[12:24].astype(float), sample[24:].astype(float))


def test_learned_estimator_per_foot_output_and_slip_floor(tmp_path: Path) -> None:
    """A per-foot checkpoint reports mu_per_foot (4,) and mu = the lowest foot; a detected slip takes the
    slipping pair to at most the prior and possibly below mu_min (down to the slip floor), for hold_s."""
    from estimators.checkpoint import save_checkpoint
    from estimators.learned import LearnedEstimator

    model = build_model(ModelConfig(variant="attention", tokens="foot", d_model=16, slip_features=True)).eval()
    with torch.no_grad():  # a model whose raw mean is 0.6 on every foot: its head's bias only
        model.head.weight.zero_()
        model.head.bias.copy_(torch.tensor([0.0, -6.0]))
        model.norm.y_mean.fill_(0.6)
    save_checkpoint(model, tmp_path / "pf")
    kw = {"checkpoint": tmp_path / "pf", "prior_mu": 0.2, "conservative_k": 0.0, "mu_min": 0.2, "threads": None}
    est = LearnedEstimator("attention", slip={"floor_mu": 0.1, "speed_mps": 0.15, "hold_s": 0.1}, **kw)
    dt, still = 0.001, _stand_sample()
    ticks_to_full = round((WINDOW_STEPS - 1) * WINDOW_DT_S / dt)
    out = [est.step(_obs(k * dt, still)) for k in range(ticks_to_full + 1)][-1]
    assert out.ready and out.mu_per_foot.shape == (4,)
    assert out.mu_per_foot == pytest.approx([0.6] * 4, abs=1e-5) and out.mu == pytest.approx(0.6, abs=1e-5)
    qd = np.zeros(12, np.float32)
    qd[1] = 2.0  # FL's thigh moves while every foot is on the ground: FL-RR disagree
    t_slip = (ticks_to_full + 30) * dt
    out = est.step(_obs(t_slip, _stand_sample(qd)))
    assert est.slips_detected == 1
    assert out.mu_per_foot[[0, 3]] == pytest.approx([0.2, 0.2]) and out.mu_per_foot[[1, 2]] == pytest.approx([0.6] * 2)
    assert out.mu == pytest.approx(0.2)
    # hold_s later, without a new slip: back to the model's estimate
    late = [est.step(_obs(t_slip + k * dt, still)) for k in range(1, 200)][-1]
    assert late.mu_per_foot == pytest.approx([0.6] * 4, abs=1e-5)
    # a model bound below mu_min stays at mu_min unless the foot slips; then down to floor_mu
    with torch.no_grad():
        model.norm.y_mean.fill_(0.05)
    save_checkpoint(model, tmp_path / "pf_low")
    kw["checkpoint"] = tmp_path / "pf_low"
    est = LearnedEstimator("attention", slip={"floor_mu": 0.1, "hold_s": 0.1}, **kw)
    out = [est.step(_obs(k * dt, still)) for k in range(ticks_to_full + 1)][-1]
    assert out.mu_per_foot == pytest.approx([0.2] * 4)
    out = est.step(_obs((ticks_to_full + 30) * dt, _stand_sample(qd)))  # the model's bound is 0.05
    assert out.mu_per_foot[[0, 3]] == pytest.approx([0.1, 0.1]) and out.mu == pytest.approx(0.1)
    assert out.mu_per_foot[[1, 2]] == pytest.approx([0.2, 0.2])
    with pytest.raises(Exception, match="slip.floor_mu"):
        LearnedEstimator("attention", slip={"floor_mu": -0.1}, **kw)


def test_per_foot_inloop_scores() -> None:
    """foot_scores: over-estimation on loaded ticks only, time to safe from the first loaded tick on the
    new surface, NaN for a foot that never changed surface."""
    from studies.estimator_per_foot_inloop import foot_scores

    mu_foot = np.full((10, 4), 0.8)
    mu_foot[4:, 0] = 0.2  # FL steps onto 0.2 at tick 4
    loaded = np.ones((10, 4), bool)
    loaded[4, 0] = False  # ... and loads it at tick 5
    mu_hat = np.full((10, 4), 0.7)
    mu_hat[8:, 0] = 0.2  # safe again from tick 8
    slip = np.zeros((10, 4))
    slip[6, 0] = 0.5  # [m/s] FL slides on the new surface one tick
    s = foot_scores(mu_hat, mu_foot, loaded, 0.01, slip)
    assert s["time_to_safe_s"][0] == pytest.approx(0.03) and np.isnan(s["time_to_safe_s"][1])
    assert s["over_rate"][0] == pytest.approx(3 / 9) and s["over_rate"][1] == 0.0
    assert s["over_rate_new"][0] == pytest.approx(3 / 5) and np.isnan(s["over_rate_new"][1])  # ticks 5-9
    assert s["slide_new_m"][0] == pytest.approx(0.005) and np.isnan(s["slide_new_m"][1])
    # useful: mu_hat >= min(mu, 0.5) - 0.1; FL is useful from tick 5 (0.7 >= 0.1), the others never changed
    assert s["time_to_useful_s"][0] == pytest.approx(0.0) and np.isnan(s["time_to_useful_s"][1])
    rise = foot_scores(np.where(np.arange(10)[:, None] >= 7, 0.45, 0.2) * np.ones((1, 4)), 1.0 - mu_foot,
                       loaded, 0.01)  # FL: 0.2 -> 0.8 at tick 4, loaded from 5, useful (>= 0.4) from tick 7
    assert rise["time_to_useful_s"][0] == pytest.approx(0.02) and rise["time_to_safe_s"][0] == 0.0
    never = foot_scores(np.full((10, 4), 0.2), 1.0 - mu_foot, loaded, 0.01)
    assert never["time_to_useful_s"][0] == float("inf")
    # useful share over loaded ticks: FL 0.7 on 0.8 (ticks 0-3) and on 0.2 (5-9) -> all 9 useful; a floor of 0.2
    # on 0.8 is never useful (0.2 < 0.4), on 0.2 always (0.2 >= 0.1)
    assert s["useful_share"][0] == 1.0
    floor = foot_scores(np.full((10, 4), 0.2), mu_foot, loaded, 0.01, ready_from=5)
    assert floor["useful_share"][0] == pytest.approx(5 / 9) and floor["useful_share"][1] == 0.0
    assert floor["useful_ready"][0] == 1.0 and floor["useful_ready"][1] == 0.0  # from tick 5: FL on 0.2 only


def test_per_foot_inloop_summary_and_worlds() -> None:
    """The p95 over feet x seeds is an order statistic (an infinite time gives inf, not NaN); a world that
    names a scenario replaces the default drop, other worlds add to it."""
    from studies.estimator_per_foot_inloop import DEFAULT_WORLD, RUN, summarise, world_overrides

    nan, inf = float("nan"), float("inf")
    run = {"fell": False, "sliding_mps": 0.1, "over_rate": [0.0, 0.1, 0.0, 0.0], "over_rate_new": [0.0, 0.2, nan, nan],
           "time_to_safe_s": [0.1, inf, nan, nan], "time_to_useful_s": [0.0, 0.0, nan, nan],
           "useful_share": [1.0, 0.5, 1.0, 1.0], "useful_ready": [1.0] * 4, "slide_new_m": [0.01, 0.03, nan, nan]}
    s = summarise([run, {**run, "fell": True}])
    assert s["falls"] == 1 and s["feet_on_new_surface"] == 4
    assert s["time_to_safe_p95_s"] == inf and s["time_to_safe_max_s"] == inf
    assert s["over_rate_new_mean"] == pytest.approx(0.1) and s["slide_new_m_mean"] == pytest.approx(0.02)
    assert world_overrides("scenario=flat scenario.friction=0.3") == [*RUN, "scenario=flat", "scenario.friction=0.3"]
    assert world_overrides("scenario.friction=0.9") == [*DEFAULT_WORLD, "scenario.friction=0.9"]


def test_per_foot_inloop_paired_table() -> None:
    """--paired pools the files' runs and pairs them by seed: the mean difference, its interval (1.96 standard
    errors of the differences) and the pairs where the set is higher; a per-foot list counts as its feet's mean."""
    from studies.estimator_per_foot_inloop import paired_markdown

    def runs(values: list[float], slides: list[list[float]]) -> dict:
        pairs = enumerate(zip(values, slides, strict=True))
        return {"runs": [{"seed": s, "distance_m": v, "slide_new_m": sl} for s, (v, sl) in pairs]}

    nan = float("nan")
    ref = {"w/A": runs([1.0, 2.0, 3.0], [[0.1, nan], [0.2, 0.4], [0.3, 0.3]])}
    first = {"w/B": runs([1.5, 2.0], [[0.2, nan], [0.3, 0.3]])}
    later = {"w/B": {"runs": [{"seed": 2, "distance_m": 4.5, "slide_new_m": [0.3, 0.3]}]}}  # a second file's seed
    row = paired_markdown([ref, first, later], "A", "B").splitlines()[-1].split(" | ")
    d = np.array([0.5, 0.0, 1.5])
    assert row[1] == "3"  # three pairs: the later file's seed 2 joined the first file's seeds 0-1
    assert row[-1].startswith(f"2 / {d.mean():+.2f} ± {1.96 * d.std(ddof=1) / np.sqrt(3):.2g} / 2")
    assert row[2].startswith("0.2333 / +0.0333 ± ")  # the slides' foot means: A 0.1, 0.3, 0.3; B 0.2, 0.3, 0.3


def test_per_foot_offline_scores() -> None:
    """studies.estimator_per_foot_offline.score: MAE per foot and on loaded feet, over-estimation of the
    mean and the lower head, the lowest foot against the trunk label; a single output serves all feet."""
    from studies.estimator_per_foot_offline import per_foot, score

    y_foot = np.array([[0.8, 0.8, 0.2, 0.2], [0.5, 0.5, 0.5, 0.5]])
    mean = np.array([[0.8, 0.7, 0.4, 0.2], [0.5, 0.5, 0.5, 0.6]])
    loaded = np.array([[True, False, True, False], [True, True, True, True]])
    s = score(mean, mean - 0.1, y_foot, loaded, np.array([0.8, 0.5]))
    assert s["mae_foot"] == pytest.approx(0.4 / 8)
    assert s["mae_loaded"] == pytest.approx(0.3 / 6)
    assert s["over_mean"] == pytest.approx(2 / 8) and s["over_lower"] == pytest.approx(1 / 8)
    assert s["mae_lowest_vs_trunk"] == pytest.approx(0.6 / 2)  # |0.2 - 0.8| and |0.5 - 0.5|
    assert s["over_lowest_vs_trunk"] == 0.0  # lowest feet 0.2 (trunk 0.8) and 0.5 (0.5)
    s = score(mean, mean - 0.1, y_foot, loaded, np.array([0.1, 0.3]))
    assert s["over_lowest_vs_trunk"] == pytest.approx(1.0)  # 0.2 > 0.1 + 0.05, 0.5 > 0.3 + 0.05
    assert s["over_lower_lowest_vs_trunk"] == pytest.approx(0.5)  # lower 0.1 vs 0.1: no; 0.4 vs 0.3: yes
    assert per_foot(np.array([0.3, 0.4]), 2).tolist() == [[0.3] * 4, [0.4] * 4]
    assert per_foot(None, 2) is None
