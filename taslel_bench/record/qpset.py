"""QP test sets: the filter's QPs recorded from real runs, as the backend received them (one ``.npz``).

A set holds one or more *groups*; a group is one QP layout (shapes, sparsity masks, row labels) with its
constant parts (lb, ub, masks) stored once and, per QP, only what changes: the values of P, A and G on
their masks, q, b, h, the solution the run used (``x_used``, NaN when the filter fell back), a reference
solution (``x_ref``, NaN until computed), and which constraints were active at ``x_used`` (G rows and
bounds within :data:`ACTIVE_TOL`). Per QP, in recorded order: the run it came from (an index into
``meta["runs"]``: scenario, solver, seed ...), its control tick, tick time [s], the filter status, the
filter's build time [s] and the backend's solve time [s] in that run.

    python -m taslel_bench.qpset info  <set.npz>
    python -m taslel_bench.qpset merge <sweep folder or sets...> -o merged.npz     # a sweep's qps.npz files

Recording: ``record.qps=true`` makes :mod:`taslel_bench.sim.run` pass a :class:`QPRecorder` to the episode, which
calls :meth:`QPRecorder.on_tick` once per control tick after the filter (``record.qps_every`` keeps every
k-th tick); the set is written to ``qps.npz`` in the run folder. Memory per recorded tick: the values on
the masks (~1000 floats for the A1 filter, ~8 KB). Replay: :mod:`taslel_bench.qp.replay`.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from taslel_bench.interfaces import QPProblem

FORMAT = "taslel_bench.qpset/3"  # /3: P per QP (the condensed filter's P changes every tick)
READS = ("taslel_bench.qpset/2", FORMAT)  # /2 files: P constant per group
FILENAME = "qps.npz"  # in a run folder
ACTIVE_TOL = 1e-7  # a G row / bound is active at x when within this of its limit
PER_QP = ("q", "b", "h", "P_values", "A_values", "G_values", "x_used", "x_ref", "active_rows", "active_bounds")
COLUMNS = ("group", "run", "tick", "t_s", "status", "build_time_s", "solve_time_s")


@dataclass
class Group:
    """One layout: constants once, per-QP values stacked along axis 0 (``members``: their global indices)."""

    P: np.ndarray  # (n, n) P of the group's first QP (each QP's own values: P_values)
    lb: np.ndarray
    ub: np.ndarray
    P_pattern: np.ndarray
    A_pattern: np.ndarray
    G_pattern: np.ndarray
    layout: dict[str, slice]
    row_labels: list[str]
    q: np.ndarray  # (k, n)
    b: np.ndarray  # (k, m_eq)
    h: np.ndarray  # (k, m_in)
    P_values: np.ndarray  # (k, P_pattern.sum())
    A_values: np.ndarray  # (k, A_pattern.sum())
    G_values: np.ndarray  # (k, G_pattern.sum())
    x_used: np.ndarray  # (k, n) solution the run used (NaN rows: the filter fell back)
    x_ref: np.ndarray  # (k, n) tight reference (NaN rows: not computed)
    active_rows: np.ndarray  # bool (k, m_in) G rows active at x_used
    active_bounds: np.ndarray  # bool (k, n) variables at a finite bound at x_used
    members: np.ndarray  # (k,) global QP indices
    _work: QPProblem | None = field(default=None, init=False, repr=False)  # problem()'s reused instance

    def key(self) -> tuple:
        return layout_key(self.P, self.lb, self.ub, self.P_pattern, self.A_pattern, self.G_pattern, self.row_labels)

    def problem(self, j: int, copy: bool = False) -> QPProblem:
        """QP ``j`` of this group, written into one preallocated problem (in place, like the filter does);
        ``copy=True`` returns an independent copy."""
        if self._work is None:
            self._work = QPProblem(
                self.P.copy(), np.zeros(self.P.shape[0]), np.zeros(self.A_pattern.shape), np.zeros(self.b.shape[1]),
                np.zeros(self.G_pattern.shape), np.zeros(self.h.shape[1]), self.lb.copy(), self.ub.copy(),
                self.P_pattern, self.A_pattern, self.G_pattern, dict(self.layout), list(self.row_labels),
            )  # fmt: skip
        w = self._work
        w.q[:], w.b[:], w.h[:] = self.q[j], self.b[j], self.h[j]
        w.P[self.P_pattern] = self.P_values[j]
        w.A[self.A_pattern] = self.A_values[j]
        w.G[self.G_pattern] = self.G_values[j]
        return w.copy() if copy else w


def layout_key(P, lb, ub, P_pattern, A_pattern, G_pattern, row_labels) -> tuple:
    """What two QPs must share to live in one group (P's values may differ: they are stored per QP)."""
    return (
        P.shape, A_pattern.shape, G_pattern.shape, lb.tobytes(), ub.tobytes(),
        P_pattern.tobytes(), A_pattern.tobytes(), G_pattern.tobytes(), tuple(row_labels),
    )  # fmt: skip


@dataclass
class QPSet:
    """A loaded (or freshly recorded) test set; global per-QP columns in recorded order."""

    groups: list[Group]
    group: np.ndarray  # (N,) group of each QP
    index: np.ndarray  # (N,) row of each QP inside its group
    run: np.ndarray  # (N,) index into meta["runs"]
    tick: np.ndarray  # (N,) control tick in its run
    t_s: np.ndarray  # (N,) [s] episode time of the tick
    status: np.ndarray  # (N,) str, filter status in the run
    build_time_s: np.ndarray  # (N,) [s] filter build time in the run
    solve_time_s: np.ndarray  # (N,) [s] backend solve time in the run
    meta: dict

    def __len__(self) -> int:
        return int(self.group.size)

    def problem(self, i: int, copy: bool = False) -> QPProblem:
        """QP ``i`` (global index). Without ``copy`` the returned object is reused by the next call."""
        return self.groups[self.group[i]].problem(int(self.index[i]), copy)

    def _column(self, name: str, i: int) -> np.ndarray:
        return getattr(self.groups[self.group[i]], name)[self.index[i]]

    def x_used_of(self, i: int) -> np.ndarray:
        return self._column("x_used", i)

    def x_ref_of(self, i: int) -> np.ndarray:
        return self._column("x_ref", i)

    def set_x_ref(self, i: int, x: np.ndarray | None) -> None:
        self._column("x_ref", i)[:] = np.nan if x is None else x

    @property
    def runs(self) -> list[dict]:
        return list(self.meta.get("runs", []))

    def scenario(self) -> np.ndarray:
        """(N,) scenario name of each QP."""
        names = np.array([str(r.get("scenario", "")) for r in self.runs] or [""], dtype=object)
        return names[self.run]

    def sequences(self) -> Iterator[np.ndarray]:
        """Global indices run by run, each in tick order (warm starts never cross a run boundary)."""
        for r in np.unique(self.run):
            idx = np.flatnonzero(self.run == r)
            yield idx[np.argsort(self.tick[idx], kind="stable")]

    # --- conveniences for small sets (the solver tests' fixture) ---
    @property
    def problems(self) -> list[QPProblem]:
        return [self.problem(i, copy=True) for i in range(len(self))]

    @property
    def x_ref(self) -> np.ndarray:
        return np.stack([self.x_ref_of(i) for i in range(len(self))])

    @property
    def x_used(self) -> np.ndarray:
        return np.stack([self.x_used_of(i) for i in range(len(self))])

    @property
    def ticks(self) -> np.ndarray:
        return self.tick

    @property
    def tags(self) -> list[str]:
        """What was active at ``x_used``: "+"-joined subset of ecbf, friction, torque, else "none"."""
        out = []
        for i in range(len(self)):
            g = self.groups[self.group[i]]
            out.append("+".join(binding_tags(g.row_labels, self._column("active_rows", i),
                                             self._column("active_bounds", i), g.layout)))  # fmt: skip
        return out


def binding_tags(row_labels: list[str], active_rows: np.ndarray, active_bounds: np.ndarray,
                 layout: dict[str, slice]) -> list[str]:  # fmt: skip
    """Constraint families active: "ecbf" (clearance rows), "friction" (pyramid sides), "torque" (u bounds)."""
    tags = set()
    for i in np.flatnonzero(active_rows):
        lab = row_labels[i]
        if lab.endswith("clearance"):
            tags.add("ecbf")
        elif lab.endswith(("fx+", "fx-", "fy+", "fy-")):
            tags.add("friction")
    if "u" in layout and np.any(active_bounds[layout["u"]]):
        tags.add("torque")
    return sorted(tags) or ["none"]


def active_sets(problem: QPProblem, x: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(G rows, bounds) active at ``x``; identically-zero G rows never count. All False if x is None/NaN."""
    m_in = problem.G.shape[0]
    if x is None or not np.all(np.isfinite(x)):
        return np.zeros(m_in, bool), np.zeros(problem.n, bool)
    rows = (problem.G @ x - problem.h > -ACTIVE_TOL) & problem.G_pattern.any(axis=1)
    if m_in:
        rows &= np.abs(problem.G).sum(axis=1) > 0
    bounds = (x - problem.lb < ACTIVE_TOL) | (problem.ub - x < ACTIVE_TOL)
    return rows, bounds


class _Builder:
    """Per-group lists while recording."""

    def __init__(self, p: QPProblem) -> None:
        self.const = (p.P.copy(), p.lb.copy(), p.ub.copy(), p.P_pattern.copy(), p.A_pattern.copy(),
                      p.G_pattern.copy(), dict(p.layout), list(p.row_labels))  # fmt: skip
        self.cols: dict[str, list[np.ndarray]] = {k: [] for k in PER_QP}
        self.members: list[int] = []

    def same_constants(self, p: QPProblem) -> bool:
        P, lb, ub = self.const[:3]
        return (
            p.P.shape == P.shape and p.A.shape[0] == self.const[4].shape[0] and p.G.shape[0] == self.const[5].shape[0]
            and np.array_equal(p.lb, lb) and np.array_equal(p.ub, ub)
        )  # fmt: skip

    def group(self) -> Group:
        n = self.const[0].shape[0]
        stacked = {}
        for k, v in self.cols.items():
            stacked[k] = np.stack(v) if v else np.zeros((0, n))
        return Group(*self.const, **stacked, members=np.asarray(self.members, dtype=np.int64))


class QPRecorder:
    """Collects QPs (see module doc). ``run``: what to store about the run (scenario, solver, seed ...)."""

    def __init__(self, run: dict | None = None, every: int = 1) -> None:
        if every < 1:
            raise ValueError(f"record.qps_every={every}; must be >= 1")
        self.every = int(every)
        self.run_info = dict(run or {})
        self._builders: list[_Builder] = []
        self._by_key: dict[tuple, int] = {}
        self._last: tuple[int, int] | None = None  # (id(problem), builder) of the last add
        self._rows: dict[str, list] = {k: [] for k in COLUMNS}

    def __len__(self) -> int:
        return len(self._rows["tick"])

    def on_tick(self, tick: int, t_s: float, problem: QPProblem, result) -> None:
        """Episode hook, after the filter: ``result`` is the :class:`taslel_bench.filter.safety_filter.FilterResult`."""
        if tick % self.every:
            return
        sol = result.solve
        x = sol.x if (sol is not None and sol.ok) else None
        self.add(problem, x, tick=tick, t_s=t_s, status=result.status, build_time_s=result.build_time_s,
                 solve_time_s=sol.solve_time_s if sol is not None else float("nan"))  # fmt: skip

    def add(self, problem: QPProblem, x_used: np.ndarray | None, *, tick: int, t_s: float = float("nan"),
            status: str = "solved", build_time_s: float = float("nan"), solve_time_s: float = float("nan"),
            x_ref: np.ndarray | None = None) -> None:  # fmt: skip
        """Store a copy of ``problem``'s values (the caller may overwrite it afterwards)."""
        b = self._builder(problem)
        nan = np.full(problem.n, np.nan)
        rows, bounds = active_sets(problem, x_used)
        c = self._builders[b].cols
        c["q"].append(problem.q.copy())
        c["b"].append(problem.b.copy())
        c["h"].append(problem.h.copy())
        c["P_values"].append(problem.P[problem.P_pattern])
        c["A_values"].append(problem.A[problem.A_pattern])
        c["G_values"].append(problem.G[problem.G_pattern])
        c["x_used"].append(nan if x_used is None else np.array(x_used, float))
        c["x_ref"].append(nan if x_ref is None else np.array(x_ref, float))
        c["active_rows"].append(rows)
        c["active_bounds"].append(bounds)
        self._builders[b].members.append(len(self))
        for k, v in zip(COLUMNS, (b, 0, tick, t_s, status, build_time_s, solve_time_s), strict=True):
            self._rows[k].append(v)

    def _builder(self, p: QPProblem) -> int:
        if self._last is not None and self._last[0] == id(p) and self._builders[self._last[1]].same_constants(p):
            return self._last[1]  # the filter's one problem instance, constants unchanged: the common case
        key = layout_key(p.P, p.lb, p.ub, p.P_pattern, p.A_pattern, p.G_pattern, p.row_labels)
        if key not in self._by_key:
            self._by_key[key] = len(self._builders)
            self._builders.append(_Builder(p))
        self._last = (id(p), self._by_key[key])
        return self._by_key[key]

    def to_set(self, meta: dict | None = None) -> QPSet:
        groups = [b.group() for b in self._builders]
        index = np.zeros(len(self), dtype=np.int64)
        for g in groups:
            index[g.members] = np.arange(g.members.size)
        r = self._rows
        meta = {**dict(meta or {}), "runs": [self.run_info]}
        return QPSet(
            groups, np.asarray(r["group"], np.int64), index, np.zeros(len(self), np.int64),
            np.asarray(r["tick"], np.int64), np.asarray(r["t_s"], float), np.asarray(r["status"], dtype=object),
            np.asarray(r["build_time_s"], float), np.asarray(r["solve_time_s"], float), meta,
        )  # fmt: skip

    def save(self, path: Path, meta: dict | None = None) -> None:
        save(path, self.to_set(meta))


# ------------------------------------------------------------------------------------------- file I/O


def save(path: Path | str, qs: QPSet) -> None:
    """Write ``qs`` to ``path`` (atomic: temporary name, then rename)."""
    from taslel_bench.record.run_files import atomic_write

    arrays: dict[str, np.ndarray] = {
        "format": np.asarray(FORMAT), "meta": np.asarray(json.dumps(qs.meta, default=str)),
        "n_groups": np.asarray(len(qs.groups)), "group": qs.group, "index": qs.index, "run": qs.run,
        "tick": qs.tick, "t_s": qs.t_s, "status": np.asarray([str(s) for s in qs.status], dtype=str),
        "build_time_s": qs.build_time_s, "solve_time_s": qs.solve_time_s,
    }  # fmt: skip
    for gi, g in enumerate(qs.groups):
        pre = f"g{gi}__"
        for k in ("P", "lb", "ub", "P_pattern", "A_pattern", "G_pattern", *PER_QP, "members"):
            arrays[pre + k] = getattr(g, k)
        arrays[pre + "layout"] = np.asarray(json.dumps({k: [s.start, s.stop] for k, s in g.layout.items()}))
        arrays[pre + "row_labels"] = np.asarray(g.row_labels, dtype=str)

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:  # a file object: np.savez would append ".npz" to the temporary name
            # cast: pyright matches **arrays against savez_compressed's allow_pickle keyword too (no key is)
            np.savez_compressed(f, **cast(dict[str, Any], arrays))

    atomic_write(Path(path), write)


class QPSetError(ValueError):
    """A file that is not a readable QP test set (the message names it and says why)."""


def load(path: Path | str) -> QPSet:
    """Read a set written by :func:`save`; :class:`QPSetError` naming the file if it is not one (missing,
    not a zip/npz, truncated, an array missing, pickled data)."""
    path = Path(path)
    if not path.is_file():
        raise QPSetError(f"{path}: no such file (a {FILENAME} of a run with record.qps=true, or a merged set)")
    try:
        return _load(path)
    except QPSetError:
        raise
    except KeyError as exc:
        raise QPSetError(f"{path}: not a complete {FORMAT} file: an array is missing "
                         f"({exc.args[0] if exc.args else exc})") from None
    except Exception as exc:  # BadZipFile, EOFError, OSError, "contains pickled data" ...
        raise QPSetError(f"{path}: not a readable {FORMAT} file ({type(exc).__name__}: {exc})") from None


def _load(path: Path) -> QPSet:
    with np.load(path, allow_pickle=False) as d:
        if "format" not in d or str(d["format"]) not in READS:
            raise QPSetError(f"{path}: not a {FORMAT} file (no 'format' entry of a known version)")
        groups = []
        for gi in range(int(d["n_groups"])):
            pre = f"g{gi}__"
            layout = {k: slice(a, b) for k, (a, b) in json.loads(str(d[pre + "layout"])).items()}
            P, lb, ub, P_pattern, A_pattern, G_pattern = (
                d[pre + k].copy() for k in ("P", "lb", "ub", "P_pattern", "A_pattern", "G_pattern"))
            per = {k: d[pre + k].copy() for k in (*PER_QP, "members") if pre + k in d}
            if "P_values" not in per:  # format /2: one P per group
                per["P_values"] = np.tile(P[P_pattern], (per["members"].size, 1))
            groups.append(Group(P, lb, ub, P_pattern, A_pattern, G_pattern, layout,
                                [str(s) for s in d[pre + "row_labels"]], **per))
        return QPSet(
            groups, d["group"].copy(), d["index"].copy(), d["run"].copy(), d["tick"].copy(), d["t_s"].copy(),
            np.asarray([str(s) for s in d["status"]], dtype=object), d["build_time_s"].copy(),
            d["solve_time_s"].copy(), json.loads(str(d["meta"])),
        )  # fmt: skip


def from_problems(problems: list[QPProblem], x_ref: np.ndarray, ticks: Iterable[int], meta: dict,
                  run: dict | None = None) -> QPSet:  # fmt: skip
    """A set from in-memory QPs whose solution used is the reference (the solver tests' fixture)."""
    rec = QPRecorder(run)
    for p, x, k in zip(problems, x_ref, ticks, strict=True):
        rec.add(p, x, tick=int(k), x_ref=x)
    return rec.to_set(meta)


def merge(sets: Iterable[QPSet], meta: dict | None = None) -> QPSet:
    """One set from several (groups with equal constants and layout are merged; runs are concatenated)."""
    groups: list[Group] = []
    by_key: dict[tuple, int] = {}
    parts: dict[int, list[tuple[Group, np.ndarray]]] = {}
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("group", "run", "tick", "t_s", "status", "build_time_s",
                                                          "solve_time_s")}  # fmt: skip
    runs: list[dict] = []
    offset = 0
    for qs in sets:
        gmap = np.zeros(len(qs.groups), np.int64)
        for gi, g in enumerate(qs.groups):
            key = g.key()
            if key not in by_key:
                by_key[key] = len(groups)
                groups.append(g)
                parts[by_key[key]] = []
            gmap[gi] = by_key[key]
            parts[by_key[key]].append((g, g.members + offset))
        cols["group"].append(gmap[qs.group])
        cols["run"].append(qs.run + len(runs))
        for k in ("tick", "t_s", "status", "build_time_s", "solve_time_s"):
            cols[k].append(np.asarray(getattr(qs, k)))
        runs += qs.runs
        offset += len(qs)
    out_groups = []
    index = np.zeros(offset, np.int64)
    for gi, g0 in enumerate(groups):
        per = {k: np.concatenate([getattr(g, k) for g, _ in parts[gi]]) for k in PER_QP}
        members = np.concatenate([m for _, m in parts[gi]])
        order = np.argsort(members, kind="stable")
        per = {k: v[order] for k, v in per.items()}
        members = members[order]
        index[members] = np.arange(members.size)
        out_groups.append(Group(g0.P, g0.lb, g0.ub, g0.P_pattern, g0.A_pattern, g0.G_pattern, g0.layout,
                                g0.row_labels, **per, members=members))  # fmt: skip
    cat = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
    return QPSet(out_groups, cat["group"].astype(np.int64), index, cat["run"].astype(np.int64),
                 cat["tick"].astype(np.int64), cat["t_s"].astype(float), cat["status"].astype(object),
                 cat["build_time_s"].astype(float), cat["solve_time_s"].astype(float),
                 {**dict(meta or {}), "runs": runs})  # fmt: skip


def find_sets(paths: Iterable[Path]) -> list[Path]:
    """``qps.npz`` files: the paths themselves when files, else every ``qps.npz`` found under a folder."""
    found = []
    for p in map(Path, paths):
        found += [p] if p.is_file() else sorted(p.rglob(FILENAME))
    return found
