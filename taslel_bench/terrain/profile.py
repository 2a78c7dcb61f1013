"""The paper's virtual obstacle: a clearance profile every swing foot must stay above, as a function of its
swing phase (paper, "Ground Clearance Enforced by an ECBF"). No geometry is added to the plant; the
ground-clearance ECBF (:mod:`taslel_bench.filter.barriers.phase_profile`) and the clearance metrics read it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ClearanceProfile:
    """Obstacle height under a swing foot as a polynomial of the swing phase s in [0, 1]:
    z(s) = sum_k coeffs[k] s^k  [m, world z of the foot-sphere *bottom*]."""

    coeffs: tuple[float, ...]
    # derived in __post_init__ (ascending powers, length K): exponents, coefficients of z, dz/ds, d²z/ds²
    _k: np.ndarray = field(init=False, repr=False, compare=False)
    _c: np.ndarray = field(init=False, repr=False, compare=False)
    _c1: np.ndarray = field(init=False, repr=False, compare=False)
    _c2: np.ndarray = field(init=False, repr=False, compare=False)

    def __call__(self, s: float) -> tuple[float, float, float]:
        """(z, dz/ds, d²z/ds²) at phase ``s``."""
        z = dz = ddz = 0.0
        for k, c in enumerate(self.coeffs):
            z += c * s**k
            if k >= 1:
                dz += k * c * s ** (k - 1)
            if k >= 2:
                ddz += k * (k - 1) * c * s ** (k - 2)
        return z, dz, ddz

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised (z, dz/ds, d²z/ds²) for an array of phases (one Vandermonde matrix, three dots)."""
        powers = np.asarray(s, float)[:, None] ** self._k  # (n, K): s^0 .. s^(K-1)
        return powers @ self._c, powers @ self._c1, powers @ self._c2

    def __post_init__(self) -> None:
        c = np.asarray(self.coeffs, float)
        k = np.arange(len(c))
        c1 = np.zeros_like(c)
        c1[: len(c) - 1] = c[1:] * k[1:]  # coefficients of dz/ds, padded to K
        c2 = np.zeros_like(c)
        c2[: len(c) - 2] = c[2:] * k[2:] * k[1:-1]  # coefficients of d²z/ds²
        for name, value in (("_k", k), ("_c", c), ("_c1", c1), ("_c2", c2)):
            object.__setattr__(self, name, value)  # frozen dataclass: cached derived arrays

    def coefficient_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The coefficients of z, dz/ds and d²z/ds² (ascending powers, all of length K)."""
        return self._c, self._c1, self._c2

    @property
    def peak_m(self) -> float:
        return float(max(self(s)[0] for s in np.linspace(0.0, 1.0, 201)))
