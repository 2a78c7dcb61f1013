"""Terrain estimators: oracle/fixed, window layout, collection, models, training, checkpoints, in-loop use.

torch-dependent tests skip when the ``learn`` extra is missing. Total runtime is a few seconds.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS, to_joint_tokens
from estimators.metrics import regression_metrics
from estimators.simple import FixedEstimator, OracleEstimator
from taslel_bench.interfaces import Estimator, GroundTruth, Proprioception

CONF = Path(__file__).resolve().parents[1] / "conf" / "estimator"


def _obs(t: float, rng: np.random.Generator | None = None) -> Proprioception:
    rng = rng or np.random.default_rng(0)
    return Proprioception(t, rng.normal(size=12), rng.normal(size=12), rng.normal(size=12) * 5)


def _tiny_data(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Windows whose mean torque depends on the label (a learnable toy problem)."""
    rng = np.random.default_rng(seed)
    y = rng.uniform(0.1, 1.2, n).astype(np.float32)
    X = rng.normal(size=(n, WINDOW_STEPS, N_FEATURES)).astype(np.float32)
    X[:, :, 24:] += 3.0 * y[:, None, None]
    return X, y


# ---------------------------------------------------------------------------------------- no torch


def test_oracle_returns_true_friction() -> None:
    est = OracleEstimator()
    assert isinstance(est, Estimator) and est.reads_ground_truth
    e = est.step(_obs(0.0), GroundTruth(0.37))
    assert (e.mu, e.sigma, e.ready, e.mu_per_foot) == (0.37, 0.0, True, None)
    feet = np.array([0.3, 0.4, 0.5, 0.6])
    assert est.step(_obs(0.0), GroundTruth(0.37, feet)).mu_per_foot is feet


def test_only_the_oracle_reads_the_ground_truth() -> None:
    """What only the simulator knows is not part of what a robot measures: the loop hands the truth to an
    estimator that declares it reads it, and to no other."""
    assert not hasattr(Proprioception(0.0, np.zeros(12), np.zeros(12), np.zeros(12)), "true_friction")
    with pytest.raises(TypeError):  # a friction where the measurements end is refused, not taken as filter_mu
        Proprioception(0.0, np.zeros(12), np.zeros(12), np.zeros(12), 0.5)
    assert not getattr(FixedEstimator(), "reads_ground_truth", False)


def test_fixed_returns_constant_and_rejects_bad_mu() -> None:
    est = FixedEstimator(0.42)
    assert isinstance(est, Estimator)
    assert [est.step(_obs(t)).mu for t in (0.0, 1.0)] == [0.42, 0.42]
    with pytest.raises(ValueError, match="positive"):
        FixedEstimator(-0.1)


def test_simple_configs_instantiate() -> None:
    from hydra.utils import instantiate

    assert instantiate(OmegaConf.load(CONF / "oracle.yaml")).name == "oracle"
    from estimators.simple import SAFE_FLOOR_MU

    # the fixed baseline is the safe floor by default (never over-estimates a floor the deployment handles)
    assert instantiate(OmegaConf.load(CONF / "fixed.yaml")).mu == SAFE_FLOOR_MU == FixedEstimator().mu == 0.2


def test_joint_tokens_layout() -> None:
    w = np.arange(2 * 40 * 36, dtype=np.float32).reshape(2, 40, 36)
    tok = to_joint_tokens(w)
    assert tok.shape == (2, 480, 3)
    # token (t=3, joint=5) holds q, qdot, tau of joint 5 at step 3
    np.testing.assert_array_equal(tok[1, 3 * 12 + 5], w[1, 3, [5, 17, 29]])


def test_metrics_numbers() -> None:
    y = np.array([0.2, 0.4, 0.6, 0.8])
    m = regression_metrics(y, y + np.array([0.1, -0.1, 0.0, 0.02]), sigma=np.full(4, 0.05))
    assert m["mae"] == pytest.approx(0.055)
    assert m["bias"] == pytest.approx(0.005)
    assert m["overestimate_rate"] == pytest.approx(0.25)
    assert m["within_1sigma"] == pytest.approx(0.5)


def test_collect_short_episode() -> None:
    from estimators.collect import EpisodeConfig, run_episode
    from estimators.randomisation import TRAIN_RANGES, draw

    p = draw(np.random.default_rng(1), TRAIN_RANGES, seed=1)
    r = run_episode(p, EpisodeConfig(duration_s=1.6, stride=2))
    assert r.steps == 1600 and not r.fell
    # samples 0..53; windows start at sample 10 and need 40 samples: starts 10, 12, 14
    assert r.windows.shape == (3, WINDOW_STEPS, N_FEATURES)
    assert np.isfinite(r.windows).all()


