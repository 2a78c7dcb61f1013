"""Evaluate shipped checkpoints on the in-distribution and shifted test sets (``python -m studies.estimator_evaluate``).

For every variant: MAE, RMSE, R², per-bin MAE, mean bias, over-estimation rate (mu_hat > mu + 0.05) and
uncertainty calibration (fraction of errors within 1 / 2 predicted sigma), for the raw mean and for the
conservative bound ``mean - k * sigma`` (each k of ``--k``); inference latency of one window (batch 1,
CPU, ``torch.no_grad``, 1 thread, median of ``--latency-runs`` after warm-up); parameter count; a
constant-predictor baseline (training mean). Writes ``metrics.csv``, ``report.md`` and
``regression_<variant>.png`` into ``--out`` and records the metrics in each checkpoint's JSON, including
the MAE on the committed 64-window fixture ``estimators/checkpoints/heldout64.npz`` (created from the
test split if missing).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np
import torch

from estimators.checkpoint import CHECKPOINT_DIR, checkpoint_paths, load_checkpoint
from estimators.data import load_split, load_windows, window_filter_mu
from estimators.features import with_filter_channels
from estimators.metrics import regression_metrics
from estimators.models import VARIANTS, FrictionModel, parameter_count
from taslel_bench.util import tables
from taslel_bench.util.machine import machine_info

FIXTURE = CHECKPOINT_DIR / "heldout64.npz"
K_SWEEP = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0)  # conservative-bound sigmas for the trade-off table
K_ROWS: list[dict[str, object]] = []  # filled by evaluate(), written by write_report()
JSON_PATHS: dict[str, Path] = {}  # variant name -> its checkpoint's .json (shipped name or a given path)
RESULTS_DIR = Path(__file__).resolve().parents[1] / "results" / "estimators"
# recorded by other studies in a checkpoint's metrics and kept when this one re-records them (the deployed
# bound of ``studies.estimator_targets offline --record``, which the configs must match)
KEPT_METRICS = ("safety_calibration",)


@torch.no_grad()
def predict(model: FrictionModel, X: np.ndarray, batch: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(mean [-], sigma [-]) for windows X (N, 40, 36)."""
    mean, sigma, _ = predict_all(model, X, batch)
    return mean, sigma


