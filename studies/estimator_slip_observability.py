"""What proprioception can see of the friction when the filter plans with a given mu
(``python -m studies.estimator_slip_observability detect|identical [--filter ...] [--out FILE.md]``).

``detect``: constant floors (``scenario=flat``) with the filter planning at the true friction (``oracle``) or
at a fixed mu; the slip detector (:class:`estimators.slip.SlipDetector`, its defaults) runs beside the
estimator. Per run: the share of stances (loaded in proprioception, >= 80 ticks, after 1 s) in which it
found a slip, the tick of the stance it first did (median), and the plant's mean contact-point slip speed
of loaded feet [m/s] (the truth it should see). A floor that holds what the filter plans shows no slip; a
floor below the plan shows slips within the stance.

``identical``: the same seed on floors mu_a and 0.9 with the filter planning at a fixed mu below both. If the
plant never reaches either floor's cone, the two runs' joint trajectories differ only by the contact
solver's small differences: what the estimator can learn about the floor above the plan. Prints the
largest and the median (t > 1 s) joint-angle difference [rad] per floor; a difference that does not grow
as the floor moves away from 0.9 carries no information about it.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np

from estimators.slip import SlipDetector
from taslel_bench import api
from taslel_bench.interfaces import FrictionEstimate, Proprioception

RUN = ["scenario=flat", "duration=4", "record.mcap=false", "progress=false", "seed=100"]
DETECT_CASES = ((0.1, "oracle"), (0.2, "oracle"), (0.5, "oracle"), (0.9, "oracle"), (0.9, 0.2), (0.5, 0.2),
                (0.1, 0.2), (0.12, 0.2), (0.15, 0.2), (0.3, 0.4), (0.2, 0.3), (0.2, 0.8), (0.3, 0.8), (0.5, 0.8))


class WithDetector:
    """Wraps an estimator; runs a slip detector on the same observations and keeps its output per tick."""

    reads_imu = True  # the detector's trunk velocity comes from the IMU (the loop samples it only if asked)

    def __init__(self, inner) -> None:
        self.inner, self.name, self.det = inner, getattr(inner, "name", "estimator"), SlipDetector()
        self.loaded: list[np.ndarray] = []
        self.slipping: list[np.ndarray] = []

    def reset(self) -> None:
        self.inner.reset()
        self.det.reset()
        self.loaded, self.slipping = [], []

    def step(self, obs: Proprioception) -> FrictionEstimate:
        st = self.det.step(obs)
        self.loaded.append(st.loaded)
        self.slipping.append(st.slipping)
        return self.inner.step(obs)


def _estimator(plan: float | str) -> list[str]:
    return ["estimator=oracle"] if plan == "oracle" else ["estimator=fixed", f"estimator.mu={plan}"]


def run_wrapped(overrides: list[str], wrapper):
    """One episode of ``overrides`` with its estimator wrapped by ``wrapper(estimator)`` (a recorder that passes
    the estimate through): (result with its trace finalized, the wrapper). A run that errors raises."""
    res, w, _ = run_built(overrides, wrapper)
    return res, w


def run_built(overrides: list[str], wrapper):
    """:func:`run_wrapped` that also returns the episode's :class:`taslel_bench.sim.build.Built` (its config,
    controller and filter)."""
    from taslel_bench.sim.build import Built

    b = Built(api.compose(overrides))
    w = wrapper(b.episode.estimator)
    b.episode.estimator = w
    res = b.episode.run()
    if res.status == "error":
        raise RuntimeError(f"{overrides}: {res.message}")
    res.trace.finalize()
    return res, w, b


def _run(overrides: list[str]):
    return run_wrapped(overrides, WithDetector)


def stance_detection(loaded: np.ndarray, slipping: np.ndarray, t_s: np.ndarray,
                     min_ticks: int = 80, after_s: float = 1.0) -> tuple[int, float, float]:
    """(stances, share with a slip, median first-slip tick of the stance) over the feet's stances (runs of
    ``loaded`` ticks of at least ``min_ticks``, starting after ``after_s``); a slip counts up to 3 ticks
    after the stance (the detector's last judged ticks)."""
    n, hits, first = 0, 0, []
    for leg in range(loaded.shape[1]):
        x = loaded[:, leg].astype(int)
        edges = np.flatnonzero(np.diff(x)) + 1
        starts, ends = [e for e in edges if x[e]], [e for e in edges if not x[e]]
        for s0 in starts:
            e1 = next((e for e in ends if e > s0), len(x))
            if e1 - s0 < min_ticks or t_s[s0] < after_s:
                continue
            n += 1
            d = slipping[s0 : e1 + 3, leg]
            if d.any():
                hits += 1
                first.append(int(np.argmax(d)))
    return n, hits / max(n, 1), float(np.median(first)) if first else float("nan")


def detect(filt: list[str]) -> list[str]:
    lines = ["| floor mu | filter plans | fell | stances | with a slip | first slip tick (median) | plant slip [m/s] |",
             "|---|---|---|---|---|---|---|"]
    for mu, plan in DETECT_CASES:
        res, w = _run([*RUN, f"scenario.friction={mu}", *_estimator(plan), *filt])
        tr, n = res.trace, res.trace.n
        stances, share, first = stance_detection(np.array(w.loaded[:n]), np.array(w.slipping[:n]), tr.t_s[:n])
        slip = np.linalg.norm(tr.slip_w[:n], axis=-1)[tr.in_contact[:n]].mean()
        lines.append(f"| {mu} | {plan} | {int(res.fell)} | {stances} | {share:.3f} | {first:.0f} | {slip:.3f} |")
        print(lines[-1], flush=True)
    return lines


def identical(filt: list[str], plans: tuple[float, ...] = (0.2, 0.3),
              floors: tuple[float, ...] = (0.25, 0.35, 0.5)) -> list[str]:
    lines = ["| filter plans | floor a | max dq vs 0.9 [rad] | median dq, t > 1 s [rad] |", "|---|---|---|---|"]
    for plan in plans:
        ref, _ = _run([*RUN, "scenario.friction=0.9", *_estimator(plan), *filt])
        for mu in floors:
            if mu < plan:
                continue
            other, _ = _run([*RUN, f"scenario.friction={mu}", *_estimator(plan), *filt])
            n = min(ref.trace.n, other.trace.n)
            dq = np.abs(ref.trace.q[:n] - other.trace.q[:n]).max(axis=1)
            late = ref.trace.t_s[:n] > 1.0
            lines.append(f"| {plan} | {mu} | {dq.max():.4f} | {np.median(dq[late]):.4f} |")
            print(lines[-1], flush=True)
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("detect", "identical"))
    ap.add_argument("--filter", default="filter=terrain", help="Hydra overrides of the filter (space-separated)")
    ap.add_argument("--out", type=Path, default=None, help="markdown table")
    a = ap.parse_args(argv)
    lines = (detect if a.what == "detect" else identical)(a.filter.split())
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        cmd = "python -m studies.estimator_slip_observability " + " ".join(
            shlex.quote(x) for x in (sys.argv[1:] if argv is None else argv))
        a.out.write_text(f"`{cmd}` (seed 100, 4 s)\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