def test_collect_with_filter_in_the_loop(tmp_path: Path) -> None:
    """Filter-in-the-loop episodes run through taslel_bench.api, change the torques the windows hold, and
    are flagged per episode and per window; the plant draws do not depend on filter_fraction."""
    from estimators.collect import EpisodeConfig, collect, run_episode
    from estimators.randomisation import TRAIN_RANGES, draw

    p = draw(np.random.default_rng(1), TRAIN_RANGES, seed=1)
    cfg = EpisodeConfig(duration_s=1.6, stride=2)
    nominal, filtered = run_episode(p, cfg), run_episode(p, cfg, filtered=True)
    assert filtered.filtered and not nominal.filtered and not filtered.fell
    assert filtered.windows.shape == nominal.windows.shape
    assert not np.allclose(filtered.windows[..., 24:], nominal.windows[..., 24:])

    cfg = EpisodeConfig(duration_s=1.4, stride=8)
    man = collect(tmp_path / "a", {"train": 3}, seed=2, workers=1, cfg=cfg, filter_fraction=1.0,
                  filter_mu_scale=(0.5, 0.9))
    assert man["splits"]["train"]["episodes_filtered"] == 3  # type: ignore[index]
    collect(tmp_path / "b", {"train": 3}, seed=2, workers=1, cfg=cfg, filter_fraction=0.0)
    with np.load(tmp_path / "a" / "train.npz") as a, np.load(tmp_path / "b" / "train.npz") as b:
        assert a["filtered"].all() and a["window_filtered"].all() and not b["filtered"].any()
        friction = a["params"][:, list(a["param_columns"]).index("friction")]
        assert np.all((a["filter_mu"] >= 0.5 * friction) & (a["filter_mu"] <= 0.9 * friction))
        assert np.isnan(b["filter_mu"]).all()
        np.testing.assert_array_equal(a["params"], b["params"])
        np.testing.assert_array_equal(a["X"][..., :24].shape, b["X"][..., :24].shape)



def test_merge_concatenates_training_splits(tmp_path: Path) -> None:
    """merge: training windows and filter flags of both collections, unique episode ids, the base's
    other splits linked; equal seeds are refused."""
    from estimators.collect import EpisodeConfig, collect
    from estimators.merge import merge

    cfg = EpisodeConfig(duration_s=1.6, stride=4)
    collect(tmp_path / "a", {"train": 2, "test": 1}, seed=3, workers=1, cfg=cfg, filter_fraction=0.5)
    collect(tmp_path / "b", {"train": 2}, seed=4, workers=1, cfg=cfg, filter_fraction=0.5, plant_beta=0.4)
    man = merge(tmp_path / "m", tmp_path / "a", [tmp_path / "b"])
    assert man["splits"]["train"]["episodes"] == 4  # type: ignore[index]
    assert [(s["seed"], s["plant_beta"], s["train_episodes"]) for s in man["sources"]] == [(3, 1.0, 2), (4, 0.4, 2)]
    with np.load(tmp_path / "m" / "train.npz") as m, np.load(tmp_path / "a" / "train.npz") as a:
        assert len(np.unique(m["episode"])) == 4 and len(m["filtered"]) == 4 and len(m["filter_mu"]) == 4
        assert len(m["window_filtered"]) == len(m["X"]) == 2 * len(a["X"])
        np.testing.assert_array_equal(m["X"][: len(a["X"])], a["X"])
    assert (tmp_path / "m" / "test.npz").resolve() == (tmp_path / "a" / "test.npz").resolve()
    with pytest.raises(ValueError, match="distinct seeds"):
        merge(tmp_path / "m2", tmp_path / "a", [tmp_path / "a"])

# ------------------------------------------------------------------------------------------- torch


@pytest.mark.parametrize("variant", ["mlp", "attention", "linformer"])
@pytest.mark.parametrize("tokens", ["joint", "step"])
@pytest.mark.parametrize("pooling", ["mean", "cls"])
def test_model_shapes(variant: str, tokens: str, pooling: str) -> None:
    torch = pytest.importorskip("torch")
    from estimators.models import ModelConfig, build_model

    cfg = ModelConfig(variant=variant, tokens=tokens, pooling=pooling, d_model=16, linformer_k=8)
    model = build_model(cfg)
    mean, log_var = model(torch.randn(5, 40, 36))
    assert mean.shape == (5,) and log_var.shape == (5,)
    assert torch.isfinite(mean).all() and torch.isfinite(log_var).all()
    if variant != "mlp":
        assert model.tokens(torch.randn(5, 40, 36)).shape == (5, cfg.n_tokens, 16)
        assert cfg.n_tokens == (480 if tokens == "joint" else 40) + (pooling == "cls")


def test_model_rejects_unknown_variant_and_bad_shape() -> None:
    torch = pytest.importorskip("torch")
    from estimators.models import ModelConfig, build_model

    with pytest.raises(ValueError, match="valid choices: mlp, attention, linformer"):
        build_model(ModelConfig(variant="rnn"))
    with pytest.raises(ValueError, match="expected windows"):
        build_model(ModelConfig(variant="mlp"))(torch.randn(2, 30, 36))


def test_fast_dev_run_training(tmp_path: Path) -> None:
    pytest.importorskip("lightning")
    from estimators.data import WindowDataModule
    from estimators.train import make_config, train

    arrays = {s: _tiny_data(32, i) for i, s in enumerate(("train", "val", "test"))}
    dm = WindowDataModule(arrays=arrays, batch_size=16)
    cfg = make_config(["estimator=linformer", f"runs_dir={tmp_path}", "trainer.fast_dev_run=true",
                       "model.d_model=16", "model.linformer_k=8", "threads=1"])
    task, record = train(cfg, datamodule=dm)
    assert record["global_steps"] == 1
    # normalisation statistics were fitted on the training windows and live in the model
    assert float(task.model.norm.y_mean) == pytest.approx(float(arrays["train"][1].mean()), rel=1e-5)


