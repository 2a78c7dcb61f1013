"""The solver tests' QP fixture: a :mod:`taslel_bench.record.qpset` file (the format lives in the core, which
writes it during runs with ``record.qps=true``; ``python -m studies.record_solver_fixture`` made this one); this
module names the committed fixture and adds helpers."""

from __future__ import annotations

from pathlib import Path

from taslel_bench.interfaces import QPProblem
from taslel_bench.record.qpset import QPSet
from taslel_bench.record.qpset import load as _load

DEFAULT_PATH = Path(__file__).resolve().parent / "data" / "qps_episode.npz"


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


__all__ = ["DEFAULT_PATH", "QPSet", "load", "without_rows"]
