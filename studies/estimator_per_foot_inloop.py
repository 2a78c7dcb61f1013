"""Per-foot friction estimates in the loop, each foot judged against its own surface
(``python -m studies.estimator_per_foot_inloop --seeds 0 1 2 3 4 [--set NAME=OVERRIDES ...]``).

For every set (Hydra overrides of one run config) and seed, one episode of the core runner; the estimator
is wrapped to record what it reported for each foot (``mu_per_foot``, or ``mu`` for all four). Per foot,
on the ticks the foot is loaded (its contact sensor found a contact) and against the friction under it
(the trace's ``mu_foot``):

* over-estimation: share of the foot's loaded ticks with mu_hat > mu + 0.05 or with the filter's planned force
  on the foot beyond the true cone there (:func:`taslel_bench.metrics.summary.foot_overestimates`: a plan the
  ground cannot hold counts whatever the estimate and its floor);
* time to safe [s]: after the foot's first loaded tick on a surface other than its starting one, until its
  first loaded tick that is not over-estimated (0 if none was); NaN if the foot never met another surface;
* time to useful [s] (rises): from the same tick until its first loaded tick with
  mu_hat >= min(mu, 0.5) - 0.1 (:func:`estimators.safety.useful`); inf if never, NaN as above;
* useful share: share of the foot's loaded ticks with mu_hat >= min(mu, 0.5) - 0.1 (an estimate pinned at
  its floor is never over-estimated and scores 0 s to safe on a drop; this says whether it was any use);
  ``useful_ready``: the same from the estimator's first ready tick on (the in-loop usefulness of the one-sided targets,
  c74fe88: after the startup window, whose prior is the safe floor);
* over-estimation on the new surface: the same share over the foot's loaded ticks from that first loaded
  tick on (the drop target's "<= 5 % of that foot's ticks");
* falls and the plant's foot sliding: mean horizontal slip speed of loaded feet [m/s] (all feet, all ticks)
  and each foot's slide on the new surface [m] (contact-point slip speed integrated over its loaded ticks
  there), to hold against the per-foot oracle's; beside them the summary's ``touchdown_slip_mps_mean`` [m/s]
  (the landing feet's slip) and ``distance_m`` [m] (how far the trunk walked: a lower plan slows the walk);
* unsafe runs: the run's safety verdict (``summary.json``'s, :mod:`taslel_bench.metrics.verdict`) is not safe.

Every world (``--world NAME=OVERRIDES``, default: the drop 0.8 -> 0.2) is run with every estimator set
(``--set NAME=OVERRIDES``) and seed. Prints one row per world and set: the p95 of the time to safe and to
useful over feet x seeds (the higher order statistic: no interpolation with an infinite time), the pooled
over-estimation rates, falls and sliding; ``--out`` writes the rows as JSON and ``--md`` a markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np

from estimators.safety import useful
from taslel_bench.interfaces import FrictionEstimate, GroundTruth, Proprioception
from taslel_bench.metrics.summary import FootTimeToSafe, foot_overestimates

DROP_SCENARIO = ["scenario=friction_patch", "scenario.friction=0.8", "scenario.friction_after=0.2",
                 "scenario.change_at_m=0.6"]
RUN = ["duration=6", "filter=terrain", "record.mcap=false", "progress=false"]
DEFAULT_WORLD = DROP_SCENARIO + RUN


def world_overrides(world: str, extra: str = "") -> list[str]:
    """The run's overrides for a world and an estimator set: the drop 0.8 -> 0.2 with ``world`` and
    ``extra`` added. A top-level key they set (``scenario=...``, ``filter=...``, ``duration=...``)
    replaces the default's, with the default's values under it (``scenario.friction`` ...)."""
    ov = world.split() + extra.split()
    top = {o.split("=", 1)[0] for o in ov if "=" in o and "." not in o.split("=", 1)[0]}
    return [o for o in DEFAULT_WORLD if o.split("=", 1)[0].split(".")[0] not in top] + ov


class Recorder:
    """Wraps an estimator; keeps the (4,) friction it reported for each foot every tick."""

    def __init__(self, inner) -> None:
        self.inner, self.name, self.rows = inner, getattr(inner, "name", "estimator"), []
        self.reads_imu = bool(getattr(inner, "reads_imu", False))  # the loop samples the IMU only if asked
        self.reads_ground_truth = bool(getattr(inner, "reads_ground_truth", False))  # the oracle: the loop passes it

    def reset(self) -> None:
        self.inner.reset()
        self.rows = []

    def step(self, obs: Proprioception, truth: GroundTruth | None = None) -> FrictionEstimate:
        est = self.inner.step(obs) if truth is None else self.inner.step(obs, truth)
        self.rows.append(np.full(4, est.mu) if est.mu_per_foot is None else np.asarray(est.mu_per_foot, float))
        return est


def foot_scores(mu_hat: np.ndarray, mu_foot: np.ndarray, loaded: np.ndarray, dt: float,
                slip_mps: np.ndarray | None = None, ready_from: int = 0,
                beyond_cone: np.ndarray | None = None) -> dict[str, list]:
    """Per-foot over-estimation rate on loaded ticks (all, and on the new surface), time to safe and time to
    useful [s], useful share (all loaded ticks, and from tick ``ready_from`` on) and (with ``slip_mps`` (n, 4)
    [m/s]) the slide on the new surface [m] (see the module doc); ``beyond_cone`` (n, 4): ticks the filter
    planned the foot's force beyond the true cone (over-estimated whatever mu_hat)."""
    over = foot_overestimates(mu_hat, mu_foot, np.zeros_like(loaded) if beyond_cone is None else beyond_cone)
    good = useful(mu_foot, mu_hat)
    nan = float("nan")
    to_safe = FootTimeToSafe()
    to_safe.feed(mu_foot, loaded, over, 0)
    safe, new_surface = to_safe.per_foot(dt), to_safe.k_new
    assert new_surface is not None  # set by the feed
    out: dict[str, list] = {k: [] for k in ("over_rate", "over_rate_new", "time_to_safe_s", "time_to_useful_s",
                                            "useful_share", "useful_ready", "slide_new_m")}
    for leg in range(4):
        ld = loaded[:, leg]
        out["over_rate"].append(float(over[ld, leg].mean()) if ld.any() else nan)
        out["useful_share"].append(float(good[ld, leg].mean()) if ld.any() else nan)
        lr = ld[ready_from:]
        out["useful_ready"].append(float(good[ready_from:, leg][lr].mean()) if lr.any() else nan)
        k0 = int(new_surface[leg])  # the foot's first loaded tick on a new surface (FootTimeToSafe's), -1: none
        if k0 < 0:
            for k in ("over_rate_new", "time_to_safe_s", "time_to_useful_s", "slide_new_m"):
                out[k].append(nan)
            continue
        out["time_to_safe_s"].append(float(safe[leg]))
        out["time_to_useful_s"].append(_first(ld[k0:] & good[k0:, leg], dt))
        out["over_rate_new"].append(float(over[k0:, leg][ld[k0:]].mean()))
        out["slide_new_m"].append(float(slip_mps[k0:, leg][ld[k0:]].sum() * dt) if slip_mps is not None else nan)
    return out


