"""A set of recorded QPs on disk: one ``.npz``, the constant parts once, the per-tick values on the masks.

Stored: P values, lb, ub, the three masks, the layout and G row labels (once); per QP: q, b, h, the values
of A and G on their masks, the tick index, the reference solution x_ref and a tag of what binds there.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from taslel_bench.interfaces import QPProblem

DEFAULT_PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "qps_episode.npz"


@dataclass
class QPSet:
    problems: list[QPProblem]
    x_ref: np.ndarray  # (k, n) reference solutions
    ticks: np.ndarray  # (k,) control tick of each QP in its episode
    tags: list[str]  # what binds at the reference solution ("ecbf", "friction", "torque", "none", ...)
    meta: dict


def save(path: Path, problems: list[QPProblem], x_ref: np.ndarray, ticks: np.ndarray, tags: list[str],
         meta: dict) -> None:  # fmt: skip
    """Write ``problems`` (one layout) to ``path``."""
    p0 = problems[0]
    for p in problems:
        if (
            p.A.shape != p0.A.shape
            or p.G.shape != p0.G.shape
            or not np.array_equal(p.A_pattern, p0.A_pattern)
        ):
            raise ValueError("all QPs of a fixture must share one layout")
        if (
            not np.array_equal(p.P, p0.P)
            or not np.array_equal(p.lb, p0.lb)
            or not np.array_equal(p.ub, p0.ub)
        ):
            raise ValueError("P, lb and ub must be constant over the fixture")
    layout = {k: [s.start, s.stop] for k, s in p0.layout.items()}
    np.savez_compressed(
        path,
        P=p0.P, lb=p0.lb, ub=p0.ub,
        P_pattern=p0.P_pattern, A_pattern=p0.A_pattern, G_pattern=p0.G_pattern,
        q=np.stack([p.q for p in problems]), b=np.stack([p.b for p in problems]),
        h=np.stack([p.h for p in problems]),
        A_values=np.stack([p.A[p0.A_pattern] for p in problems]),
        G_values=np.stack([p.G[p0.G_pattern] for p in problems]),
        x_ref=np.asarray(x_ref), ticks=np.asarray(ticks), tags=np.asarray(tags),
        row_labels=np.asarray(p0.row_labels), layout=json.dumps(layout), meta=json.dumps(meta),
    )  # fmt: skip


def load(path: Path | str = DEFAULT_PATH) -> QPSet:
    """Read a fixture written by :func:`save`."""
    with np.load(path, allow_pickle=False) as d:
        layout = {k: slice(a, b) for k, (a, b) in json.loads(str(d["layout"])).items()}
        problems = []
        for i in range(d["q"].shape[0]):
            A = np.zeros(d["A_pattern"].shape)
            A[d["A_pattern"]] = d["A_values"][i]
            G = np.zeros(d["G_pattern"].shape)
            G[d["G_pattern"]] = d["G_values"][i]
            problems.append(
                QPProblem(
                    d["P"].copy(),
                    d["q"][i].copy(),
                    A,
                    d["b"][i].copy(),
                    G,
                    d["h"][i].copy(),
                    d["lb"].copy(),
                    d["ub"].copy(),
                    d["P_pattern"],
                    d["A_pattern"],
                    d["G_pattern"],
                    dict(layout),
                    [str(s) for s in d["row_labels"]],
                )
            )
        return QPSet(
            problems,
            d["x_ref"].copy(),
            d["ticks"].copy(),
            [str(t) for t in d["tags"]],
            json.loads(str(d["meta"])),
        )


def without_rows(problem: QPProblem, labels_prefix_out: str) -> QPProblem:
    """A copy of ``problem`` without the G rows whose label ends with ``labels_prefix_out`` (e.g.
    ``"clearance"``: the same QP as the filter builds with the ECBF off) -- a different layout."""
    keep = [i for i, lab in enumerate(problem.row_labels) if not lab.endswith(labels_prefix_out)]
    p = problem.copy()
    return QPProblem(
        p.P, p.q, p.A, p.b, p.G[keep], p.h[keep], p.lb, p.ub, p.P_pattern, p.A_pattern, p.G_pattern[keep],
        p.layout, [p.row_labels[i] for i in keep],
    )  # fmt: skip