def test_lower_quantile_head_and_time_cosine_schedule(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("lightning")
    from estimators.data import WindowDataModule
    from estimators.models import ModelConfig, build_model
    from estimators.train import make_config, pinball, train

    for variant in ("mlp", "linformer"):
        model = build_model(ModelConfig(variant=variant, tokens="step", d_model=16, linformer_k=8,
                                        mlp_hidden=[8], lower_quantile=0.1))
        mean, _log_var, lower = model.predict(torch.randn(4, 40, 36))
        assert lower is not None and lower.shape == (4,) and (lower <= mean).all()
        assert model(torch.randn(4, 40, 36))[0].shape == (4,)
    assert build_model(ModelConfig(variant="mlp", mlp_hidden=[8])).predict(torch.randn(2, 40, 36))[2] is None
    with pytest.raises(ValueError, match="lower_quantile"):
        ModelConfig(lower_quantile=0.7).validate()
    # pinball at q = 0.1: an over-estimate by 1 costs 0.9, an under-estimate by 1 costs 0.1
    y = torch.zeros(1)
    assert float(pinball(torch.ones(1), y, 0.1)) == pytest.approx(0.9)
    assert float(pinball(-torch.ones(1), y, 0.1)) == pytest.approx(0.1)

    arrays = {s: _tiny_data(32, i) for i, s in enumerate(("train", "val", "test"))}
    cfg = make_config(["estimator=linformer", f"runs_dir={tmp_path}", "trainer.fast_dev_run=true",
                       "model.tokens=step", "model.d_model=16", "model.linformer_k=8", "threads=1",
                       "model.lower_quantile=0.1", "schedule=cosine_time"])
    _, record = train(cfg, datamodule=WindowDataModule(arrays=arrays, batch_size=16))
    assert record["global_steps"] == 1


def test_checkpoint_round_trip(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from estimators.checkpoint import load_checkpoint, save_checkpoint
    from estimators.models import ModelConfig, build_model

    model = build_model(ModelConfig(variant="attention", tokens="step", d_model=16)).eval()
    X, y = _tiny_data(20, 3)
    model.norm.fit(torch.from_numpy(X), torch.from_numpy(y))
    save_checkpoint(model, tmp_path / "m", {"note": "test"})
    loaded, meta = load_checkpoint(tmp_path / "m.pt")
    assert meta["note"] == "test" and meta["model"]["tokens"] == "step"
    x = torch.from_numpy(X)
    with torch.no_grad():
        for a, b in zip(model(x), loaded(x), strict=True):
            torch.testing.assert_close(a, b)
    with pytest.raises(FileNotFoundError, match="shipped checkpoints"):
        load_checkpoint(tmp_path / "missing")


def test_ensemble_combines_members_and_round_trips(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from estimators.checkpoint import load_checkpoint, save_checkpoint
    from estimators.learned import LearnedEstimator
    from estimators.models import EnsembleModel, ModelConfig, build_model, calibrate_variance

    cfg = ModelConfig(variant="attention", tokens="step", d_model=16, lower_quantile=0.1)
    X, y = _tiny_data(24, 5)
    x = torch.from_numpy(X)
    members = []
    for seed in (0, 1, 2):
        torch.manual_seed(seed)
        m = build_model(cfg).eval()
        m.norm.fit(x, torch.from_numpy(y))
        members.append(m)
    ens = EnsembleModel(members).eval()
    with torch.no_grad():
        outs = [m.predict(x) for m in members]
        mean, log_var, lower = ens.predict(x)
    # mixture of Gaussians: mean of means; variance = mean of variances + population variance of the means
    means = np.stack([o[0].numpy() for o in outs])
    var = np.stack([np.exp(o[1].numpy()) for o in outs]).mean(0) + means.var(0)
    np.testing.assert_allclose(mean.numpy(), means.mean(0), rtol=1e-5)
    np.testing.assert_allclose(np.exp(log_var.numpy()), var, rtol=1e-4)
    gaps = np.stack([(o[0] - o[2]).numpy() for o in outs]).mean(0)
    np.testing.assert_allclose(lower.numpy(), means.mean(0) - gaps, rtol=1e-5, atol=1e-6)
    # calibration scales the ensemble's variance only
    s = calibrate_variance(ens, x, torch.from_numpy(y))
    with torch.no_grad():
        np.testing.assert_allclose(np.exp(ens.predict(x)[1].numpy()), s * var, rtol=1e-4)
    save_checkpoint(ens, tmp_path / "ens", {"training": {"members": 3}})
    loaded, meta = load_checkpoint(tmp_path / "ens")
    assert isinstance(loaded, EnsembleModel) and meta["ensemble"]["members"] == 3
    assert len(meta["normalisation"]) == 3
    with torch.no_grad():
        for a, b in zip(ens.predict(x), loaded.predict(x), strict=True):
            torch.testing.assert_close(a, b)
    est = LearnedEstimator("attention", checkpoint=tmp_path / "ens", prior_mu=0.5, conservative_k=1.0)
    for i in range(WINDOW_STEPS):
        e = est.step(_obs(i * WINDOW_DT_S))
    assert e.ready and e.sigma > 0
    # a single model saved over an ensemble's file leaves no ensemble record behind
    save_checkpoint(members[0], tmp_path / "ens")
    assert not isinstance(load_checkpoint(tmp_path / "ens")[0], EnsembleModel)
    with pytest.raises(ValueError, match="at least 2"):
        EnsembleModel(members[:1])
    with pytest.raises(ValueError, match="share one ModelConfig"):
        EnsembleModel([members[0], build_model(ModelConfig(variant="attention", tokens="step", d_model=8))])


def test_ensemble_training_runs_members_side_by_side(tmp_path: Path) -> None:
    pytest.importorskip("lightning")
    from estimators.models import EnsembleModel
    from estimators.train import make_config, member_overrides, train_ensemble

    data = tmp_path / "data"
    data.mkdir()
    for i, split in enumerate(("train", "val", "test")):
        X, y = _tiny_data(32, i)
        np.savez(data / f"{split}.npz", X=X, y=y, episode=np.arange(len(y)))
    cfg = make_config(["estimator=mlp", f"runs_dir={tmp_path / 'runs'}", f"data_dir={data}", "ensemble=2",
                       "trainer.fast_dev_run=true", "model.mlp_hidden=[8]", "threads=2", "name=ens",
                       "augment.tau_scale=[0.8,1.25]"])
    over = member_overrides(cfg, 1, tmp_path / "runs" / "ens" / "members")
    assert "seed=1" in over and "threads=1" in over and "ensemble=1" in over and "name=ens_m1" in over
    assert make_config(over).augment.tau_scale == [0.8, 1.25]  # lists survive the round trip
    ens, record = train_ensemble(cfg)
    assert isinstance(ens, EnsembleModel) and len(ens.members) == 2
    assert record["members"] == 2 and record["epochs"] == [1, 1]
    assert record["train_wall_time_s"] > 0 and len(record["member_records"]) == 2
    # members differ (different seeds), so the ensemble has a spread
    w0, w1 = (next(m.parameters()).detach() for m in ens.members)
    assert not np.allclose(w0.numpy(), w1.numpy())
    bad = make_config(["estimator=mlp", f"runs_dir={tmp_path / 'runs'}", f"data_dir={tmp_path / 'nowhere'}",
                       "ensemble=2", "trainer.fast_dev_run=true", "model.mlp_hidden=[8]", "name=bad"])
    with pytest.raises(RuntimeError, match="members \\[0, 1\\] failed"):
        train_ensemble(bad)


def test_learned_estimator_prior_then_estimates(tmp_path: Path) -> None:
    pytest.importorskip("torch")
    from estimators.checkpoint import save_checkpoint
    from estimators.learned import LearnedEstimator
    from estimators.models import ModelConfig, build_model

    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8])).eval(), tmp_path / "m")
    est = LearnedEstimator("mlp", checkpoint=tmp_path / "m", prior_mu=0.33, conservative_k=1.0, threads=None)
    assert isinstance(est, Estimator)
    rng = np.random.default_rng(0)
    dt = 0.001
    ticks_to_full = round((WINDOW_STEPS - 1) * WINDOW_DT_S / dt)  # the 40th sample is at t = 1.17 s
    outs = [est.step(_obs(k * dt, rng=rng)) for k in range(ticks_to_full + 100)]
    assert all(o.mu == 0.33 and not o.ready for o in outs[:ticks_to_full])
    last = outs[-1]
    assert outs[ticks_to_full].ready and last.ready and np.isfinite(last.mu) and last.sigma > 0
    assert last.mu == pytest.approx(max(0.05, est.mean - est.sigma))
    est.reset()
    assert not est.step(_obs(0.0)).ready
    with pytest.raises(ValueError, match="valid choices"):
        LearnedEstimator("gru")
    with pytest.raises(ValueError, match="holds a 'mlp' model"):
        LearnedEstimator("linformer", checkpoint=tmp_path / "m")
    with pytest.raises(ValueError, match="lower-quantile head"):
        LearnedEstimator("mlp", checkpoint=tmp_path / "m", bound="quantile")
    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8], lower_quantile=0.1)).eval(), tmp_path / "q")
    est = LearnedEstimator("mlp", checkpoint=tmp_path / "q", conservative_k=0.0, bound="quantile", threads=None)
    outs = [est.step(_obs(k * dt, rng=rng)) for k in range(ticks_to_full + 1)]
    assert outs[-1].ready and outs[-1].mu == pytest.approx(max(0.05, est.lower)) and est.lower <= est.mean