def _first(ok: np.ndarray, dt: float) -> float:
    """[s] time of the first True in ``ok`` (ticks of dt from its start); inf if none."""
    k = np.flatnonzero(ok)
    return float(k[0] * dt) if len(k) else float("inf")


def run(overrides: list[str], seed: int) -> dict[str, object]:
    """One episode of ``overrides`` + ``seed``; its per-foot scores, fall, sliding and safety verdict."""
    from studies.estimator_slip_observability import run_built
    from taslel_bench.config.settings import health_limits, safety_limits
    from taslel_bench.metrics.contacts import ContactStream
    from taslel_bench.metrics.summary import summary_sections

    res, rec, b = run_built([*overrides, f"seed={seed}"], Recorder)
    cfg = b.cfg
    tr = res.trace
    n = tr.n
    mu_hat, loaded = np.array(rec.rows[:n]), tr.in_contact[:n]
    dt = float(tr.t_s[1] - tr.t_s[0]) if n > 1 else 1e-3
    slip = np.linalg.norm(tr.slip_w[:n], axis=-1)
    ready = np.flatnonzero(tr.mu_hat_ready[:n])
    planned = ContactStream(dt, b.controller.stance_swing_s[0], "")
    planned.feed(tr, slice(0, n))
    scores = foot_scores(mu_hat, tr.mu_foot[:n], loaded, dt, slip, int(ready[0]) if len(ready) else n,
                         planned.last.beyond_cone)
    summary = summary_sections(res, dt, float(cfg.controller.stand_duration), b.controller.stance_swing_s[0],
                               health_limits(cfg), safety_limits(cfg))
    verdict, flat = summary.verdict, summary.flat()
    return {"seed": seed, "fell": bool(res.fell), "status": res.status, **scores,
            "sliding_mps": float(slip[loaded].mean()) if loaded.any() else float("nan"),
            "touchdown_slip_mps": float(flat["touchdown_slip_mps_mean"]), "distance_m": float(flat["distance_m"]),
            "safe": verdict.safe, "unsafe_reasons": [r.tag for r in verdict.reasons]}


