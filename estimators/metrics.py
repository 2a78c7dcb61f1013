"""Regression metrics of friction estimates (numpy only). All errors are in friction units [-]."""

from __future__ import annotations

import itertools

import numpy as np

from taslel_bench.interfaces import overestimates

FRICTION_BINS = (0.1, 0.3, 0.5, 0.7, 0.9, 1.2001)  # [-] bin edges for the per-bin MAE


def regression_metrics(y: np.ndarray, mu_hat: np.ndarray, sigma: np.ndarray | None = None) -> dict[str, float]:
    """MAE, RMSE, R², mean bias (mu_hat - y), over-estimation rate, per-bin MAE and, with ``sigma``, the
    fraction of errors within 1 and 2 sigma (a calibrated Gaussian gives 0.683 and 0.954)."""
    y, mu_hat = np.asarray(y, float), np.asarray(mu_hat, float)
    err = mu_hat - y
    ss_tot = float(((y - y.mean()) ** 2).sum())
    out: dict[str, float] = {
        "n": float(len(y)),
        "mae": float(np.abs(err).mean()),
        "rmse": float(np.sqrt((err**2).mean())),
        "r2": float(1.0 - (err**2).sum() / ss_tot) if ss_tot > 0 else float("nan"),
        "bias": float(err.mean()),
        "overestimate_rate": float(overestimates(mu_hat, y).mean()),
    }
    for lo, hi in itertools.pairwise(FRICTION_BINS):
        sel = (y >= lo) & (y < hi)
        out[f"mae_bin_{lo:.1f}_{min(hi, 1.2):.1f}"] = float(np.abs(err[sel]).mean()) if sel.any() else float("nan")
    if sigma is not None:
        s = np.asarray(sigma, float)
        out["mean_sigma"] = float(s.mean())
        out["within_1sigma"] = float((np.abs(err) <= s).mean())
        out["within_2sigma"] = float((np.abs(err) <= 2 * s).mean())
    return out
