"""Dense -> CSC with a *fixed* sparsity pattern (the QP's constant masks), so every tick gives the same
structure (explicit zeros kept) and the conversion is one fancy-indexing gather."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class PatternCSC:
    """CSC structure of a boolean mask; :meth:`values` gathers a dense matrix's entries in CSC order."""

    def __init__(self, mask: np.ndarray, upper_only: bool = False) -> None:
        mask = np.array(mask, dtype=bool, copy=True)
        if upper_only:
            mask = np.triu(mask)
        self.shape = mask.shape
        cols, rows = np.nonzero(mask.T)  # column-major order: by column, rows ascending
        self.rows, self.cols = rows, cols
        self.indices = rows.astype(np.int64)
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=mask.shape[1]))]).astype(
            np.int64
        )

    @property
    def nnz(self) -> int:
        return int(self.rows.size)

    def values(self, dense: np.ndarray) -> np.ndarray:
        return dense[self.rows, self.cols]

    def matrix(self, dense: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((self.values(dense), self.indices, self.indptr), shape=self.shape)


class PatternCache:
    """A few :class:`PatternCSC` keyed by their mask (the kept G rows change with the stance set)."""

    def __init__(self, max_size: int = 64) -> None:
        self._cache: dict[tuple, PatternCSC] = {}
        self.max_size = max_size

    def get(self, mask: np.ndarray, upper_only: bool = False) -> PatternCSC:
        key = (mask.shape, mask.tobytes(), upper_only)
        pat = self._cache.get(key)
        if pat is None:
            if len(self._cache) >= self.max_size:
                self._cache.clear()
            pat = self._cache[key] = PatternCSC(mask, upper_only)
        return pat