def test_hold_min_drops_at_once_and_rises_late(tmp_path: Path) -> None:
    """hold_min_samples = n reports the smallest bound of the last n model outputs."""
    torch = pytest.importorskip("torch")
    from estimators.checkpoint import save_checkpoint
    from estimators.learned import LearnedEstimator
    from estimators.models import ModelConfig, build_model

    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8])).eval(), tmp_path / "m")
    est = LearnedEstimator("mlp", checkpoint=tmp_path / "m", conservative_k=0.0, threads=None, hold_min_samples=3)
    reported = []
    for m in (0.9, 0.4, 0.8, 0.8, 0.8, 0.7):  # drive the hold with known model outputs (sigma = 1)
        est.model.predict = lambda x, m=m: (torch.tensor([m]), torch.zeros(1), None)  # type: ignore[method-assign]
        reported.append(est._estimate().mu)
    assert reported == pytest.approx([0.9, 0.4, 0.4, 0.4, 0.8, 0.7])
    with pytest.raises(ValueError, match="hold_min_samples"):
        LearnedEstimator("mlp", checkpoint=tmp_path / "m", hold_min_samples=0)


@pytest.mark.parametrize(
    "variant", ["mlp", "attention", "linformer", "attention_step", "attention_step_notau", "linformer_step"]
)
def test_shipped_checkpoint_reaches_recorded_mae(variant: str) -> None:
    pytest.importorskip("torch")
    from estimators.checkpoint import CHECKPOINT_DIR, load_checkpoint
    from studies.estimator_evaluate import FIXTURE, fixture_mae

    if not (CHECKPOINT_DIR / f"{variant}.pt").is_file():
        pytest.skip(f"no shipped {variant} checkpoint")
    model, meta = load_checkpoint(variant)
    recorded = meta["metrics"]["fixture_mae"]
    assert FIXTURE.is_file()
    assert fixture_mae(model) == pytest.approx(recorded, abs=2e-3)
    # the fixture is a sample of the test split: its MAE is of the order of the recorded test MAE
    assert recorded < 3 * meta["metrics"]["test/mean"]["mae"] + 0.02
    # its windows collected with the safety filter in the loop, and the others, separately
    for subset in ("filtered", "nominal"):
        rec = meta["metrics"].get(f"fixture_mae_{subset}")
        if rec is not None and np.isfinite(rec):
            assert fixture_mae(model, subset) == pytest.approx(rec, abs=2e-3)


