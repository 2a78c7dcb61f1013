"""Rates over the worst window of an episode, so a local violation cannot hide in the episode's mean.

A rate is a count of bad events over a count of judged ones (per tick: ``bad[k]``, ``judged[k]``). Its worst
window is the largest ratio over every window of :data:`WINDOW_S` of consecutive ticks (sliding by one
tick) that holds at least one judged event; an episode shorter than the window is one window.
"""

from __future__ import annotations

import math

import numpy as np

WINDOW_S = 0.5  # [s] length of the sliding window of the ``*_worst_window`` rates


def window_ticks(dt: float, window_s: float = WINDOW_S) -> int:
    """Ticks in a window of ``window_s`` [s] at control period ``dt`` [s] (at least 1)."""
    return max(1, round(window_s / dt))


def worst_window_rate(bad: np.ndarray, judged: np.ndarray, ticks: int) -> float:
    """max over windows of ``ticks`` consecutive rows of sum(bad) / sum(judged); ``bad`` and ``judged``:
    per-tick counts (n,) (or per-tick arrays whose other axes are summed). NaN when nothing is judged."""
    bad = _per_tick(bad)
    judged = _per_tick(judged)
    if judged.size == 0 or judged.sum() <= 0:
        return math.nan
    ticks = min(ticks, bad.size)
    cb = np.concatenate([[0.0], np.cumsum(bad)])
    cj = np.concatenate([[0.0], np.cumsum(judged)])
    num, den = cb[ticks:] - cb[:-ticks], cj[ticks:] - cj[:-ticks]
    ok = den > 0
    return float(np.max(num[ok] / den[ok]))


def _per_tick(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, float)
    return x.reshape(x.shape[0], int(np.prod(x.shape[1:]))).sum(axis=1) if x.ndim > 1 else x
