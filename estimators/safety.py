"""One-sided safety targets of friction estimates, per friction band, with episode-bootstrap CIs (numpy only).

What matters to the safety filter is one-sided: never claim more friction than there is where
friction is low, and do not starve the gait.

* **over-estimation**: ``mu_hat > mu + 0.05``; target P(over | mu < 0.5) <= 5 % (checked per band 0.1-0.3
  and 0.3-0.5 and pooled below 0.5);
* **usefulness**: ``mu_hat >= min(mu, 0.5) - 0.1``; target >= 95 % of windows (per band), or, instead,
  the capped MAE ``mean |min(mu_hat, 0.6) - min(mu, 0.6)|`` <= 0.03.

Every rate is a ratio of counts over windows (or control ticks); its 95 % CI comes from resampling whole
episodes (runs) with replacement, so windows of one episode, which are strongly correlated, count as one
draw (:func:`ratio_ci`).

:class:`BandMargin` is the band-aware conservatism of :class:`estimators.learned.LearnedEstimator`: a margin
subtracted from the bound that depends on the band of the model's raw mean; :func:`fit_band_margin`
chooses the margins on a (shifted *validation*) set.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from taslel_bench.interfaces import OVERESTIMATE_MARGIN
from taslel_bench.interfaces import overestimates as is_overestimate

BANDS: tuple[tuple[float, float], ...] = ((0.1, 0.3), (0.3, 0.5), (0.5, 0.8), (0.8, 1.2))  # [-] truth bands
LOW_MU = 0.5  # [-] the over-estimation target conditions on mu below this
OVER_MARGIN = OVERESTIMATE_MARGIN  # [-] mu_hat above mu + this is an over-estimate (the core's one margin)
USEFUL_CAP = 0.5  # [-] usefulness: mu_hat >= min(mu, USEFUL_CAP) - USEFUL_SLACK
USEFUL_SLACK = 0.1  # [-]
MAE_CAP = 0.6  # [-] capped MAE: estimate and truth capped here
OVER_TARGET = 0.05
USEFUL_TARGET = 0.95
CAPPED_MAE_TARGET = 0.03
CI_HALF_WIDTH_TARGET = 0.02  # the low band's over-estimation CI half-width must be at most this


def band_label(lo: float, hi: float) -> str:
    return f"{lo:.1f}-{hi:.1f}"


def band_mask(y: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Truth in [lo, hi) (the top band includes its upper edge)."""
    y = np.asarray(y, float)
    return (y >= lo) & ((y < hi) | ((hi == BANDS[-1][1]) & (y <= hi + 1e-9)))


def overestimates(y: np.ndarray, mu_hat: np.ndarray) -> np.ndarray:
    """mu_hat > y + OVERESTIMATE_MARGIN per window (the core's one predicate, truth first here)."""
    return is_overestimate(mu_hat, y)


def useful(y: np.ndarray, mu_hat: np.ndarray) -> np.ndarray:
    return np.asarray(mu_hat, float) >= np.minimum(np.asarray(y, float), USEFUL_CAP) - USEFUL_SLACK


def capped_error(y: np.ndarray, mu_hat: np.ndarray) -> np.ndarray:
    return np.abs(np.minimum(np.asarray(mu_hat, float), MAE_CAP) - np.minimum(np.asarray(y, float), MAE_CAP))


def ratio_ci(num: np.ndarray, den: np.ndarray, groups: np.ndarray, n_boot: int = 2000, seed: int = 0,
             level: float = 0.95) -> tuple[float, float, float]:
    """sum(num) / sum(den) and its percentile CI from resampling the groups (episodes) with replacement.

    ``num``, ``den``: per-window values (e.g. over-estimate flags and ones); ``groups``: per-window
    episode ids. Returns (point, lo, hi); nan when ``den`` sums to 0."""
    num, den = np.asarray(num, float), np.asarray(den, float)
    _, g = np.unique(np.asarray(groups), return_inverse=True)
    n_g = int(g.max()) + 1 if g.size else 0
    if n_g == 0 or den.sum() <= 0:
        return float("nan"), float("nan"), float("nan")
    num_g = np.bincount(g, num, n_g)
    den_g = np.bincount(g, den, n_g)
    point = float(num_g.sum() / den_g.sum())
    rng = np.random.default_rng(seed)
    w = rng.multinomial(n_g, np.full(n_g, 1.0 / n_g), size=n_boot).astype(float)  # (B, G) resample counts
    d = w @ den_g
    r = np.divide(w @ num_g, d, out=np.full(n_boot, np.nan), where=d > 0)
    r = r[np.isfinite(r)]
    a = (1.0 - level) / 2.0
    return point, float(np.quantile(r, a)), float(np.quantile(r, 1.0 - a))