@pytest.mark.parametrize(
    "variant", ["mlp", "attention", "linformer", "attention_step", "attention_step_notau", "linformer_step"]
)
def test_learned_configs_instantiate(variant: str) -> None:
    pytest.importorskip("torch")
    from hydra.utils import instantiate

    from estimators.checkpoint import CHECKPOINT_DIR

    if not (CHECKPOINT_DIR / f"{variant}.pt").is_file():
        pytest.skip(f"no shipped {variant} checkpoint")
    est = instantiate(OmegaConf.load(CONF / f"{variant}.yaml"))
    assert est.name == variant and json.dumps(est.meta["model"])


def test_inloop_window_matches_collected_window(tmp_path: Path) -> None:
    """The window a learned estimator feeds its model in the core loop is exactly the one collection labels
    in the same episode (same sample instants, previous-tick torque, core joint order)."""
    torch = pytest.importorskip("torch")
    from estimators.checkpoint import save_checkpoint
    from estimators.collect import EpisodeConfig, build_episode, run_episode
    from estimators.learned import LearnedEstimator
    from estimators.models import ModelConfig, build_model
    from studies.estimator_friction_switch import nominal_params

    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8])).eval(), tmp_path / "m")
    est = LearnedEstimator("mlp", checkpoint=tmp_path / "m", threads=None, inference="inline")
    seen: list[torch.Tensor] = []
    predict = est.model.predict
    est.model.predict = lambda x: (seen.append(x.clone()), predict(x))[1]  # type: ignore[method-assign]
    cfg = EpisodeConfig(duration_s=1.2, first_window_s=0.0, stride=1)
    build_episode(nominal_params(0.6), cfg, est).run()
    collected = run_episode(nominal_params(0.6), cfg)
    assert len(seen) == 1 and collected.windows.shape[0] == 1
    np.testing.assert_allclose(seen[0][0].numpy(), collected.windows[0], rtol=0, atol=1e-6)


def test_model_without_tau_ignores_torques() -> None:
    torch = pytest.importorskip("torch")
    from estimators.models import ModelConfig, build_model

    model = build_model(ModelConfig(variant="attention", tokens="step", d_model=16, use_tau=False)).eval()
    x = torch.randn(3, 40, 36)
    x2 = x.clone()
    x2[..., 24:] += 10.0
    with torch.no_grad():
        torch.testing.assert_close(model(x)[0], model(x2)[0])


def test_foot_kinematics_match_leg_fk_and_its_finite_difference() -> None:
    torch = pytest.importorskip("torch")
    from estimators.models import foot_kinematics
    from taslel_bench.robot.description import load_robot
    from taslel_bench.robot.kinematics import LegKinematics

    rng = np.random.default_rng(4)
    q, qd = rng.uniform(-1.0, 1.0, 12), rng.normal(size=12)
    x = torch.from_numpy(np.concatenate([q, qd, np.zeros(12)])[None, None]).double()
    out = foot_kinematics(x)[0, 0].numpy()
    h = 1e-6
    kin = LegKinematics(load_robot("a1"))
    for leg in range(4):
        ql, dl = q[3 * leg : 3 * leg + 3], qd[3 * leg : 3 * leg + 3]
        p = kin.leg_fk(leg, ql) + load_robot("a1").hip_positions_in_trunk[leg]
        v = (kin.leg_fk(leg, ql + h * dl) - kin.leg_fk(leg, ql - h * dl)) / (2 * h)
        np.testing.assert_allclose(out[3 * leg : 3 * leg + 3], p, atol=1e-6)
        np.testing.assert_allclose(out[12 + 3 * leg : 15 + 3 * leg], v, atol=1e-6)


def test_window_norm_removes_torque_scale_and_kinematic_features_shape() -> None:
    torch = pytest.importorskip("torch")
    from estimators.models import ModelConfig, build_model, window_features

    x = torch.randn(3, 40, 36)
    x2 = x.clone()
    x2[..., 24:] *= 1.7  # a payload / motor-strength change scales every torque of the window
    torch.testing.assert_close(window_features(x, "tau"), window_features(x2, "tau"))
    assert not torch.allclose(window_features(x, "none"), window_features(x2, "none"))
    xq = x.clone()
    xq[..., :12] += 0.1  # posture offset
    torch.testing.assert_close(window_features(x, "tau_q"), window_features(xq, "tau_q"))
    with pytest.raises(ValueError, match="valid choices: none, tau, tau_q"):
        window_features(x, "per_joint")
    for variant in ("mlp", "attention"):
        cfg = ModelConfig(variant=variant, tokens="step", d_model=16, mlp_hidden=[8], kinematic_features=True)
        model = build_model(cfg)
        assert cfg.n_inputs == 60 and model.norm.x_mean.shape == (60,)
        assert model(x)[0].shape == (3,)
    with pytest.raises(ValueError, match="kinematic_features needs tokens='step'"):
        ModelConfig(variant="linformer", tokens="joint", kinematic_features=True).validate()


