"""The solver tests' QP fixture: a :mod:`taslel_bench.record.qpset` file (the format lives in the core, which writes
it during runs with ``record.qps=true``); this module only names the committed fixture and adds helpers.

``save(path, problems, x_ref, ticks, tags, meta)`` keeps the old call signature (``tags`` are recomputed from
what is active at ``x_ref``, the solution stored as used).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from taslel_bench.interfaces import QPProblem
from taslel_bench.record.qpset import QPSet, from_problems
from taslel_bench.record.qpset import load as _load
from taslel_bench.record.qpset import save as _save

DEFAULT_PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "qps_episode.npz"


def save(path: Path, problems: list[QPProblem], x_ref: np.ndarray, ticks: np.ndarray, tags: list[str] | None,
         meta: dict, run: dict | None = None) -> None:  # fmt: skip
    """Write in-memory QPs (x_ref = the solution used) as a QP set."""
    del tags  # derived from the active sets at x_ref on load
    _save(path, from_problems(problems, x_ref, ticks, meta, run))


def load(path: Path | str = DEFAULT_PATH) -> QPSet:
    """Read a QP set (default: the committed fixture)."""
    return _load(path)


def without_rows(problem: QPProblem, labels_prefix_out: str) -> QPProblem:
    """A copy of ``problem`` without the G rows whose label ends with ``labels_prefix_out`` (e.g.
    ``"clearance"``: the same QP as the filter builds with the ECBF off) -- a different layout."""
    keep = [i for i, lab in enumerate(problem.row_labels) if not lab.endswith(labels_prefix_out)]
    p = problem.copy()
    return QPProblem(
        p.P, p.q, p.A, p.b, p.G[keep], p.h[keep], p.lb, p.ub, p.P_pattern, p.A_pattern, p.G_pattern[keep],
        p.layout, [p.row_labels[i] for i in keep],
    )  # fmt: skip


__all__ = ["DEFAULT_PATH", "QPSet", "load", "save", "without_rows"]
