"""One-sided estimator targets: per-band metrics with episode-bootstrap CIs, band-aware margins,
the conservative prior, the drop detector and inference off the control tick. A few seconds in all."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS
from estimators.safety import BandMargin, band_rows, fit_band_margin, ratio_ci, verdict
from taslel_bench.interfaces import Proprioception

DT = 0.001  # [s] control tick of the synthetic runs


def _obs(t: float, rng: np.random.Generator) -> Proprioception:
    return Proprioception(t, rng.normal(size=12), rng.normal(size=12), rng.normal(size=12) * 5)


def test_ratio_ci_resamples_episodes_not_windows() -> None:
    # 10 episodes of 100 windows; two episodes over-estimate everywhere: 20 %, and a wide CI since only
    # 10 independent draws exist (window resampling would give a CI of about +-2.5 %)
    g = np.repeat(np.arange(10), 100)
    over = np.isin(g, [3, 7]).astype(float)
    p, lo, hi = ratio_ci(over, np.ones_like(over), g, n_boot=2000, seed=1)
    assert p == pytest.approx(0.2)
    assert lo < 0.05 and hi > 0.4
    assert np.isnan(ratio_ci(over, np.zeros_like(over), g)[0])


def test_band_rows_and_verdict() -> None:
    y = np.array([0.2, 0.2, 0.4, 0.4, 0.6, 1.0])
    mu = np.array([0.3, 0.2, 0.4, 0.25, 0.45, 0.2])  # over at 0.2 (first), under-useful at 0.4 (0.25 < 0.3) and 1.0
    rows = {r["band"]: r for r in band_rows(y, mu, np.arange(6), n_boot=50)}
    assert rows["0.1-0.3"]["over"] == 0.5 and rows["0.3-0.5"]["useful"] == 0.5
    assert rows["0.8-1.2"]["useful"] == 0.0 and rows["<0.5"]["over"] == 0.25
    assert rows["0.5-0.8"]["capped_mae"] == pytest.approx(0.15)
    v = verdict(list(rows.values()))
    assert v["over"] is False and v["useful"] is False


def test_band_margin_fit_keeps_low_bands_under_the_limit_with_the_smallest_margins() -> None:
    rng = np.random.default_rng(0)
    y = rng.uniform(0.1, 1.2, 4000)
    mean = y + np.where(y < 0.3, 0.06, 0.0) + rng.normal(0, 0.01, y.size)  # biased high at low friction only
    bm, info = fit_band_margin(y, mean, mean, mu_min=0.05, max_over=0.02)
    assert info["over_0.1-0.3"] <= 0.02 and info["over_0.3-0.5"] <= 0.02
    assert bm.margins[0] >= 0.02 and bm.margins[2] == bm.margins[3] == 0.0  # only where the bias is
    assert bm.margin(np.array([0.2, 0.9])).tolist() == [bm.margins[0], 0.0]
    assert fit_band_margin(y, y + 1.0, y + 1.0, mu_min=0.05, grid=np.array([0.0]), max_over=0.02) is None
    with pytest.raises(ValueError, match="ascending"):
        BandMargin((0.5, 0.3), (0, 0, 0))


@pytest.fixture()
def tiny_checkpoints(tmp_path: Path) -> Path:
    pytest.importorskip("torch")
    from estimators.checkpoint import save_checkpoint
    from estimators.models import ModelConfig, build_model

    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8])).eval(), tmp_path / "m")
    save_checkpoint(build_model(ModelConfig(variant="mlp", mlp_hidden=[8], window_steps=12)).eval(), tmp_path / "s")
    return tmp_path


def test_prior_is_the_safe_floor_and_band_margin_applies(tiny_checkpoints: Path) -> None:
    from estimators.learned import LearnedEstimator
    from estimators.simple import SAFE_FLOOR_MU

    est = LearnedEstimator("mlp", checkpoint=tiny_checkpoints / "m", conservative_k=0.0, threads=None,
                           band_margin={"edges": [0.3], "margins": [0.0, 0.05]})
    rng = np.random.default_rng(0)
    n = round((WINDOW_STEPS - 1) * WINDOW_DT_S / DT) + 1
    outs = [est.step(_obs(k * DT, rng)) for k in range(n)]
    assert all(o.mu == SAFE_FLOOR_MU and not o.ready for o in outs[:-1])
    expect = est.mean - (0.05 if est.mean >= 0.3 else 0.0)
    assert outs[-1].ready and outs[-1].mu == pytest.approx(max(0.05, expect))


def test_drop_detector_resets_to_the_prior_until_the_window_refills(tiny_checkpoints: Path) -> None:
    import torch

    from estimators.learned import LearnedEstimator

    est = LearnedEstimator("mlp", checkpoint=tiny_checkpoints / "m", conservative_k=0.0, threads=None, prior_mu=0.2,
                           drop_detector={"checkpoint": str(tiny_checkpoints / "s"), "k": 1.0, "delta": 0.1})
    est.model.predict = lambda x: (torch.tensor([0.8]), torch.zeros(1), None)  # type: ignore[method-assign]
    short = {"mu": 0.75}  # short-window model: upper bound 0.75 + 1 sigma (sigma 1 -> log_var 0)
    est.detector.model.predict = lambda x: (torch.tensor([short["mu"]]), torch.tensor([-20.0]), None)  # type: ignore
    rng = np.random.default_rng(0)
    every = round(WINDOW_DT_S / DT)
    samples = []
    for k in range(every * 100):
        o = est.step(_obs(k * DT, rng))
        if k % every == 0:
            samples.append(o)
        if k == every * 50:  # friction "drops": the short model sees it, the long window does not yet
            short["mu"] = 0.3
    first = WINDOW_STEPS - 1
    assert not samples[first - 1].ready and samples[first].ready and samples[first].mu == pytest.approx(0.8)
    hit = next(i for i, o in enumerate(samples) if i > first and not o.ready)
    assert hit == 51 and samples[hit].mu == 0.2  # the first sample after the drop
    # back to the prior until 40 fresh samples are in the window; the short model keeps firing, and after the
    # refill each first output resets again (0.3 + 0 < 0.8 - 0.1): no output of the stale window ever shows
    assert all(not o.ready and o.mu == 0.2 for o in samples[hit:])
    assert est.diagnostics()["drops_detected"] == 2  # at sample 51 and at the refill, sample 91


@pytest.mark.parametrize("mode", ["staged", "thread"])
def test_off_tick_inference_applies_the_inline_results_after_a_fixed_latency(tiny_checkpoints: Path,
                                                                              mode: str) -> None:
    from estimators.learned import LearnedEstimator

    delay = 0.01
    kw = {"checkpoint": tiny_checkpoints / "m", "threads": None, "conservative_k": 0.0,
          "drop_detector": {"checkpoint": str(tiny_checkpoints / "s"), "delta": 5.0}}
    inline = LearnedEstimator("mlp", **kw)
    thread = LearnedEstimator("mlp", inference=mode, apply_delay_s=delay, **kw)
    inline.mu_min = thread.mu_min = -10.0  # no floor: the untrained model's outputs all show
    ticks = round((WINDOW_STEPS + 5) * WINDOW_DT_S / DT)
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    a = [inline.step(_obs(k * DT, rng_a)).mu for k in range(ticks)]
    b = [thread.step(_obs(k * DT, rng_b)).mu for k in range(ticks)]
    thread.close()
    # exactly the inline run, `delay` later: a late worker makes its tick wait, never changes the result
    lag = round(delay / DT)
    assert b[lag:] == a[: ticks - lag] and len(set(a)) > 2
    d = thread.diagnostics()
    assert d["samples"] == inline.diagnostics()["samples"]
    if mode == "staged":  # 3 slices (2 of the mlp, 1 of the detector) + 1: always within the 10 ticks
        assert d["deadline_misses"] == 0 and d["wait_s"] == 0.0
    else:
        assert (d["wait_s"] > 0) == (d["deadline_misses"] > 0)
    with pytest.raises(ValueError, match="inference"):
        LearnedEstimator("mlp", checkpoint=tiny_checkpoints / "m", inference="process")


def test_short_window_datamodule_crops_the_windows() -> None:
    pytest.importorskip("lightning")
    from estimators.data import WindowDataModule

    rng = np.random.default_rng(0)
    arrays = {s: (rng.normal(size=(16, WINDOW_STEPS, N_FEATURES)).astype(np.float32),
                  rng.uniform(0.1, 1.2, 16).astype(np.float32)) for s in ("train", "val", "test")}
    dm = WindowDataModule(arrays=arrays, batch_size=8, crop_steps=12)
    dm.setup("fit")
    np.testing.assert_array_equal(dm.tensors["train"][0].numpy(), arrays["train"][0][:, -12:])
    with pytest.raises(ValueError, match="crop_steps"):
        WindowDataModule(arrays=arrays, crop_steps=0)


def test_staged_prediction_equals_the_forward_pass() -> None:
    torch = pytest.importorskip("torch")
    from estimators.models import EnsembleModel, ModelConfig, build_model

    x = torch.randn(2, WINDOW_STEPS, N_FEATURES)
    for cfg in (ModelConfig(variant="mlp", mlp_hidden=[8, 8], lower_quantile=0.1),
                ModelConfig(variant="linformer", tokens="step", d_model=16, linformer_k=8),
                ModelConfig(variant="attention", tokens="joint", d_model=8, n_heads=2, pooling="cls")):
        torch.manual_seed(0)
        model = build_model(cfg).eval()
        gen, n = model.predict_stages(x), 0
        while True:
            try:
                next(gen)
                n += 1
            except StopIteration as stop:
                staged = stop.value
                break
        assert n >= 2  # really sliced
        with torch.no_grad():
            z = (model.features(x) - model.norm.x_mean) / model.norm.x_std
            direct = model.encode(z)[:, 0] * model.norm.y_std + model.norm.y_mean
        assert torch.equal(staged[0], direct)
    ens = EnsembleModel([build_model(ModelConfig(variant="mlp", mlp_hidden=[8])).eval() for _ in range(2)])
    with torch.no_grad():
        mean = torch.stack([m(x)[0] for m in ens.members]).mean(0)
        assert torch.allclose(ens.predict(x)[0], mean)


def test_targets_choose_keeps_the_fit_sets_upper_ci_under_five_percent(monkeypatch: pytest.MonkeyPatch) -> None:
    from studies import estimator_targets as targets
    from studies.estimator_targets import choose, deployed, estimator_label, group_name

    monkeypatch.setattr(targets, "K_GRID", (0.0, 1.0))
    rng = np.random.default_rng(2)
    y = np.repeat(rng.uniform(0.1, 1.2, 300), 10)  # 300 episodes of 10 windows
    ep = np.repeat(np.arange(300), 10)
    sigma = np.where(y < 0.5, 0.01, 0.08)
    mean = y + np.where(y < 0.3, 0.05, 0.0) + rng.normal(0, 1, y.size) * sigma  # biased high at low friction
    d = {"mean": mean, "sigma": sigma, "lower": mean - sigma, "y": y, "episode": ep}
    c = choose(d, mu_min=0.05, n_boot=200, edges=(0.3, 0.5, 0.8))
    assert all(hi <= 0.05 for hi in c["fit_over_hi"].values()) and c["bound"] in ("gaussian", "quantile")
    rows = {r["band"]: r for r in band_rows(y, deployed(d, c, 0.05), ep, n_boot=200)}
    assert rows["0.1-0.3"]["over"] <= c["alpha"] + 1e-9 and rows["0.8-1.2"]["useful"] > 0.95
    assert group_name({"scenario": "friction_patch"}, {"friction": 0.8, "friction_after": 0.2}) == \
        "friction_patch mu=0.8->0.2"
    assert group_name({"scenario": "stress"}, {"friction": 0.3, "trunk_mass_scale": 1.6}) == "stress mu=0.3 trunk x1.6"
    assert estimator_label({"estimator": "fixed"}, {"mu": 0.2}) == "fixed (mu=0.2)"
    assert estimator_label({"estimator": "mlp"}, {"inference": "staged"}) == "mlp (staged)"