@torch.no_grad()
def predict_all(
    model: FrictionModel, X: np.ndarray, batch: int = 256
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(mean [-], sigma [-], lower quantile [-] or None) for windows X (N, 40, 36 or 38); windows with the
    filter features (38) serve a model without them too (sliced to ``model.cfg.n_raw``)."""
    X = X[..., : model.cfg.n_raw]
    means, sigmas, lowers = [], [], []
    for i in range(0, len(X), batch):
        m, lv, lo = model.predict(torch.from_numpy(X[i : i + batch]))
        means.append(m.numpy())
        sigmas.append(torch.exp(0.5 * lv).numpy())
        if lo is not None:
            lowers.append(lo.numpy())
    return np.concatenate(means), np.concatenate(sigmas), (np.concatenate(lowers) if lowers else None)


def window_filtered(data_dir: Path, split: str) -> np.ndarray | None:
    """Per-window flag "collected with the safety filter in the loop" (None for collections without it)."""
    with np.load(Path(data_dir) / f"{split}.npz") as f:
        return f["window_filtered"].astype(bool) if "window_filtered" in f.files else None


@torch.no_grad()
def latency_s(model: FrictionModel, runs: int = 200) -> float:
    """Median wall time [s] of one forward pass on one window (batch 1) with the current thread count."""
    x = torch.randn(1, model.cfg.window_steps, model.cfg.n_raw)
    for _ in range(10):
        model(x)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        model(x)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def select_k(model: FrictionModel, X: np.ndarray, y: np.ndarray, max_rate: float = 0.05,
             base: str = "mean") -> float | None:
    """Smallest k of :data:`K_SWEEP` whose bound max(0.05, b - k sigma) over-estimates (> truth + 0.05)
    at most ``max_rate`` of the windows of (X, y), with b the mean (``base="mean"``) or the lower-quantile
    head (``base="lower"``) — meant for the validation split, not a test split."""
    mean, sigma, lower = predict_all(model, X)
    b = mean if base == "mean" else lower
    if b is None:
        return None
    for k in K_SWEEP:
        if regression_metrics(y, np.maximum(b - k * sigma, 0.05))["overestimate_rate"] <= max_rate:
            return k
    return None


def make_fixture(data_dir: Path, n: int = 64, seed: int = 123) -> None:
    """Write ``n`` windows drawn (fixed seed) from the test split to the committed fixture, with their
    "collected with the safety filter in the loop" flags and the filter's mu per window (NaN: no filter)
    when the collection has them."""
    X, y, ep = load_split(data_dir, "test")
    idx = np.sort(np.random.default_rng(seed).choice(len(y), n, replace=False))
    wf = window_filtered(data_dir, "test")
    extra = {}
    if wf is not None:
        with np.load(Path(data_dir) / "test.npz") as f:
            extra = {"window_filtered": wf[idx], "filter_mu": window_filter_mu(f)[idx]}
    np.savez_compressed(FIXTURE, X=X[idx], y=y[idx], episode=ep[idx], **extra)


def fixture_mae(model: FrictionModel, subset: str | None = None) -> float:
    """MAE of the raw mean on the committed fixture; ``subset="filtered"`` / ``"nominal"``: only its
    windows collected with / without the safety filter in the loop (nan if the fixture has no flags)."""
    with np.load(FIXTURE) as f:
        sel = np.ones(len(f["y"]), bool)
        if subset is not None:
            if "window_filtered" not in f.files:
                return float("nan")
            sel = f["window_filtered"].astype(bool) == (subset == "filtered")
        X = f["X"].astype(np.float32)
        if model.cfg.filter_mu_input:
            if "filter_mu" not in f.files:
                raise ValueError(f"{FIXTURE} has no filter_mu record; regenerate it (make_fixture)")
            X = with_filter_channels(X, f["filter_mu"])
        mean, _ = predict(model, X[sel])
        return float(np.abs(mean - f["y"][sel]).mean())


def scatter_png(
    path: Path, variant: str, panels: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], k: float
) -> None:
    """Predicted vs true friction for each split (the paper's regression figure), mean and mean - k sigma."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.6), squeeze=False)
    for ax, (split, (y, mean, sigma)) in zip(axes[0], panels.items(), strict=True):
        ax.scatter(y, mean, s=3, alpha=0.35, label="mean")
        ax.scatter(y, mean - k * sigma, s=3, alpha=0.25, label=f"mean - {k:g} sigma")
        ax.plot([0, 1.3], [0, 1.3], "k--", lw=1)
        ax.plot([0, 1.3], [0.05, 1.35], "r:", lw=1, label="over-estimate margin")
        ax.set(xlabel="true friction [-]", ylabel="estimated friction [-]", xlim=(0, 1.3), ylim=(-0.1, 1.5),
               title=f"{variant} — {split} (MAE {np.abs(mean - y).mean():.3f})")
        ax.legend(loc="upper left", markerscale=4, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


BOUND_SELECTION: dict[str, str] = {}  # how the deployed bound was chosen (filled by evaluate, for the report)


_Windows = tuple[np.ndarray, np.ndarray]  # (windows X (N, 40, 38), true friction y (N,) [-])
_BoundSpec = tuple[str, float]  # (base: "mean" or "lower" quantile, k [sigmas]) of max(0.05, base - k sigma)
_Splits = dict[str, tuple[np.ndarray, ...]]  # split name -> (X, y, episode) of its windows
_Flags = dict[str, np.ndarray | None]  # split name -> per-window "filter in the loop" flags (None: no record)


def _bound(spec: _BoundSpec, mean: np.ndarray, sigma: np.ndarray, lower: np.ndarray | None) -> np.ndarray:
    """The bound max(0.05, base - k sigma) [-] of ``spec`` = (base, k) from the model outputs [-]."""
    b = mean if spec[0] == "mean" else lower
    return np.maximum(b - spec[1] * sigma, 0.05)  # type: ignore[operator]


def _load_evaluation_sets(data_dir: Path,
                          bound_set: Path | None) -> tuple[_Splits, _Flags, _Windows, _Windows]:
    """(test / shifted splits (X, y, episode), their per-window filter flags, the validation windows, the
    bound-selection windows: ``bound_set`` or the validation split); records the selection rule in
    :data:`BOUND_SELECTION`. Windows carry the filter features; predict_all slices them for models that do
    not read them."""
    splits = {s: load_split(data_dir, s, filter_mu=True) for s in ("test", "shifted")}
    flags = {s: window_filtered(data_dir, s) for s in splits}
    splits_val = load_split(data_dir, "val", filter_mu=True)[:2]
    if bound_set is not None:
        sel_set = load_windows(bound_set, filter_mu=True)[:2]
        BOUND_SELECTION.update(set=str(bound_set), rule="over-estimation <= 5 % on this set, lowest validation MAE")
    else:
        sel_set = splits_val
        BOUND_SELECTION.update(set="the validation split", rule="over-estimation <= 5 %, lowest validation MAE")
    return splits, flags, splits_val, sel_set


def _constant_rows(data_dir: Path, splits: _Splits) -> list[dict[str, object]]:
    """The baseline rows: every split's metrics of the constant predictor (the training mean friction [-])."""
    y_train_mean = float(load_split(data_dir, "train")[1].mean())
    rows: list[dict[str, object]] = []
    for split, (_, y, _) in splits.items():
        base = regression_metrics(y, np.full_like(y, y_train_mean))
        rows.append({"variant": "constant(train mean)", "split": split, "estimate": "mean", **base})
    return rows


def _candidate_bounds(model: FrictionModel, sel_set: _Windows, q: float,
                      recorded: dict[str, object]) -> dict[str, _BoundSpec]:
    """The candidate deployed bounds, by label: the smallest k of :data:`K_SWEEP` giving <= 5 %
    over-estimation on the selection set, for the mean and (models with a lower-quantile head, ``q`` > 0)
    the lower quantile, which is also a candidate with k = 0; records both k in ``recorded``."""
    k_val = select_k(model, *sel_set)
    k_val_q = select_k(model, *sel_set, base="lower")
    recorded["k_val_over_5pct"] = k_val
    recorded["k_val_over_5pct_quantile"] = k_val_q
    cand_spec: dict[str, _BoundSpec] = {} if k_val is None else {f"gaussian k={k_val:g}": ("mean", k_val)}
    if q > 0:
        cand_spec["quantile k=0"] = ("lower", 0.0)
        if k_val_q:  # the lower quantile alone over-estimates > 5 % of validation windows
            cand_spec[f"quantile k={k_val_q:g}"] = ("lower", k_val_q)
    return cand_spec


def _choose_bound(model: FrictionModel, cand_spec: dict[str, _BoundSpec], splits_val: _Windows,
                  sel_set: _Windows, recorded: dict[str, object]) -> str | None:
    """The label of the candidate with the lowest validation MAE among those over-estimating <= 5 % on the
    selection set (None: none does); records every candidate's validation metrics in ``recorded``."""
    mean_val, sigma_val, lower_val = predict_all(model, splits_val[0])
    mean_sel, sigma_sel, lower_sel = (
        (mean_val, sigma_val, lower_val) if sel_set is splits_val else predict_all(model, sel_set[0]))
    val_bounds: dict[str, dict[str, float]] = {}
    recorded["val_bounds"] = val_bounds
    recorded["bound_selection"] = dict(BOUND_SELECTION)
    for label, spec in cand_spec.items():
        mv = regression_metrics(splits_val[1], _bound(spec, mean_val, sigma_val, lower_val))
        ms = regression_metrics(sel_set[1], _bound(spec, mean_sel, sigma_sel, lower_sel))
        val_bounds[label] = {"mae": mv["mae"], "overestimate_rate": mv["overestimate_rate"],
                             "selection_set_overestimate_rate": ms["overestimate_rate"]}
    ok = {lb: v for lb, v in val_bounds.items() if v["selection_set_overestimate_rate"] <= 0.05}
    choice = min(ok, key=lambda lb: ok[lb]["mae"]) if ok else None
    recorded["val_bound_choice"] = choice
    return choice


def _estimates(mean: np.ndarray, sigma: np.ndarray, lower: np.ndarray | None, ks: list[float], q: float,
               choice: str | None, cand_spec: dict[str, _BoundSpec]) -> list[tuple[str, np.ndarray]]:
    """The estimates [-] evaluated on one split, by label: the raw mean, max(0.05, mean - k sigma) for each
    k of ``ks``, the lower quantile (if the model has one) and the chosen bound (if any)."""
    ests = [("mean", mean)] + [(f"mean-{k:g}sigma", np.maximum(mean - k * sigma, 0.05)) for k in ks]
    if lower is not None:
        ests.append((f"lower(q={q:g})", np.maximum(lower, 0.05)))
    if choice is not None:
        ests.append((f"chosen({choice})", _bound(cand_spec[choice], mean, sigma, lower)))
    return ests


def _subset_rows(row: dict[str, object], split: str, y: np.ndarray, sigma: np.ndarray, wf: np.ndarray | None,
                 ests: list[tuple[str, np.ndarray]], recorded: dict[str, object]) -> list[dict[str, object]]:
    """Rows of the raw mean, lower quantile and chosen bound on the nominal-controller and the
    filter-in-the-loop windows of ``split`` (flags ``wf``; no rows unless it has both kinds), also recorded
    in ``recorded``; ``row``: the variant's common cells."""
    rows: list[dict[str, object]] = []
    if wf is None or not 0 < wf.sum() < len(wf):  # nominal-controller vs filter-in-the-loop windows
        return rows
    for sub, sel in (("nominal", ~wf), ("filtered", wf)):
        for label, est in ests:
            if label != "mean" and not label.startswith(("lower", "chosen")):
                continue
            m = regression_metrics(y[sel], est[sel], sigma[sel])
            rows.append({"variant": row["variant"], "split": f"{split}[{sub}]", "estimate": label,
                         "params": row["params"], "latency_ms": row["latency_ms"], **m})
            recorded[f"{split}[{sub}]/{label}"] = {key: m[key] for key in
                                                   ("mae", "bias", "overestimate_rate")}
    return rows


def _estimate_rows(row: dict[str, object], split: str, y: np.ndarray, sigma: np.ndarray,
                   ests: list[tuple[str, np.ndarray]],
                   recorded: dict[str, object]) -> list[dict[str, object]]:
    """One row per estimate on all windows of ``split`` (truth ``y``, predicted ``sigma`` [-]), also recorded
    in ``recorded``; ``row``: the variant's common cells (variant, params, latency_ms)."""
    rows: list[dict[str, object]] = []
    for label, est in ests:
        m = regression_metrics(y, est, sigma)
        rows.append({"variant": row["variant"], "split": split, "estimate": label, "params": row["params"],
                     "latency_ms": row["latency_ms"], **m})
        recorded[f"{split}/{label}"] = {key: m[key] for key in
                                        ("mae", "rmse", "r2", "bias", "overestimate_rate",
                                         "within_1sigma", "within_2sigma")}
    return rows


def _record_metrics(model: FrictionModel, meta: dict, recorded: dict[str, object], lat: float, n_params: int,
                    json_path: Path) -> float:
    """Write the metrics (``recorded``, latency ``lat`` [s], parameters, fixture MAEs) into the checkpoint's
    JSON ``json_path``; returns the fixture MAE [-] of the raw mean."""
    fx = fixture_mae(model)
    kept = {k: v for k, v in meta.get("metrics", {}).items() if k in KEPT_METRICS}
    meta["metrics"] = {**kept, **recorded, "latency_ms_batch1_1thread": lat * 1e3, "parameters": n_params,
                       "fixture": FIXTURE.name, "fixture_mae": fx,
                       "fixture_mae_filtered": fixture_mae(model, "filtered"),
                       "fixture_mae_nominal": fixture_mae(model, "nominal")}
    json_path.write_text(json.dumps(meta, indent=2))
    return fx


def _record_k_sweep(variant: str, panels: dict[str, tuple[np.ndarray, ...]]) -> None:
    """Append to :data:`K_ROWS` the MAE, bias and over-estimation rate of max(0.05, mean - k sigma) for every
    k of :data:`K_SWEEP` on every split."""
    for split, (y, mean, sigma) in panels.items():
        for k in K_SWEEP:
            m = regression_metrics(y, np.maximum(mean - k * sigma, 0.05))
            K_ROWS.append({"variant": variant, "split": split, "k": k, "mae": m["mae"],
                           "bias": m["bias"], "overestimate_rate": m["overestimate_rate"]})


def _evaluate_variant(name: str, splits: _Splits, flags: _Flags, splits_val: _Windows, sel_set: _Windows,
                      ks: list[float], out_dir: Path, latency_runs: int) -> list[dict[str, object]]:
    """Evaluate one checkpoint (shipped name or path): choose its bound on validation data, measure every
    estimate on every split, record the metrics in its JSON, draw its regression figure; returns its rows."""
    model, meta = load_checkpoint(name)
    variant = checkpoint_paths(name)[0].stem
    JSON_PATHS[variant] = checkpoint_paths(name)[1]
    lat = latency_s(model, latency_runs)
    n_params = parameter_count(model)
    row = {"variant": variant, "params": n_params, "latency_ms": lat * 1e3}  # the cells common to its rows
    panels = {}
    recorded: dict[str, object] = {}
    q = float(meta["model"].get("lower_quantile", 0.0))
    # bound choice on validation data only: the candidates' (base, k) = the smallest k giving <= 5 %
    # over-estimation on the selection set (the validation split, or bound_set); the lowest validation
    # MAE among the candidates that hold <= 5 % there
    cand_spec = _candidate_bounds(model, sel_set, q, recorded)
    choice = _choose_bound(model, cand_spec, splits_val, sel_set, recorded)
    print(f"{variant}: validation bounds {recorded['val_bounds']} -> {choice}")
    k_val, k_val_q = recorded["k_val_over_5pct"], recorded["k_val_over_5pct_quantile"]
    print(f"{variant}: smallest k with validation over-estimation <= 5 %: mean {k_val}, "
          f"lower quantile {k_val_q}")
    rows: list[dict[str, object]] = []
    for split, (X, y, _) in splits.items():
        mean, sigma, lower = predict_all(model, X)
        panels[split] = (y, mean, sigma)
        ests = _estimates(mean, sigma, lower, ks, q, choice, cand_spec)
        rows += _estimate_rows(row, split, y, sigma, ests, recorded)
        rows += _subset_rows(row, split, y, sigma, flags.get(split), ests, recorded)
    fx = _record_metrics(model, meta, recorded, lat, n_params, checkpoint_paths(name)[1])
    scatter_png(out_dir / f"regression_{variant}.png", variant, panels, ks[0])
    _record_k_sweep(variant, panels)
    print(f"{variant}: test MAE {recorded['test/mean']['mae']:.4f}  shifted MAE "
          f"{recorded['shifted/mean']['mae']:.4f}  latency {lat * 1e3:.2f} ms  fixture MAE {fx:.4f}")
    return rows


def evaluate(data_dir: Path, variants: list[str], ks: list[float], out_dir: Path, latency_runs: int,
             bound_set: Path | None = None) -> list[dict[str, object]]:
    """Evaluate each variant; returns one row per (variant, split, estimate). ``bound_set``: a collected
    ``.npz`` (e.g. a shifted *validation* set, never a test split) on which the candidate bounds must
    over-estimate <= 5 % (default: the validation split); the validation MAE ranks them."""
    torch.set_num_threads(1)
    if not FIXTURE.is_file():
        make_fixture(data_dir)
    splits, flags, splits_val, sel_set = _load_evaluation_sets(data_dir, bound_set)
    rows = _constant_rows(data_dir, splits)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in variants:
        if not checkpoint_paths(name)[0].is_file():
            print(f"skip {name}: no checkpoint")
            continue
        rows += _evaluate_variant(name, splits, flags, splits_val, sel_set, ks, out_dir, latency_runs)
    return rows


def markdown_table(df: object) -> str:
    """A pipe table of a DataFrame, floats with 4 decimals (the core's table writer)."""
    return tables.markdown_table(df, fmt=lambda v: f"{v:.4f}" if isinstance(v, float) else str(v)).rstrip("\n")


def summary_table(df: object, names: list[str], ks: list[float], train_rec: dict[str, dict]) -> list[str]:
    """One row per variant: the headline numbers of the issue side by side."""
    head = ["variant", "params", "train wall [s]", "train CPU [s]", "latency [ms]", "test MAE", "test RMSE",
            "test R²", "test bias", "test over", "shifted MAE", "shifted RMSE", "shifted bias", "shifted over"]
    head += [f"shifted over (k={k:g})" for k in ks] + [f"shifted MAE (k={k:g})" for k in ks]
    head += ["test within 1σ / 2σ", "k for ≤5 % over on val", "lower-quantile head: test MAE / shifted MAE / shifted "
                                                              "over",
             "bound chosen on val: test MAE / test over / shifted MAE / shifted over"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def get(v: str, split: str, est: str, col: str) -> float:
        sel = df[(df.variant == v) & (df.split == split) & (df.estimate == est)]  # type: ignore[attr-defined]
        return float(sel[col].iloc[0]) if len(sel) else float("nan")

    for v in names:
        r = train_rec.get(v, {})
        t = get(v, "test", "mean", "mae")
        if np.isnan(t):
            continue
        cells = [v, str(int(get(v, "test", "mean", "params"))), str(r.get("train_wall_time_s", "n/a")),
                 str(r.get("train_cpu_time_s", "n/a")), f"{get(v, 'test', 'mean', 'latency_ms'):.2f}"]
        cells += [f"{get(v, 'test', 'mean', c):.3f}" for c in ("mae", "rmse", "r2", "bias")]
        cells += [f"{100 * get(v, 'test', 'mean', 'overestimate_rate'):.1f} %"]
        cells += [f"{get(v, 'shifted', 'mean', c):.3f}" for c in ("mae", "rmse", "bias")]
        cells += [f"{100 * get(v, 'shifted', 'mean', 'overestimate_rate'):.1f} %"]
        cells += [f"{100 * get(v, 'shifted', f'mean-{k:g}sigma', 'overestimate_rate'):.1f} %" for k in ks]
        cells += [f"{get(v, 'shifted', f'mean-{k:g}sigma', 'mae'):.3f}" for k in ks]
        cells += [f"{get(v, 'test', 'mean', 'within_1sigma'):.2f} / {get(v, 'test', 'mean', 'within_2sigma'):.2f}"]
        cells += [str(r.get("k_val"))]
        lo = [e for e in df[(df.variant == v) & (df.split == "shifted")].estimate if str(e).startswith("lower")]  # type: ignore[attr-defined]
        cells += [f"{get(v, 'test', lo[0], 'mae'):.3f} / {get(v, 'shifted', lo[0], 'mae'):.3f} / "
                  f"{100 * get(v, 'shifted', lo[0], 'overestimate_rate'):.1f} % ({lo[0]})" if lo else "—"]
        ch = [e for e in df[(df.variant == v) & (df.split == "shifted")].estimate if str(e).startswith("chosen")]  # type: ignore[attr-defined]
        cells += [f"{get(v, 'test', ch[0], 'mae'):.3f} / {100 * get(v, 'test', ch[0], 'overestimate_rate'):.1f} % / "
                  f"{get(v, 'shifted', ch[0], 'mae'):.3f} / {100 * get(v, 'shifted', ch[0], 'overestimate_rate'):.1f} "
                  f"% ({ch[0][7:-1]})" if ch else "none ≤ 5 % on val"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def subset_table(df: object, names: list[str]) -> list[str]:
    """Per variant and estimate: MAE / over-estimation rate on the nominal and filtered windows of each split."""
    subs = [f"{s}[{k}]" for s in ("test", "shifted") for k in ("nominal", "filtered")]
    if not any(df.split.isin(subs)):  # type: ignore[attr-defined]
        return ["(the collection has no filtered / nominal split)"]
    lines = ["| variant | estimate | " + " | ".join(f"{s} MAE / over" for s in subs) + " |",
             "|" + "---|" * (2 + len(subs))]
    for v in names:
        d = df[df.variant == v]  # type: ignore[attr-defined]
        for est in dict.fromkeys(d[d.split.isin(subs)].estimate):
            cells = []
            for s in subs:
                sel = d[(d.split == s) & (d.estimate == est)]
                cells.append(
                    f"{sel.mae.iloc[0]:.3f} / {100 * sel.overestimate_rate.iloc[0]:.1f} %" if len(sel) else "—"
                )
            lines.append(f"| {v} | {est} | " + " | ".join(cells) + " |")
    return lines


def _source_text(src: dict[str, object]) -> str:
    """One training source of a merged manifest: episodes kept, seed, plant draws, filter draws, throughput."""
    beta = float(src.get("plant_beta", 1.0))  # type: ignore[arg-type]
    plant = "uniform" if beta == 1.0 else f"lo + (hi - lo) Beta({beta:g}, {beta:g})"
    n_dropped = int((src.get("dropped_filtered") or {}).get("episodes", 0))  # type: ignore[union-attr]
    ff = float(src.get("filter_fraction") or 0.0)  # type: ignore[arg-type]
    if n_dropped:
        filt = f"nominal-controller episodes only, its {n_dropped} filtered episodes left out"
    elif ff == 0.0:
        filt = "no filter"
    elif src.get("filter_mu_range"):
        lo, hi = src["filter_mu_range"]  # type: ignore[misc]
        filt = f"filter in the loop for {ff:.0%}, its mu ~ U({lo:g}, {hi:g}) independent of the truth"
    else:
        lo, hi = src.get("filter_mu_scale") or (1.0, 1.0)  # type: ignore[misc]
        filt = f"filter in the loop for {ff:.0%}, its mu = truth x U({lo:g}, {hi:g})"
    return (f"{int(src['train_episodes']) - n_dropped} episodes (seed {src['seed']}, plant factors {plant}, "  # type: ignore[arg-type]
            f"{filt}, {float(src['env_steps_per_s']):,.0f} env-steps/s)")  # type: ignore[arg-type]


def _training_records(names: list[str]) -> dict[str, dict]:
    """Per variant: the training record of its checkpoint's JSON, with the validation-chosen k
    (``k_val``) and whether the model reads the filter's mu (``filter_mu_input``); variants without a JSON
    are left out."""
    train_rec = {}
    for v in names:
        js = JSON_PATHS.get(v, checkpoint_paths(v)[1])
        if js.is_file():
            full = json.loads(js.read_text())
            train_rec[v] = {**full.get("training", {}),
                            "k_val": full.get("metrics", {}).get("k_val_over_5pct"),
                            "filter_mu_input": bool(full.get("model", {}).get("filter_mu_input", False))}
    return train_rec


def _metrics_table(df: object) -> object:
    """The columns of the metrics DataFrame shown in the report's "All metrics" table (per-bin MAE last)."""
    cols = ["variant", "split", "estimate", "mae", "rmse", "r2", "bias", "overestimate_rate",
            "within_1sigma", "within_2sigma"] + [c for c in df.columns if c.startswith("mae_bin")]
    return df[[c for c in cols if c in df]].copy()  # type: ignore[index]


def _k_tradeoff_table(out_dir: Path) -> str:
    """Write ``k_tradeoff.csv`` from :data:`K_ROWS` and return its pivot (MAE and over-estimation rate per
    variant, k [sigmas] and split) as a markdown table."""
    import pandas as pd

    kdf = pd.DataFrame(K_ROWS)
    if len(kdf):
        kdf.to_csv(out_dir / "k_tradeoff.csv", index=False)
        piv = kdf.pivot_table(index=["variant", "k"], columns="split", values=["mae", "overestimate_rate"])
        piv.columns = [f"{split} {metric}" for metric, split in piv.columns]
        k_table = markdown_table(piv.reset_index())
    else:
        k_table = "(no variants evaluated)"
    return k_table


def _splits_line(manifest: dict) -> str:
    """The report's line on the collection's splits: episodes, windows, falls (and filtered episodes)."""
    return "- Splits by episode: " + ", ".join(
        f"{s} {i['episodes']} episodes / {i['windows']} windows ({i['episodes_fallen']} fell"
        + (f"; {i['episodes_filtered']} episodes with the safety filter in the loop"
           if "episodes_filtered" in i else "")
        + ")"
        for s, i in manifest["splits"].items()) + "."


def _filter_lines(manifest: dict) -> list[str]:
    """The report's line on the safety filter in the collection loop (none if no episode had it)."""
    if not manifest.get("filter_fraction"):
        return []
    return [(f"- Safety filter in the loop for a fraction {manifest['filter_fraction']} of the episodes "
             f"(ID-CBF-QP through `taslel_bench.api`, the filter's mu = true floor friction x "
             f"U({manifest.get('filter_mu_scale', [1, 1])[0]:g}, "
             f"{manifest.get('filter_mu_scale', [1, 1])[1]:g}) per episode, "
             "features hold the filtered torque); "
             "per worker: nominal episodes "
             f"{manifest['env_steps_per_s_per_worker']['nominal'] or 0:,.0f} env-steps/s, "
             f"filtered {manifest['env_steps_per_s_per_worker']['filtered'] or 0:,.0f} env-steps/s. Rows "
             "`test[nominal]` / `test[filtered]` split the test windows by how they were collected.")]


def _data_section(manifest: dict, base: object, data_dirs: dict[str, str] | None = None) -> list[str]:
    """The report's "Data" section: collection throughput (env-steps/s), splits, filter, training sources,
    each variant's training folder (``data_dirs``), plant ranges and the constant predictor's MAE [-]
    (``base``: per split)."""
    data_dirs = data_dirs or {}
    return [
        "## Data",
        "",
        (f"- Collection (`python -m estimators.collect`): {manifest['env_steps']:,} env steps in "
        f"{manifest['wall_time_s']:.0f} s with {manifest['workers']} processes = "
        f"**{manifest['env_steps_per_s']:,.0f} env-steps/s** (paper: 100,000 steps/s, Isaac Gym, 4096 A1s, "
        f"RTX 3080) — one env step = one 1 ms MuJoCo step plus the Python nominal controller (and, in "
        "filtered episodes, the ID-CBF-QP safety filter)."),
        _splits_line(manifest),
        *_filter_lines(manifest),
        *([ "- Training split = " + " + ".join(_source_text(src) for src in manifest["sources"])
            + "; val / test / shifted: the first collection, uniform draws."] if "sources" in manifest else []),
        *([ "- Each variant's training data (`data_dir` of its checkpoint's training record; the lines above "
            "describe the `--data` folder only): " + "; ".join(f"`{v}`: `{d}`" for v, d in data_dirs.items())
            + "."] if data_dirs else []),
        f"- Training ranges: `{json.dumps(manifest['train_ranges'])}`",
        (f"- Shifted ranges (outside training in every plant quantity): `{json.dumps(manifest['shifted_ranges'])}`"
        " (CoM shift: magnitude, random sign)."),
        (f"- Constant predictor (training mean) MAE: test {base.get('test', float('nan')):.3f}, "
        f"shifted {base.get('shifted', float('nan')):.3f}."),
        "",
    ]


def _summary_section(df: object, names: list[str], ks: list[float], train_rec: dict[str, dict]) -> list[str]:
    """The report's "Summary" section: how the bound was chosen, the summary table and the models that read
    the filter's mu."""
    return [
        "## Summary",
        "",
        (f"Bound chosen on validation data: {BOUND_SELECTION.get('rule', '')}, on {BOUND_SELECTION.get('set', '')} "
        "(columns `k for ≤5 % over on val` and `bound chosen on val` use it; the configs deploy it). "
        "`over`: over-estimation rate, estimate > truth + 0.05. `k`: the conservative bound "
        "max(0.05, mean - k sigma) that `LearnedEstimator(conservative_k=k)` reports. Latency: one window, "
        "batch 1, CPU, 1 torch thread, `torch.no_grad`, median of repeated calls after warm-up. Train wall / "
        "CPU: Lightning `fit` wall-clock and process CPU time (the 2 cores were shared with other jobs); for a "
        "seed ensemble (`members` in the training records, `python -m estimators.train ensemble=n`) the wall "
        "time of all members trained side by side (one process and core each) and the sum of their CPU times, "
        "and the latency is that of the whole ensemble. "
        "within 1σ / 2σ: fraction of |error of the mean| <= 1 / 2 predicted sigma (calibrated: 0.68 / 0.95)."),
        "",
        *summary_table(df, names, ks, train_rec),
        "",
        "Models that also read the filter's mu per sample (`filter_mu_input`: filter in the loop 0/1 and the "
        "mu it assumed; in the loop `Proprioception.filter_mu`, on the test windows the collection's per-episode "
        "filter mu): " + (", ".join(f"`{v}`" for v in names if train_rec.get(v, {}).get("filter_mu_input")) or "none")
        + "; the others read q, qdot, tau only.",
        "",
    ]


def _subset_and_tradeoff_sections(df: object, names: list[str], k_table: str) -> list[str]:
    """The report's nominal-vs-filtered windows section and the conservative-bound trade-off section."""
    return [
        "## Nominal-controller vs filter-in-the-loop windows",
        "",
        ("The same metrics on the windows of episodes collected under the nominal controller only and of "
        "episodes with the safety filter in the loop (`test[nominal]`, `test[filtered]`, ...), for the raw "
        "mean and the lower-quantile head (where the model has one)."),
        "",
        *subset_table(df, names),
        "",
        "## Conservative bound trade-off",
        "",
        ("Estimate max(0.05, mean - k sigma) for several k (`k_tradeoff.csv`): MAE and over-estimation rate on "
        "the in-distribution test set and the shifted set. k is a deployment choice; the configs use "
        "`conservative_k` from `conf/estimator/<variant>.yaml`."),
        "",
        k_table,
        "",
    ]


def _appendix_sections(table: object, train_rec: dict[str, dict], names: list[str]) -> list[str]:
    """The report's closing sections: all metrics, training records, machine and the figure list."""
    return [
        "## All metrics",
        "",
        markdown_table(table),
        "",
        "## Training records",
        "",
        "```",
        json.dumps({v: {k: r.get(k) for k in ("train_wall_time_s", "train_cpu_time_s", "members", "epochs",
                                              "global_steps", "best_val_mae", "variance_scale_fitted_on_val",
                                              "torch_threads", "note") if r.get(k) is not None}
                    for v, r in train_rec.items()}, indent=1),
        "```",
        "",
        "## Machine",
        "",
        "```",
        json.dumps(machine_info(), indent=2),
        "```",
        "",
        "Figures: " + ", ".join(f"`regression_{v}.png`" for v in names) + ".",
    ]


def write_report(rows: list[dict[str, object]], out_dir: Path, data_dir: Path, ks: list[float],
                 command: str | None = None) -> None:
    """Write ``metrics.csv`` (one row per variant, split and estimate), ``k_tradeoff.csv`` and ``report.md``
    into ``out_dir``; the data section reads ``data_dir/manifest.json``; ``command``: the command line that
    regenerates the report (in its header)."""
    import pandas as pd

    df = pd.DataFrame(rows)
    df.to_csv(out_dir / "metrics.csv", index=False)
    manifest = json.loads((data_dir / "manifest.json").read_text())
    names = [n for n in dict.fromkeys(df.variant) if not n.startswith("constant")]
    train_rec = _training_records(names)
    base = df[df.variant.str.startswith("constant")].set_index("split")["mae"]
    table = _metrics_table(df)
    k_table = _k_tradeoff_table(out_dir)
    lines = [
        "# Terrain estimators: friction from proprioception",
        "",
        "Generated by `python -m studies.estimator_evaluate`; every number is measured on this machine.",
        *([f"Command: `{command}`"] if command else []),
        "",
        *_data_section(manifest, base, {v: str(r.get("train_config", {}).get("data_dir"))
                                        for v, r in train_rec.items() if r.get("train_config")}),
        *_summary_section(df, names, ks, train_rec),
        *_subset_and_tradeoff_sections(df, names, k_table),
        *_appendix_sections(table, train_rec, names),
    ]
    (out_dir / "report.md").write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=Path("/work/data/estimators"))
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS),
                    help="shipped checkpoint names (mlp attention linformer) or paths to .pt files")
    ap.add_argument("--k", type=float, nargs="+", default=[1.0, 2.0], help="conservative bound sigmas")
    ap.add_argument("--out", type=Path, default=RESULTS_DIR)
    ap.add_argument("--latency-runs", type=int, default=200)
    ap.add_argument("--bound-set", type=Path, default=None, metavar="NPZ",
                    help="collected windows (e.g. a shifted validation set, never a test split) on which the "
                         "deployed bound must over-estimate <= 5 %% (default: the validation split)")
    a = ap.parse_args(argv)
    rows = evaluate(a.data, a.variants, a.k, a.out, a.latency_runs, a.bound_set)
    cmd = "python -m studies.estimator_evaluate " + " ".join(
        shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:])
    )
    write_report(rows, a.out, a.data, a.k, cmd)
    print(f"wrote {a.out}/report.md, metrics.csv")


if __name__ == "__main__":
    main()
