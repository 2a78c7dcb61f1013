"""Summary numbers of an episode from its chunks, in memory that does not grow with the episode's length.

A :class:`Reducer` holds one reduction per summary key, fed chunk by chunk and read once at the end:

* ``mean``/``rms`` (sum and count), ``total``, ``ratio`` (two counts), ``max``/``min``: a few numbers each.
  Sums are exact (:class:`ExactSum`: the float values summed as integers) and rounded once at the end, so a
  mean is the same number whatever the chunks (it is the correctly rounded mean; numpy's pairwise sum over
  the whole series can differ from it in the last bit or two, ~1e-16 relative);
* ``pct``/``median``: :class:`Quantiles`: exact (every value kept, 8 bytes each) up to
  :data:`EXACT_QUANTILE_VALUES` values per key, then a log-bucketed histogram with relative accuracy
  :data:`SKETCH_RELATIVE_ACCURACY` (the DDSketch idea: bucket i holds values in (gamma^(i-1), gamma^i],
  gamma = (1 + a) / (1 - a), so any value read back is within a relative error a of a value of that rank);
  its memory is fixed, whatever the episode's length. A 10 s run at 500 Hz stays exact; the keys that were
  read from a histogram are listed by :meth:`Reducer.sketched_keys` (``percentiles_from_histogram`` in the
  summary);
* ``window``: the worst sliding-window rate (:mod:`taslel_bench.metrics.windows`) with the last window's
  per-tick counts carried across the chunk boundary (integer counts: exact).

Order of the result: the order in which keys were first fed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

_SCALE_BITS = 1200  # every float64 (subnormals too) is an integer multiple of 2**-1074 (+ 53 bits of margin)


class ExactSum:
    """The exact sum of float64 values fed in any grouping (each value x = m 2**(e - 53) with an integer
    mantissa m; mantissas summed per exponent in int64 halves, combined as one Python integer scaled by
    2**_SCALE_BITS). Non-finite values are summed apart (nan or ±inf, as a float sum would give)."""

    def __init__(self) -> None:
        self.scaled, self.nonfinite = 0, 0.0

    def add(self, x: np.ndarray) -> None:
        x = np.asarray(x, float).ravel()
        finite = np.isfinite(x)
        if not finite.all():
            self.nonfinite += float(x[~finite].sum())
            x = x[finite]
        if not x.size:
            return
        mant, exp = np.frexp(x)
        m = (mant * 2.0**53).astype(np.int64)  # exact: |m| < 2**53
        hi = m >> 26
        lo = m - (hi << 26)
        exps, inverse = np.unique(exp, return_inverse=True)
        sum_hi, sum_lo = np.zeros(exps.size, np.int64), np.zeros(exps.size, np.int64)
        np.add.at(sum_hi, inverse, hi)
        np.add.at(sum_lo, inverse, lo)
        for e, h, low in zip(exps.tolist(), sum_hi.tolist(), sum_lo.tolist(), strict=True):
            self.scaled += ((h << 26) + low) << (int(e) - 53 + _SCALE_BITS)

    def divided(self, count: int) -> float:
        """The sum / ``count``, rounded once (nan without values)."""
        if not count:
            return math.nan
        if self.nonfinite != 0.0 or math.isnan(self.nonfinite):
            return float(self.nonfinite)
        return self.scaled / (count << _SCALE_BITS)


class _Mean:
    def __init__(self) -> None:
        self.s, self.c = ExactSum(), 0

    def add(self, x: np.ndarray) -> None:
        if x.size:
            self.s.add(x)
            self.c += x.size

    def value(self) -> float:
        return float(self.s.divided(self.c))


class _Rms(_Mean):
    """sqrt(mean(x²)) of the finite values."""

    def add(self, x: np.ndarray) -> None:
        x = x[np.isfinite(x)]
        super().add(x * x)

    def value(self) -> float:
        return float(np.sqrt(self.s.divided(self.c))) if self.c else math.nan


class _Total(_Mean):
    def value(self) -> float:
        return float(self.s.divided(1)) if self.c else 0.0


class _Ratio:
    def __init__(self) -> None:
        self.num, self.den = 0, 0

    def add(self, num, den) -> None:
        self.num, self.den = self.num + num.item() if hasattr(num, "item") else self.num + num, self.den + int(den)

    def value(self) -> float:
        return float(self.num / self.den) if self.den else math.nan


EXACT_QUANTILE_VALUES = 1 << 17  # values kept exactly per percentile key (1 MB); beyond: the histogram
SKETCH_RELATIVE_ACCURACY = 1e-3  # a: relative error of a percentile read from the histogram
_SKETCH_MIN_ABS = 1e-12  # |x| below this counts as 0 (every summary quantity is in SI units: m, N, us, ...)
_SKETCH_MAX_ABS = 1e12  # |x| above this is kept in the outermost bucket (and stated by the value it reads)
_GAMMA = (1.0 + SKETCH_RELATIVE_ACCURACY) / (1.0 - SKETCH_RELATIVE_ACCURACY)
_LOG_GAMMA = math.log(_GAMMA)
_I_MIN = math.ceil(math.log(_SKETCH_MIN_ABS) / _LOG_GAMMA)
_N_BUCKETS = math.ceil(math.log(_SKETCH_MAX_ABS) / _LOG_GAMMA) - _I_MIN + 1


class Quantiles:
    """Percentiles of a stream of values (``pct``/``median``): exact while at most
    :data:`EXACT_QUANTILE_VALUES` values came (numpy's linear interpolation, as ``np.percentile``), then from a
    fixed-size histogram of |x| in log buckets, one for x > 0 and one for x < 0, plus a count of zeros
    (memory: 2 x ~27.6k int64 = 0.44 MB per key). NaNs are kept (exact) or counted (histogram): a percentile of
    a stream with a NaN is NaN, as numpy's."""

    def __init__(self, p: float) -> None:
        self.p = float(p)
        self.parts: list[np.ndarray] = []
        self.n_exact = 0
        self.pos: np.ndarray | None = None  # bucket counts of x > 0 (None while exact)
        self.neg: np.ndarray | None = None
        self.zeros = self.nans = 0

    @property
    def sketched(self) -> bool:
        return self.pos is not None

    def add(self, x: np.ndarray) -> None:
        x = np.asarray(x, dtype=np.float64).ravel()
        if not x.size:
            return
        if self.pos is None:
            self.parts.append(x.copy())
            self.n_exact += x.size
            if self.n_exact <= EXACT_QUANTILE_VALUES:
                return
            x, self.parts = np.concatenate(self.parts), []
            self.pos, self.neg = np.zeros(_N_BUCKETS, np.int64), np.zeros(_N_BUCKETS, np.int64)
        self._bucket(x)

    def _bucket(self, x: np.ndarray) -> None:
        nan = np.isnan(x)
        self.nans += int(nan.sum())
        x = x[~nan]
        nonzero = np.abs(x) >= _SKETCH_MIN_ABS
        self.zeros += int(x.size - nonzero.sum())
        x = x[nonzero]
        idx = np.ceil(np.log(np.minimum(np.abs(x), _SKETCH_MAX_ABS)) / _LOG_GAMMA).astype(np.int64) - _I_MIN
        np.clip(idx, 0, _N_BUCKETS - 1, out=idx)
        positive = x > 0
        assert self.pos is not None and self.neg is not None  # made (together) before the first _bucket
        self.pos += np.bincount(idx[positive], minlength=_N_BUCKETS)
        self.neg += np.bincount(idx[~positive], minlength=_N_BUCKETS)

    def value(self) -> float:
        if self.pos is None:
            if not self.parts:
                return math.nan
            v = np.concatenate(self.parts)
            return float(np.median(v) if self.p == 50.0 else np.percentile(v, self.p))
        if self.nans:
            return math.nan
        assert self.neg is not None  # made with pos
        # the values in ascending order: negatives (largest magnitude first), zeros, positives
        counts = np.concatenate([self.neg[::-1], [self.zeros], self.pos])
        n = int(counts.sum())
        rank = self.p / 100.0 * (n - 1)  # numpy's linear rule, between the values of ranks floor and ceil
        cum = np.cumsum(counts)
        lo, hi = (int(np.searchsorted(cum, r, side="right")) for r in (math.floor(rank), math.ceil(rank)))
        a, b = self._bucket_value(lo), self._bucket_value(hi)
        return float(a + (rank - math.floor(rank)) * (b - a))

    def _bucket_value(self, j: int) -> float:
        """The value that represents merged bucket ``j`` (within a relative error a of all its values)."""
        if j == _N_BUCKETS:
            return 0.0
        i = (j - _N_BUCKETS - 1 if j > _N_BUCKETS else _N_BUCKETS - 1 - j) + _I_MIN
        mag = 2.0 * _GAMMA**i / (_GAMMA + 1.0)  # the point of (gamma^(i-1), gamma^i] with relative error <= a
        return mag if j > _N_BUCKETS else -mag


class _Extreme:
    def __init__(self, pick) -> None:
        self.v, self.pick = None, pick

    def add(self, x: np.ndarray) -> None:
        if x.size:
            m = self.pick(x)
            self.v = m if self.v is None else self.pick(np.array([self.v, m]))

    def value(self) -> float:
        return float(self.v) if self.v is not None else math.nan


class _Window:
    """max over windows of ``ticks`` consecutive ticks of sum(bad) / sum(judged) (see
    :func:`taslel_bench.metrics.windows.worst_window_rate`), the last ticks - 1 ticks carried."""

    def __init__(self, ticks: int) -> None:
        self.ticks, self.n, self.judged = ticks, 0, 0.0
        self.tail_b, self.tail_j = np.zeros(0), np.zeros(0)
        self.best: float | None = None

    def add(self, bad: np.ndarray, judged: np.ndarray) -> None:
        from taslel_bench.metrics.windows import _per_tick

        b, j = _per_tick(bad), _per_tick(judged)
        self.n += b.size
        self.judged += float(j.sum())
        b, j = np.concatenate([self.tail_b, b]), np.concatenate([self.tail_j, j])
        if b.size >= self.ticks:
            cb, cj = np.concatenate([[0.0], np.cumsum(b)]), np.concatenate([[0.0], np.cumsum(j)])
            num, den = cb[self.ticks :] - cb[: -self.ticks], cj[self.ticks :] - cj[: -self.ticks]
            ok = den > 0
            if ok.any():
                m = float(np.max(num[ok] / den[ok]))
                self.best = m if self.best is None else max(self.best, m)
        keep = self.ticks - 1
        self.tail_b, self.tail_j = (b[-keep:], j[-keep:]) if keep else (b[:0], j[:0])

    def value(self) -> float:
        if self.judged <= 0:
            return math.nan
        if self.n < self.ticks:  # an episode shorter than the window is one window
            return float(self.tail_b.sum() / self.tail_j.sum())
        return float(self.best) if self.best is not None else math.nan


class Reducer:
    """One reduction per key (see the module doc); :meth:`result` gives the summary numbers."""

    def __init__(self) -> None:
        self.ops: dict[str, Any] = {}  # key -> its reduction (_Mean, Quantiles, ...; None: a value in fixed)
        self.fixed: dict[str, float] = {}  # values set once (counts of flags, first times ...)

    def _op(self, key: str, make):
        op = self.ops.get(key)
        if op is None:
            op = self.ops[key] = make()
        return op

    def mean(self, key: str, x: np.ndarray) -> None:
        self._op(key, _Mean).add(np.asarray(x))

    def rms(self, key: str, x: np.ndarray) -> None:
        self._op(key, _Rms).add(np.asarray(x))

    def pct(self, key: str, x: np.ndarray, p: float) -> None:
        self._op(key, lambda: Quantiles(p)).add(np.asarray(x))

    def median(self, key: str, x: np.ndarray) -> None:
        self._op(key, lambda: Quantiles(50.0)).add(np.asarray(x))

    def max(self, key: str, x: np.ndarray) -> None:
        self._op(key, lambda: _Extreme(np.max)).add(np.asarray(x))

    def min(self, key: str, x: np.ndarray) -> None:
        self._op(key, lambda: _Extreme(np.min)).add(np.asarray(x))

    def window(self, key: str, bad: np.ndarray, judged: np.ndarray, ticks: int) -> None:
        self._op(key, lambda: _Window(ticks)).add(bad, judged)

    def ratio(self, key: str, num, den) -> None:
        """sum(num) / sum(den) over the chunks (nan while sum(den) is 0)."""
        self._op(key, _Ratio).add(num, den)

    def count(self, key: str, x) -> None:
        """An integer total (counts of flags)."""
        self.fixed[key] = int(self.fixed.get(key, 0)) + int(x)
        self.ops.setdefault(key, None)

    def total(self, key: str, x: np.ndarray) -> None:
        """The exact sum of the values, rounded once."""
        self._op(key, _Total).add(np.asarray(x))

    def first(self, key: str, x: float) -> None:
        """The first value given for ``key`` (nan until one is)."""
        if key not in self.fixed or math.isnan(self.fixed[key]):
            self.fixed[key] = float(x)
        self.ops.setdefault(key, None)

    def result(self) -> dict[str, float]:
        return {k: (op.value() if op is not None else self.fixed[k]) for k, op in self.ops.items()}

    def sketched_keys(self) -> list[str]:
        """The percentile keys read from the histogram (more than :data:`EXACT_QUANTILE_VALUES` values)."""
        return [k for k, op in self.ops.items() if isinstance(op, Quantiles) and op.sketched]

    def __contains__(self, key: str) -> bool:
        return key in self.ops


class Onsets:
    """Onsets of a per-tick mask over consecutive chunks (see :func:`taslel_bench.metrics.clearance.onsets`):
    True where the mask turns on after at least ``rearm`` ticks off; a run under way at the first tick is
    not an onset. Carries each column's last on tick."""

    def __init__(self, rearm: int = 1) -> None:
        self.rearm, self.k, self.last_on = rearm, 0, None

    def __call__(self, mask: np.ndarray) -> np.ndarray:
        n = mask.shape[0]
        out = np.zeros_like(mask)
        if n == 0:
            return out
        if self.last_on is None:
            self.last_on = np.full(mask.shape[1:], -(10**9))
        ticks = (self.k + np.arange(n)).reshape(-1, *([1] * (mask.ndim - 1)))
        last_on = np.maximum.accumulate(np.where(mask, ticks, -(10**9)), axis=0)
        last_on = np.maximum(last_on, self.last_on)
        prev_on = np.concatenate([self.last_on[None], last_on[:-1]])
        out[:] = mask & (ticks - prev_on > self.rearm) & (ticks > 0)
        self.last_on, self.k = last_on[-1], self.k + n
        return out


class Touchdowns:
    """The first ``n_ticks`` ticks of every run of consecutive True of each column over consecutive chunks
    (see :func:`taslel_bench.metrics.contacts.touchdown_window`; a run under way at the first tick is not a
    touchdown). Carries the previous row and each column's latest touchdown tick."""

    def __init__(self, n_ticks: int) -> None:
        self.n_ticks, self.k, self.prev, self.start = n_ticks, 0, None, None

    def __call__(self, loaded: np.ndarray) -> np.ndarray:
        n = loaded.shape[0]
        if n == 0:
            return np.zeros_like(loaded)
        if self.prev is None:
            self.prev = np.ones(loaded.shape[1], bool)
            self.start = np.full(loaded.shape[1], -1)
        ticks = (self.k + np.arange(n))[:, None]
        starts = loaded & ~np.concatenate([self.prev[None], loaded[:-1]])
        start = np.maximum(np.maximum.accumulate(np.where(starts, ticks, -1), axis=0), self.start)
        out = loaded & (start >= 0) & (ticks - start < self.n_ticks)
        self.prev, self.start, self.k = loaded[-1].copy(), start[-1], self.k + n
        return out