def _pooled(rows: list[dict], key: str) -> np.ndarray:
    return np.array([x for r in rows for x in r[key] if not np.isnan(x)])


def _stat(a: np.ndarray, how: str) -> float:
    """p95 (the higher order statistic), max or mean of ``a``; NaN if empty."""
    if not len(a):
        return float("nan")
    if how == "p95":
        return float(np.percentile(a, 95, method="higher"))
    return float(a.max() if how == "max" else a.mean())


def summarise(rows: list[dict]) -> dict[str, float]:
    """The row of one world and set over its seeds (feet x seeds pooled)."""
    p = {k: _pooled(rows, k) for k in ("time_to_safe_s", "time_to_useful_s", "over_rate", "over_rate_new",
                                       "useful_share", "useful_ready", "slide_new_m")}
    return {"runs": len(rows), "falls": sum(r["fell"] for r in rows), "feet_on_new_surface": len(p["time_to_safe_s"]),
            "unsafe": sum(not r.get("safe", True) for r in rows),
            "time_to_safe_p95_s": _stat(p["time_to_safe_s"], "p95"),
            "time_to_safe_max_s": _stat(p["time_to_safe_s"], "max"),
            "time_to_useful_p95_s": _stat(p["time_to_useful_s"], "p95"),
            "time_to_useful_max_s": _stat(p["time_to_useful_s"], "max"),
            "over_rate_mean": _stat(p["over_rate"], "mean"), "over_rate_max": _stat(p["over_rate"], "max"),
            "over_rate_new_mean": _stat(p["over_rate_new"], "mean"),
            "over_rate_new_max": _stat(p["over_rate_new"], "max"),
            "useful_share_mean": _stat(p["useful_share"], "mean"),
            "useful_ready_mean": _stat(p["useful_ready"], "mean"),
            "slide_new_m_mean": _stat(p["slide_new_m"], "mean"),
            "sliding_mps": float(np.mean([r["sliding_mps"] for r in rows])),
            "touchdown_slip_mps": _mean_of(rows, "touchdown_slip_mps"), "distance_m": _mean_of(rows, "distance_m")}


def _mean_of(rows: list[dict], key: str) -> float:
    """The mean of a per-run value over the seeds (NaN for rows written before the key existed)."""
    return float(np.mean([r.get(key, np.nan) for r in rows]))