def band_rows(y: np.ndarray, mu_hat: np.ndarray, groups: np.ndarray, n_boot: int = 2000,
              seed: int = 0) -> list[dict[str, object]]:
    """Per truth band (and pooled below 0.5): windows, episodes, over-estimation, usefulness and capped MAE,
    each with its episode-bootstrap 95 % CI."""
    y, mu_hat, groups = np.asarray(y, float), np.asarray(mu_hat, float), np.asarray(groups)
    over, use, cerr = overestimates(y, mu_hat), useful(y, mu_hat), capped_error(y, mu_hat)
    rows = []
    sets = [(band_label(lo, hi), band_mask(y, lo, hi)) for lo, hi in BANDS]
    sets.append((f"<{LOW_MU:.1f}", y < LOW_MU))
    for label, sel in sets:
        row: dict[str, object] = {"band": label, "windows": int(sel.sum()),
                                  "episodes": int(np.unique(groups[sel]).size)}
        for name, v in (("over", over), ("useful", use), ("capped_mae", cerr)):
            p, lo, hi = ratio_ci(np.where(sel, v, 0.0), sel.astype(float), groups, n_boot, seed)
            row.update({name: p, f"{name}_lo": lo, f"{name}_hi": hi})
        rows.append(row)
    return rows


def verdict(rows: list[dict[str, object]]) -> dict[str, bool]:
    """Targets met on these rows: ``over`` (every band below 0.5 and the pooled one <= 5 %, point
    estimates), ``useful`` (every band >= 95 % useful windows, or capped MAE <= 0.03), ``ci`` (the
    0.1-0.3 band's over-estimation CI half-width <= 2 %)."""
    by = {r["band"]: r for r in rows}
    low = [band_label(lo, hi) for lo, hi in BANDS if hi <= LOW_MU] + [f"<{LOW_MU:.1f}"]
    bands = [band_label(lo, hi) for lo, hi in BANDS]
    ok_over = all(float(by[b]["over"]) <= OVER_TARGET for b in low if by[b]["windows"])
    ok_use = all(float(by[b]["useful"]) >= USEFUL_TARGET or float(by[b]["capped_mae"]) <= CAPPED_MAE_TARGET
                 for b in bands if by[b]["windows"])
    first = by[bands[0]]
    half = (float(first["over_hi"]) - float(first["over_lo"])) / 2.0
    return {"over": ok_over, "useful": ok_use, "ci": bool(half <= CI_HALF_WIDTH_TARGET)}


@dataclass(frozen=True)
class BandMargin:
    """Band-aware margin [-]: ``margins[i]`` is subtracted from the bound when the model's raw mean lies in
    band i of ``edges`` (``edges`` (n,) ascending -> n + 1 bands: below edges[0], ..., at or above
    edges[-1])."""

    edges: tuple[float, ...] = (0.3, 0.5, 0.8)
    margins: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if len(self.margins) != len(self.edges) + 1:
            raise ValueError(f"BandMargin needs len(edges) + 1 margins, got {len(self.edges)} edges and "
                             f"{len(self.margins)} margins")
        if any(b <= a for a, b in itertools.pairwise(self.edges)):
            raise ValueError(f"BandMargin edges must be strictly ascending, got {self.edges}")
        if not all(np.isfinite(m) and m >= 0 for m in self.margins):
            raise ValueError(f"BandMargin margins must be finite and >= 0, got {self.margins}")

    def margin(self, mean: np.ndarray | float) -> np.ndarray:
        idx = np.searchsorted(np.asarray(self.edges, float), np.asarray(mean, float), side="right")
        return np.asarray(self.margins, float)[idx]

    def apply(self, mean: np.ndarray | float, bound: np.ndarray | float) -> np.ndarray:
        """``bound - margin(mean)``."""
        return np.asarray(bound, float) - self.margin(mean)

    def to_dict(self) -> dict[str, list[float]]:
        return {"edges": [float(e) for e in self.edges], "margins": [float(m) for m in self.margins]}


