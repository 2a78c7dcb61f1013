"""Statistics the reports share."""

from __future__ import annotations

import numpy as np

SHGEOM_SHIFT_US = 10.0  # [µs] shift of the shifted geometric mean of solve times


def shifted_geometric_mean(values_us: np.ndarray, shift_us: float = SHGEOM_SHIFT_US) -> float:
    """exp(mean(log(t + shift))) - shift over all solve times [µs]; robust to a few huge outliers and to
    tiny times, as in qpbenchmark."""
    v = np.asarray(values_us, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan")
    return float(np.exp(np.mean(np.log(v + shift_us))) - shift_us)