def test_plant_beta_favours_range_edges_and_one_factor_shift() -> None:
    from estimators.randomisation import PLANT_FACTORS, SHIFTED_RANGES, TRAIN_RANGES, draw, shifted_ranges

    rng_u, rng_b = np.random.default_rng(0), np.random.default_rng(0)
    uni = [draw(rng_u, TRAIN_RANGES, seed=i) for i in range(2000)]
    edge = [draw(rng_b, TRAIN_RANGES, seed=i, plant_beta=0.4) for i in range(2000)]
    lo, hi = TRAIN_RANGES.motor_strength_scale
    for draws in (uni, edge):
        assert all(lo <= d.motor_strength_scale <= hi for d in draws)
    def near(ds):
        return np.mean([min(d.motor_strength_scale - lo, hi - d.motor_strength_scale) < 0.1 * (hi - lo) for d in ds])

    assert near(uni) == pytest.approx(0.2, abs=0.03) and near(edge) > 0.35
    # friction and operator settings are still uniform
    assert np.mean([d.friction for d in edge]) == pytest.approx(np.mean(TRAIN_RANGES.friction), abs=0.03)
    with pytest.raises(ValueError, match="plant_beta must be > 0"):
        draw(np.random.default_rng(0), TRAIN_RANGES, seed=0, plant_beta=0.0)

    assert shifted_ranges(PLANT_FACTORS) == SHIFTED_RANGES
    one = shifted_ranges(["motor_strength_scale"])
    assert one.motor_strength_scale == SHIFTED_RANGES.motor_strength_scale
    assert one.trunk_mass_scale == TRAIN_RANGES.trunk_mass_scale and one.trunk_com_shift_xy_m == (0.0, 0.03)
    with pytest.raises(ValueError, match="valid factors: trunk_mass_scale"):
        shifted_ranges(["payload"])