def fit_band_margin(y: np.ndarray, mean: np.ndarray, bound: np.ndarray, mu_min: float,
                    edges: tuple[float, ...] = (0.3, 0.5, 0.8), grid: np.ndarray | None = None,
                    max_over: float = 0.03) -> tuple[BandMargin, dict[str, float]] | None:
    """Margins (one per band of the raw mean, from ``grid``) that keep the over-estimation rate of every
    truth band below 0.5 (0.1-0.3, 0.3-0.5) at most ``max_over`` on (y, mean, bound) and, among those,
    maximise the smallest per-truth-band usefulness (ties: the most useful windows overall, then the
    smallest total margin). The search is exhaustive over the grid^(bands) combinations: the windows of
    each mean band contribute to the counts independently of the other bands' margins. None if no
    combination meets ``max_over``. Returns the margin and its rates on this set."""
    y, mean, bound = (np.asarray(a, float) for a in (y, mean, bound))
    grid = np.round(np.arange(0.0, 0.301, 0.01), 4) if grid is None else np.asarray(grid, float)
    idx = np.searchsorted(np.asarray(edges, float), mean, side="right")
    n_b, n_m = len(edges) + 1, len(grid)
    low_bands = [band_mask(y, lo, hi) for lo, hi in BANDS if hi <= LOW_MU]
    all_bands = [band_mask(y, lo, hi) for lo, hi in BANDS]
    over = np.zeros((len(low_bands), n_b, n_m))  # over-estimate counts per truth band, mean band, margin
    use = np.zeros((len(all_bands), n_b, n_m))  # useful counts per truth band, mean band, margin
    for b in range(n_b):
        in_b = idx == b
        for j, m in enumerate(grid):
            mu = np.maximum(bound[in_b] - m, mu_min)
            ov, us = overestimates(y[in_b], mu), useful(y[in_b], mu)
            for t, sel in enumerate(low_bands):
                over[t, b, j] = ov[sel[in_b]].sum()
            for t, sel in enumerate(all_bands):
                use[t, b, j] = us[sel[in_b]].sum()

    def combine(a: np.ndarray) -> np.ndarray:  # (T, n_b, n_m) -> (T, n_m, ..., n_m): sum over mean bands
        tot = a[:, 0, :]
        for b in range(1, n_b):
            tot = tot[..., None] + a[:, b, :].reshape((a.shape[0],) + (1,) * b + (n_m,))
        return tot

    shape = (-1,) + (1,) * n_b
    n_low = np.array([s.sum() for s in low_bands], float)
    n_all = np.array([s.sum() for s in all_bands], float)
    ok = np.all(combine(over) <= max_over * n_low.reshape(shape) + 1e-9, axis=0)
    if not ok.any():
        return None
    tot_use = combine(use)
    has = n_all > 0
    worst = np.min(tot_use[has] / n_all[has].reshape(shape), axis=0)
    pooled = tot_use.sum(0) / max(n_all.sum(), 1)
    tot_m = combine(np.broadcast_to(grid, (1, n_b, n_m)))[0]
    score = np.where(ok, worst + 1e-4 * pooled - 1e-7 * tot_m, -np.inf)
    pick = np.unravel_index(int(np.argmax(score)), score.shape)
    bm = BandMargin(tuple(float(e) for e in edges), tuple(float(grid[i]) for i in pick))
    mu = np.maximum(bm.apply(mean, bound), mu_min)
    info = {"useful": float(useful(y, mu).mean()), "useful_worst_band": float(worst[pick])}
    for (lo, hi), sel in zip([b for b in BANDS if b[1] <= LOW_MU], low_bands, strict=True):
        info[f"over_{band_label(lo, hi)}"] = float(overestimates(y[sel], mu[sel]).mean()) if sel.any() else float("nan")
    return bm, info
