"""Per-foot friction estimates in the loop, each foot judged against its own surface
(``python -m studies.estimator_per_foot_inloop --seeds 0 1 2 3 4 [--set NAME=OVERRIDES ...]``).

For every set (Hydra overrides of one run config) and seed, one episode of the core runner; the estimator
is wrapped to record what it reported for each foot (``mu_per_foot``, or ``mu`` for all four). Per foot,
on the ticks the foot is loaded (its contact sensor found a contact) and against the friction under it
(the trace's ``mu_foot``):

* over-estimation: share of the foot's loaded ticks with mu_hat > mu + 0.05;
* time to safe [s]: after the foot's first loaded tick on a surface other than its starting one, until its
  first loaded tick that is not over-estimated (0 if none was); NaN if the foot never met another surface;
* time to useful [s] (rises): from the same tick until its first loaded tick with
  mu_hat >= min(mu, 0.5) - 0.1 (:func:`estimators.safety.useful`); inf if never, NaN as above;
* useful share: share of the foot's loaded ticks with mu_hat >= min(mu, 0.5) - 0.1 (an estimate pinned at
  its floor is never over-estimated and scores 0 s to safe on a drop; this says whether it was any use);
* falls and the plant's foot sliding (mean horizontal slip speed of loaded feet [m/s]).

Prints one row per set: the p95 of the time to safe and to useful over feet x seeds, the pooled
over-estimation rate, falls and sliding; ``--out`` writes the rows as JSON.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from estimators.safety import useful
from taslel_bench import api
from taslel_bench.interfaces import OVERESTIMATE_MARGIN, FrictionEstimate, Proprioception

DEFAULT_WORLD = ["scenario=friction_patch", "scenario.friction=0.8", "scenario.friction_after=0.2",
                 "scenario.change_at_m=0.6", "duration=6", "filter=terrain", "record.mcap=false", "progress=false"]


class Recorder:
    """Wraps an estimator; keeps the (4,) friction it reported for each foot every tick."""

    def __init__(self, inner) -> None:
        self.inner, self.name, self.rows = inner, getattr(inner, "name", "estimator"), []

    def reset(self) -> None:
        self.inner.reset()
        self.rows = []

    def step(self, obs: Proprioception) -> FrictionEstimate:
        est = self.inner.step(obs)
        self.rows.append(np.full(4, est.mu) if est.mu_per_foot is None else np.asarray(est.mu_per_foot, float))
        return est


def foot_scores(mu_hat: np.ndarray, mu_foot: np.ndarray, loaded: np.ndarray, dt: float) -> dict[str, list]:
    """Per-foot over-estimation rate on loaded ticks, time to safe and time to useful [s] (see the module doc)."""
    over = mu_hat > mu_foot + OVERESTIMATE_MARGIN
    good = useful(mu_foot, mu_hat)
    rate, t_safe, t_useful, useful_share = [], [], [], []
    for leg in range(4):
        ld = loaded[:, leg]
        rate.append(float(over[ld, leg].mean()) if ld.any() else float("nan"))
        useful_share.append(float(good[ld, leg].mean()) if ld.any() else float("nan"))
        changed = np.flatnonzero(ld & (np.abs(mu_foot[:, leg] - mu_foot[0, leg]) > 1e-9))
        if not len(changed):
            t_safe.append(float("nan"))
            t_useful.append(float("nan"))
            continue
        k0 = changed[0]
        t_safe.append(_first(ld[k0:] & ~over[k0:, leg], dt))
        t_useful.append(_first(ld[k0:] & good[k0:, leg], dt))
    return {"over_rate": rate, "time_to_safe_s": t_safe, "time_to_useful_s": t_useful, "useful_share": useful_share}


def _first(ok: np.ndarray, dt: float) -> float:
    """[s] time of the first True in ``ok`` (ticks of dt from its start); inf if none."""
    k = np.flatnonzero(ok)
    return float(k[0] * dt) if len(k) else float("inf")


def run(overrides: list[str], seed: int) -> dict[str, object]:
    """One episode of ``overrides`` + ``seed``; its per-foot scores, fall and sliding."""
    from taslel_bench.sim.build import Built

    b = Built(api.compose([*overrides, f"seed={seed}"]))
    rec = Recorder(b.episode.estimator)
    b.episode.estimator = rec
    res = b.episode.run()
    tr = res.trace
    tr.finalize()
    n = tr.n
    mu_hat, loaded = np.array(rec.rows[:n]), tr.in_contact[:n]
    dt = float(tr.t_s[1] - tr.t_s[0]) if n > 1 else 1e-3
    scores = foot_scores(mu_hat, tr.mu_foot[:n], loaded, dt)
    slip = np.linalg.norm(tr.slip_w[:n], axis=-1)
    return {"seed": seed, "fell": bool(res.fell), "status": res.status, **scores,
            "sliding_mps": float(slip[loaded].mean()) if loaded.any() else float("nan")}


def _pooled(rows: list[dict], key: str) -> np.ndarray:
    return np.array([x for r in rows for x in r[key] if not np.isnan(x)])


def summarise(rows: list[dict]) -> dict[str, float]:
    t, tu, over = _pooled(rows, "time_to_safe_s"), _pooled(rows, "time_to_useful_s"), _pooled(rows, "over_rate")
    use = _pooled(rows, "useful_share")
    return {"runs": len(rows), "falls": sum(r["fell"] for r in rows), "feet_on_new_surface": len(t),
            "time_to_safe_p95_s": float(np.percentile(t, 95)) if len(t) else float("nan"),
            "time_to_safe_max_s": float(t.max()) if len(t) else float("nan"),
            "time_to_useful_p95_s": float(np.percentile(tu, 95)) if len(tu) else float("nan"),
            "time_to_useful_max_s": float(tu.max()) if len(tu) else float("nan"),
            "over_rate_mean": float(over.mean()) if len(over) else float("nan"),
            "over_rate_max": float(over.max()) if len(over) else float("nan"),
            "useful_share_mean": float(use.mean()) if len(use) else float("nan"),
            "sliding_mps": float(np.mean([r["sliding_mps"] for r in rows]))}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--set", action="append", default=[], metavar="NAME=OVERRIDES",
                    help="a named set: space-separated Hydra overrides added to the default drop world")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    sets = dict(s.split("=", 1) for s in a.set) or {"oracle": "estimator=oracle"}
    table = {}
    for name, ov in sets.items():
        rows = [run(DEFAULT_WORLD + ov.split(), seed) for seed in a.seeds]
        table[name] = {"overrides": ov, "summary": summarise(rows), "runs": rows}
        print(name, json.dumps(table[name]["summary"]), flush=True)
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(table, indent=2))


if __name__ == "__main__":
    main()