COLUMNS = (("falls", "falls", "{:d}"), ("unsafe", "unsafe", "{:d}"), ("feet_on_new_surface", "feet", "{:d}"),
           ("time_to_safe_p95_s", "safe p95 [s]", "{:.3f}"), ("time_to_safe_max_s", "safe max [s]", "{:.3f}"),
           ("over_rate_new_mean", "over new", "{:.3f}"), ("over_rate_new_max", "over new max", "{:.3f}"),
           ("over_rate_mean", "over all", "{:.3f}"), ("time_to_useful_p95_s", "useful p95 [s]", "{:.2f}"),
           ("useful_share_mean", "useful", "{:.3f}"), ("useful_ready_mean", "useful ready", "{:.3f}"),
           ("slide_new_m_mean", "slide new [m]", "{:.3f}"),
           ("sliding_mps", "sliding [m/s]", "{:.4f}"), ("touchdown_slip_mps", "touchdown slip [m/s]", "{:.3f}"),
           ("distance_m", "distance [m]", "{:.2f}"))


def markdown(table: dict[str, dict]) -> str:
    """One row per world and set (the ``summary`` of each)."""
    lines = ["| world | estimator | " + " | ".join(c[1] for c in COLUMNS) + " |",
             "|---|---|" + "---|" * len(COLUMNS)]
    for key, v in table.items():
        world, name = key.split("/", 1)
        row = {k: v["summary"].get(k, float("nan")) for k, _, _ in COLUMNS}  # nan: a key newer than the file
        cells = [fmt.format(row[k]) if np.isfinite(row[k]) or isinstance(row[k], int) else str(row[k])
                 for k, _, fmt in COLUMNS]
        lines.append(f"| {world} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


PAIRED = (("slide_new_m", "slide new [m]", "{:+.4f}"), ("sliding_mps", "sliding [m/s]", "{:+.4f}"),
          ("touchdown_slip_mps", "touchdown slip [m/s]", "{:+.3f}"), ("distance_m", "distance [m]", "{:+.2f}"))


def paired_markdown(files: list[dict], ref: str, name: str) -> str:
    """Per world, set ``name`` against set ``ref`` seed by seed (the runs of every file pooled; a seed in both
    sets is a pair): for each of :data:`PAIRED` the reference's mean, the mean difference with its 95 % interval
    (1.96 standard errors of the paired differences) and in how many pairs ``name`` was higher."""
    runs: dict[str, dict[int, dict]] = {}
    for table in files:
        for key, v in table.items():
            runs.setdefault(key, {}).update({r["seed"]: r for r in v["runs"]})
    worlds = dict.fromkeys(k.split("/", 1)[0] for k in runs)
    lines = [f"`{name}` against `{ref}`, pair by pair (same world and seed): the reference's mean, the mean "
             f"difference `{name}` - `{ref}` +- its 95 % interval, and the pairs where `{name}` is higher.\n",
             "| world | pairs | " + " | ".join(f"{c[1]}: {ref} / difference / higher" for c in PAIRED) + " |",
             "|---|---|" + "---|" * len(PAIRED)]
    for world in worlds:
        a, b = runs.get(f"{world}/{ref}", {}), runs.get(f"{world}/{name}", {})
        seeds = sorted(set(a) & set(b))
        cells = []
        for key, _, fmt in PAIRED:
            x = np.array([_run_value(a[s], key) for s in seeds])
            d = np.array([_run_value(b[s], key) for s in seeds]) - x
            ok = np.isfinite(d)
            if ok.sum() < 2:
                cells.append("–")
                continue
            half = 1.96 * d[ok].std(ddof=1) / np.sqrt(ok.sum())
            cells.append(f"{x[ok].mean():.4g} / {fmt.format(d[ok].mean())} ± {half:.2g} / {int((d[ok] > 0).sum())}")
        lines.append(f"| {world} | {len(seeds)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _run_value(run: dict, key: str) -> float:
    """A run's value of ``key``: the mean over its feet for a per-foot list (NaN feet left out), NaN if absent."""
    v = run.get(key, float("nan"))
    if isinstance(v, list):
        v = [x for x in v if x is not None and np.isfinite(x)]
        return float(np.mean(v)) if v else float("nan")
    return float(v)


def merged_header(argv: list[str], files: list[Path], paired: bool = False) -> str:
    """The title and provenance of a table written from ``--out`` files (``--from-json``; ``paired``: their
    runs pooled, not replaced)."""
    names = ", ".join(f"`{f}`" for f in files)
    how = "their runs pooled" if paired else "a later file's rows replace an earlier's"
    return ("# Per-foot estimates in the loop\n\n"
            f"Generated by `python -m studies.estimator_per_foot_inloop {' '.join(argv)}` from {names} ({how}; "
            "each file holds every run's overrides, seed and summary). Sets "
            "named `T_*` run `filter=terrain`, `P_*` the paper's filter with per-foot cones; the columns are "
            "defined in the module's docstring.\n\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--set", action="append", default=[], metavar="NAME=OVERRIDES",
                    help="an estimator set: space-separated Hydra overrides (after the world's)")
    ap.add_argument("--world", action="append", default=[], metavar="NAME=OVERRIDES",
                    help="a world: space-separated Hydra overrides added to the default drop world")
    ap.add_argument("--out", type=Path, default=None, help="JSON of every run")
    ap.add_argument("--md", type=Path, default=None, help="markdown table of the summaries")
    ap.add_argument("--from-json", type=Path, nargs="+", default=None, metavar="FILE",
                    help="run nothing: write --md from these --out files (a later file's rows replace an earlier's)")
    ap.add_argument("--paired", nargs=2, default=None, metavar=("REF", "SET"),
                    help="with --from-json: SET against REF per world, seed by seed (the files' runs pooled)")
    a = ap.parse_args(argv)
    if a.from_json:
        files = [json.loads(f.read_text()) for f in a.from_json]
        merged: dict[str, dict] = {}
        for table in files:
            merged.update(table)
        body = paired_markdown(files, *a.paired) if a.paired else markdown(merged)
        text = merged_header(sys.argv[1:] if argv is None else argv, a.from_json, bool(a.paired)) + body
        print(text)
        if a.md is not None:
            a.md.write_text(text)
        return
    load0, commit = os.getloadavg(), git_commit()
    sets = dict(s.split("=", 1) for s in a.set) or {"oracle": "estimator=oracle"}
    worlds = dict(w.split("=", 1) for w in a.world) or {"drop_0.8_0.2": ""}
    table = {}
    for world, wov in worlds.items():
        for name, ov in sets.items():
            rows = [run(world_overrides(wov, ov), seed) for seed in a.seeds]
            key = f"{world}/{name}"
            table[key] = {"world": wov, "overrides": ov, "summary": summarise(rows), "runs": rows}
            print(key, json.dumps(table[key]["summary"]), flush=True)
            if a.out is not None:  # after every set: a killed study keeps what it measured
                a.out.parent.mkdir(parents=True, exist_ok=True)
                a.out.write_text(json.dumps(table, indent=2))
    if a.md is not None:
        a.md.parent.mkdir(parents=True, exist_ok=True)
        a.md.write_text(header(sys.argv[1:] if argv is None else argv, load0, a.seeds, commit) + markdown(table))


def git_commit() -> str:
    """The checkout's commit (short hash; ``+`` if the tree has changes), ``unknown`` outside git."""
    def run_(*c: str) -> str:
        return subprocess.run(["git", *c], capture_output=True, text=True, check=True).stdout.strip()

    try:
        return run_("rev-parse", "--short", "HEAD") + ("+" if run_("status", "--porcelain", "-uno") else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def header(argv: list[str], load0: tuple[float, ...], seeds: list[int], commit: str) -> str:
    """The command, the commit the study started at, seeds and the machine's load at start and end (1-min
    load average)."""
    cmd = "python -m studies.estimator_per_foot_inloop " + " ".join(shlex.quote(x) for x in argv)
    return (f"`{cmd}`\n\ncommit {commit}; seeds {seeds}; load average {load0[0]:.1f} at the start, "
            f"{os.getloadavg()[0]:.1f} at the end ({os.cpu_count()} cores); one process, torch 1 thread.\n\n")


if __name__ == "__main__":
    main()
