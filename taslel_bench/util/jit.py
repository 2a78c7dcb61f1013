"""Compilation of the control tick's numeric kernels (Numba).

The 1 kHz tick does a few dozen small array operations (18x18 and 30x42 blocks, 4-vectors). As numpy
calls each costs ~1 µs of interpreter and dispatch overhead, more than the arithmetic; compiled into one
kernel per step they cost a fraction of that. Kernels are plain functions over preallocated arrays (no
allocation), decorated with :func:`kernel`; their callers stay ordinary Python objects. Compiled code is
cached next to the sources (``__pycache__``), so only the first process after an edit pays the compile.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from numba import njit

F = TypeVar("F", bound=Callable)


def kernel(fn: F) -> F:
    """Compile ``fn`` in nopython mode, cached on disk, no GIL needed."""
    return njit(cache=True, nogil=True)(fn)  # type: ignore[return-value]