def test_compare_scores_checkpoints_on_named_sets(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from estimators.checkpoint import save_checkpoint
    from estimators.models import ModelConfig, build_model
    from studies.estimator_compare import compare, main, score

    err = score(np.array([0.5, 0.2, 1.0]), np.array([0.4, 0.2, 1.2]), np.array([False, False, True]))
    assert err["mae[all]"] == pytest.approx(0.1) and err["over[all]"] == pytest.approx(1 / 3)
    assert err["mae[filtered]"] == pytest.approx(0.2) and err["bias[mu>=0.9]"] == pytest.approx(-0.2)
    model = build_model(ModelConfig(variant="mlp", mlp_hidden=[8], lower_quantile=0.1)).eval()
    X, y = _tiny_data(12, 5)
    model.fit_normaliser(torch.from_numpy(X), torch.from_numpy(y))
    save_checkpoint(model, tmp_path / "tiny", {"training": {"epochs": 3, "train_windows": 12}})
    np.savez(tmp_path / "w.npz", X=X, y=y, window_filtered=np.arange(12) % 2 == 0)
    rows = compare([str(tmp_path / "tiny")], {"a": tmp_path / "w.npz"}, {"tiny": "test model"})
    assert [(r["set"], r["estimate"], r["what"]) for r in rows] == [
        ("a", "mean", "test model"),
        ("a", "lower", "test model"),
    ]
    assert set(rows[0]) >= {"mae[nominal]", "mae[filtered]", "over[all]"}
    main(
        [str(tmp_path / "tiny"), "--set", f"a={tmp_path / 'w.npz'}", "--out", str(tmp_path / "r.md"), "--threads", "1"]
    )
    assert "| tiny |" in (tmp_path / "r.md").read_text()
    with pytest.raises(SystemExit, match="expected NAME=PATH"):
        main([str(tmp_path / "tiny"), "--set", "nopath"])


@pytest.mark.parametrize("config", ["mlp", "attention_step", "linformer_step", "attention", "linformer"])
def test_estimator_config_uses_the_bound_chosen_on_validation(config: str) -> None:
    """conf/estimator/<config>.yaml deploys the bound that ``studies.estimator_targets offline`` chose on the shifted
    validation set for the checkpoint it loads (metrics.safety_calibration: bound, k, band margin), so a
    retrained checkpoint cannot silently keep the previous calibration."""
    cfg = OmegaConf.load(CONF / f"{config}.yaml")
    name = cfg.get("checkpoint") or config
    meta = json.loads((Path(__file__).resolve().parents[1] / "estimators" / "checkpoints" / f"{name}.json").read_text())
    choice = meta["metrics"]["safety_calibration"]
    assert (cfg.bound, float(cfg.conservative_k)) == (choice["bound"], float(choice["k"])), (
        f"{config}.yaml vs {name}.json"
    )
    assert OmegaConf.to_container(cfg.band_margin) == choice["band_margin"], f"{config}.yaml vs {name}.json"


# --------------------------------------------------------------------- the filter's mu as an input


def test_filter_channels_layout_and_model_input() -> None:
    torch = pytest.importorskip("torch")
    from estimators.features import N_FILTER_FEATURES, filter_channels, with_filter_channels
    from estimators.models import ModelConfig, build_model

    np.testing.assert_allclose(filter_channels(np.array([np.nan, 0.4])), [[0.0, 0.0], [1.0, 0.4]], rtol=1e-6)
    X = np.zeros((3, WINDOW_STEPS, N_FEATURES), np.float32)
    W = with_filter_channels(X, np.array([np.nan, 0.3, 1.1]))
    assert W.shape == (3, WINDOW_STEPS, N_FEATURES + N_FILTER_FEATURES)
    np.testing.assert_allclose(W[:, 5, N_FEATURES:], [[0, 0], [1, 0.3], [1, 1.1]])
    per_sample = np.full((3, WINDOW_STEPS), 0.5)
    assert with_filter_channels(X, per_sample)[..., -1].min() == pytest.approx(0.5)
    with pytest.raises(ValueError, match="filter_mu must have shape"):
        with_filter_channels(X, np.zeros(4))
    for variant in ("mlp", "attention", "linformer"):
        cfg = ModelConfig(variant=variant, tokens="step", d_model=16, linformer_k=8, mlp_hidden=[8],
                          filter_mu_input=True)
        model = build_model(cfg).eval()
        assert cfg.n_raw == 38 and model(torch.from_numpy(W))[0].shape == (3,)
        with pytest.raises(ValueError, match="2 filter features"):
            model(torch.from_numpy(X))
        # the filter features reach the encoder: changing only the filter's mu changes the estimate
        W2 = W.copy()
        W2[..., -1] += 0.5
        assert not torch.allclose(model(torch.from_numpy(W))[0], model(torch.from_numpy(W2))[0])
    with pytest.raises(ValueError, match="filter_mu_input needs tokens='step'"):
        ModelConfig(variant="attention", tokens="joint", filter_mu_input=True).validate()


def test_collect_filter_mu_range_is_independent_of_the_truth(tmp_path: Path) -> None:
    from estimators.collect import EpisodeConfig, collect
    from estimators.data import load_split

    cfg = EpisodeConfig(duration_s=1.6, stride=4)
    man = collect(tmp_path / "r", {"train": 4}, seed=2, workers=1, cfg=cfg, filter_fraction=1.0,
                  filter_mu_range=(0.2, 0.3))
    assert man["filter_mu_range"] == [0.2, 0.3] and man["filter_mu_scale"] is None
    with np.load(tmp_path / "r" / "train.npz") as f:
        friction = f["params"][:, list(f["param_columns"]).index("friction")]
        assert np.all((f["filter_mu"] >= 0.2) & (f["filter_mu"] <= 0.3))
        assert friction.max() > 0.35  # drawn from the training range, not tied to the filter's mu
        mu_ep = f["filter_mu"]
    X, _, ep = load_split(tmp_path / "r", "train", filter_mu=True)
    assert len(X) >= 4 and X.shape[-1] == 38 and (X[..., 36] == 1).all()
    np.testing.assert_allclose(X[:, 0, 37], mu_ep[ep], rtol=1e-6)
    with pytest.raises(ValueError, match="not both"):
        collect(tmp_path / "x", {"train": 1}, filter_fraction=1.0, filter_mu_scale=(0.5, 0.9),
                filter_mu_range=(0.2, 0.3))
    with pytest.raises(ValueError, match="filter_mu_range must be"):
        collect(tmp_path / "x", {"train": 1}, filter_fraction=1.0, filter_mu_range=(0.3, 0.2))


def test_merge_drops_the_filtered_episodes_of_named_folders(tmp_path: Path) -> None:
    from estimators.collect import EpisodeConfig, collect
    from estimators.merge import merge

    cfg = EpisodeConfig(duration_s=1.6, stride=4)
    collect(tmp_path / "a", {"train": 6, "test": 1}, seed=3, workers=1, cfg=cfg, filter_fraction=0.5,
            filter_mu_scale=(0.6, 1.1))
    collect(tmp_path / "b", {"train": 2}, seed=4, workers=1, cfg=cfg, filter_fraction=1.0,
            filter_mu_range=(0.1, 1.2))
    with np.load(tmp_path / "a" / "train.npz") as a:
        a_nominal = ~a["filtered"]
        a_X_nominal = a["X"][~a["window_filtered"]]
    assert 0 < a_nominal.sum() < 6 and len(a_X_nominal) > 0
    man = merge(tmp_path / "m", tmp_path / "a", [tmp_path / "b"], drop_filtered=[tmp_path / "a"])
    train = man["splits"]["train"]  # type: ignore[index]
    assert train["episodes"] == a_nominal.sum() + 2 and train["episodes_filtered"] == 2
    assert man["sources"][0]["dropped_filtered"]["episodes"] == 6 - a_nominal.sum()  # type: ignore[index]
    assert man["sources"][1]["filter_mu_range"] == [0.1, 1.2]  # type: ignore[index]
    from studies.estimator_evaluate import _source_text  # the report's line per training source

    texts = [_source_text(src) for src in man["sources"]]  # type: ignore[union-attr]
    assert texts[0].startswith(f"{a_nominal.sum()} episodes (seed 3") and "filtered episodes left out" in texts[0]
    assert texts[1].startswith("2 episodes (seed 4") and "U(0.1, 1.2) independent of the truth" in texts[1]
    with np.load(tmp_path / "m" / "train.npz") as m:
        n_a = len(a_X_nominal)
        np.testing.assert_array_equal(m["X"][:n_a], a_X_nominal)
        assert not m["window_filtered"][:n_a].any() and m["window_filtered"][n_a:].all()
        # episode ids are 0..n-1, every per-episode array has one row per id
        assert sorted(np.unique(m["episode"])) == list(range(train["episodes"]))
        assert len(m["params"]) == len(m["filter_mu"]) == len(m["fell"]) == train["episodes"]
        np.testing.assert_array_equal(m["filtered"][m["episode"]], m["window_filtered"])
    with pytest.raises(ValueError, match="not among the merged"):
        merge(tmp_path / "m3", tmp_path / "a", [tmp_path / "b"], drop_filtered=[tmp_path / "zzz"])


def test_learned_estimator_feeds_the_filters_mu_and_training_runs(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("lightning")
    from estimators.checkpoint import save_checkpoint
    from estimators.data import WindowDataModule
    from estimators.features import with_filter_channels
    from estimators.learned import LearnedEstimator
    from estimators.models import ModelConfig, build_model
    from estimators.train import make_config, train

    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8], filter_mu_input=True)).eval(),
                    tmp_path / "m")
    est = LearnedEstimator("mlp", checkpoint=tmp_path / "m", threads=None)
    seen: list[torch.Tensor] = []
    predict = est.model.predict
    est.model.predict = lambda x: (seen.append(x.clone()), predict(x))[1]  # type: ignore[method-assign]
    rng = np.random.default_rng(0)
    for k in range(WINDOW_STEPS):
        o = _obs(k * WINDOW_DT_S, rng=rng)
        o.filter_mu = float("nan") if k < 10 else 0.25 + 0.01 * k
        est.step(o)
    assert len(seen) == 1 and seen[0].shape == (1, WINDOW_STEPS, 38)
    x = seen[0][0].numpy()
    np.testing.assert_array_equal(x[:10, 36:], 0.0)
    np.testing.assert_allclose(x[10:, 36], 1.0)
    np.testing.assert_allclose(x[10:, 37], 0.25 + 0.01 * np.arange(10, WINDOW_STEPS), rtol=1e-6)

    def tiny(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        X, y = _tiny_data(n, seed)
        return with_filter_channels(X, np.where(np.arange(n) % 2, 0.5, np.nan)), y

    arrays = {s: tiny(32, i) for i, s in enumerate(("train", "val", "test"))}
    cfg = make_config(["estimator=mlp", f"runs_dir={tmp_path}", "trainer.fast_dev_run=true", "threads=1",
                       "model.filter_mu_input=true", "augment.noise_std=0.1", "augment.tau_scale=[0.8,1.25]"])
    task, record = train(cfg, datamodule=WindowDataModule(arrays=arrays, batch_size=16))
    assert record["global_steps"] == 1 and task.model.cfg.n_raw == 38
    # augmentation scales the torques and leaves the filter features exact
    xb = torch.from_numpy(arrays["train"][0][:4])
    aug = task.augment(xb)
    torch.testing.assert_close(aug[..., 36:], xb[..., 36:])
    assert not torch.allclose(aug[..., 24:36], xb[..., 24:36])


def test_evaluate_chooses_the_bound_on_the_bound_set(tmp_path: Path) -> None:
    """--bound-set: every candidate bound's k is the smallest giving <= 5 % over-estimation on that set, and
    the choice is recorded with the set it was made on."""
    pytest.importorskip("torch")
    from estimators.checkpoint import save_checkpoint
    from estimators.models import ModelConfig, build_model
    from studies.estimator_evaluate import K_SWEEP, evaluate

    data = tmp_path / "data"
    data.mkdir()
    for i, split in enumerate(("train", "val", "test", "shifted")):
        X, y = _tiny_data(48, i)
        np.savez(data / f"{split}.npz", X=X, y=y, episode=np.arange(48))
    Xb, yb = _tiny_data(64, 9)
    np.savez(tmp_path / "bound_set.npz", X=Xb, y=yb * 0.5, episode=np.arange(64))  # lower truth: a "shift"
    model = build_model(ModelConfig(variant="mlp", mlp_hidden=[8], lower_quantile=0.1)).eval()
    import torch

    model.norm.fit(torch.from_numpy(_tiny_data(48, 0)[0]), torch.from_numpy(_tiny_data(48, 0)[1]))
    save_checkpoint(model, tmp_path / "m")
    meta = json.loads((tmp_path / "m.json").read_text())  # recorded by other studies before: one kept
    meta["metrics"] = {"safety_calibration": {"bound": "gaussian", "k": 0.5}, "test/stale": 1.0}
    (tmp_path / "m.json").write_text(json.dumps(meta))
    evaluate(data, [str(tmp_path / "m.pt")], [1.0], tmp_path / "out", latency_runs=3,
             bound_set=tmp_path / "bound_set.npz")
    rec = json.loads((tmp_path / "m.json").read_text())["metrics"]
    assert rec["safety_calibration"] == {"bound": "gaussian", "k": 0.5} and "test/stale" not in rec
    assert rec["bound_selection"]["set"] == str(tmp_path / "bound_set.npz")
    for label, v in rec["val_bounds"].items():
        k = float(label.split("k=")[1])
        assert k in K_SWEEP
        if label.startswith("gaussian") or k > 0:  # chosen k: <= 5 % on the bound set
            assert v["selection_set_overestimate_rate"] <= 0.05
    choice = rec["val_bound_choice"]
    if choice is not None:
        assert rec["val_bounds"][choice]["selection_set_overestimate_rate"] <= 0.05


def test_evaluate_report_data_section_names_each_variants_training_data() -> None:
    """The report's data section names the training folder of every variant (its checkpoint's record), not
    only the ``--data`` folder's manifest."""
    from studies.estimator_evaluate import _data_section

    manifest = {"env_steps": 10, "wall_time_s": 1.0, "workers": 2, "env_steps_per_s": 10.0,
                "splits": {"test": {"episodes": 1, "windows": 3, "episodes_fallen": 0}},
                "train_ranges": {}, "shifted_ranges": {}}
    lines = _data_section(manifest, {"test": 0.2, "shifted": 0.3}, {"mlp": "/d/a", "attention_step": "/d/b"})
    text = "\n".join(lines)
    assert "`mlp`: `/d/a`; `attention_step`: `/d/b`" in text
    assert "training data" not in "\n".join(_data_section(manifest, {"test": 0.2}))
