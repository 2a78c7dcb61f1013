"""How much friction the trot uses, and how well proprioception measures it: the signal an active friction
probe would read (``python -m studies.estimator_probe_signal [--out FILE.md]``).

The per-foot work (075da76) found that under ``filter=terrain`` no passive estimator can be useful above the friction
the filter plans with. An active probe (a foot deliberately loaded towards a higher force ratio, with an internal force
between two stance feet so the trunk feels nothing) would need two things this study measures on flat floors:

* **what the gait already uses**: the plant's force ratio |f_t| / f_n of each loaded foot (MuJoCo's contact
  frame, feet with f_n >= 20 N), per stance its largest value over the first 30 ms (the landing) and over the
  rest (the support), medians and p90 over the stances: the friction the trot proves without any probe;
* **how well proprioception reads it**: the slip detector's torque-implied ratio (quasi-static leg,
  ``estimators.slip``), without and with the legs' own weight subtracted (``SlipSettings.leg_gravity``),
  against the plant's on the same support ticks (the detector sees the previous tick's torque: compared with
  the plant's force one tick earlier): signed median error and |error| p50 / p90 / p99; the same over the
  landing ticks with leg gravity.

Runs: seed 100, 0.5 s stand + 4 s trot, the URDF plant, stances after 1 s; cases in ``CASES`` (filter, the mu it
plans with, the floor).
"""

from __future__ import annotations

import numpy as np

from estimators.slip import SlipDetector, SlipSettings
from studies.estimator_slip_observability import run_wrapped
from studies.study_table import table_study
from taslel_bench.interfaces import FrictionEstimate, Proprioception

RUN = ["scenario=flat", "duration=4", "record.mcap=false", "progress=false", "seed=100"]
PAPER_PER_FOOT = ["filter=id_cbf_qp", "+filter.friction_cone=terrain"]
CASES = (("T", ["filter=terrain"], 0.2, 0.5), ("T", ["filter=terrain"], 0.2, 1.0),
         ("T", ["filter=terrain"], "oracle", 0.5), ("T", ["filter=terrain"], "oracle", 1.0),
         ("P", PAPER_PER_FOOT, "oracle", 0.5), ("P", PAPER_PER_FOOT, "oracle", 1.0),
         ("nominal", ["filter.enabled=false"], "oracle", 1.0))
LOADED_N = 20.0  # [N] plant normal force of a loaded foot
LANDING_TICKS = 30  # first ticks of a stance counted as the landing
MIN_STANCE_TICKS = 80


class RatioRecorder:
    """Wraps an estimator; runs a slip detector on the same observations and keeps its torque-implied ratio."""

    reads_imu = True  # the detector's trunk velocity comes from the IMU (the loop samples it only if asked)

    def __init__(self, inner) -> None:
        self.inner, self.name = inner, getattr(inner, "name", "estimator")
        self.dets = (SlipDetector(), SlipDetector(SlipSettings(leg_gravity=True)))
        self.ratio: list[np.ndarray] = []

    def reset(self) -> None:
        self.inner.reset()
        for det in self.dets:
            det.reset()
        self.ratio = []

    def step(self, obs: Proprioception) -> FrictionEstimate:
        self.ratio.append(np.stack([det.step(obs).ratio for det in self.dets]))  # (2, 4)
        return self.inner.step(obs)


def _run(overrides: list[str]):
    res, rec = run_wrapped(overrides, RatioRecorder)
    return res, np.array(rec.ratio)


def stances(loaded: np.ndarray, t_s: np.ndarray) -> list[tuple[int, int, int]]:
    """(leg, first tick, end tick) of every run of ``loaded`` ticks of at least MIN_STANCE_TICKS after 1 s."""
    out = []
    for leg in range(loaded.shape[1]):
        x = np.concatenate([[0], loaded[:, leg].astype(int), [0]])
        edges = np.flatnonzero(np.diff(x))
        for s0, e1 in zip(edges[::2], edges[1::2], strict=True):
            if e1 - s0 >= MIN_STANCE_TICKS and t_s[s0] >= 1.0:
                out.append((leg, int(s0), int(e1)))
    return out


def _abs_q(x: np.ndarray, p: float) -> float:
    return float(np.percentile(np.abs(x), p)) if len(x) else float("nan")


def _errors(detector_ratio: np.ndarray, true_ratio: np.ndarray, spans: list[tuple[int, slice]]) -> str:
    """Cells: median signed error and |error| p50 / p90 / p99 over the ticks of ``spans`` (leg, ticks)."""
    # the detector at tick k reads the torque applied during tick k - 1: compare with the plant one tick earlier
    est = np.full_like(true_ratio, np.nan)
    est[:-1] = detector_ratio[1:]
    e = np.concatenate([est[sl, leg] - true_ratio[sl, leg] for leg, sl in spans]) if spans else np.zeros(0)
    e = e[np.isfinite(e)]
    return (f"{np.median(e):+.3f} | {_abs_q(e, 50):.3f} / {_abs_q(e, 90):.3f} / {_abs_q(e, 99):.3f}" if len(e)
            else "- | -")


def case_row(name: str, filt: list[str], plan: float | str, floor: float) -> str:
    est = ["estimator=oracle"] if plan == "oracle" else ["estimator=fixed", f"estimator.mu={plan}"]
    res, ratio_hat = _run([*RUN, f"scenario.friction={floor}", *est, *filt])
    tr = res.trace
    n = min(tr.n, len(ratio_hat))
    fn, ft = tr.contact_fn_n[:n].sum(axis=2), np.abs(tr.contact_ft_n[:n]).sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        true_ratio = np.where(fn >= LOADED_N, ft / fn, np.nan)
    land_max, support_max, support, landing = [], [], [], []
    for leg, s0, e1 in stances(fn >= LOADED_N, tr.t_s[:n]):
        land, sup = slice(s0, s0 + LANDING_TICKS), slice(s0 + LANDING_TICKS, e1)
        land_max.append(np.nanmax(true_ratio[land, leg]))
        support_max.append(np.nanmax(true_ratio[sup, leg]))
        support.append((leg, sup))
        landing.append((leg, land))
    lm, sm = np.array(land_max), np.array(support_max)
    return (f"| {name} | {plan} | {floor} | {int(res.fell)} | {len(lm)} | {np.median(lm):.3f} / "
            f"{np.percentile(lm, 90):.3f} | {np.median(sm):.3f} / {np.percentile(sm, 90):.3f} | "
            f"{_errors(ratio_hat[:n, 0], true_ratio, support)} | {_errors(ratio_hat[:n, 1], true_ratio, support)} | "
            f"{_errors(ratio_hat[:n, 1], true_ratio, landing)} |")


def main(argv: list[str] | None = None) -> None:
    header = [("| filter | plans mu | floor | fell | stances | landing max ratio, median / p90 | support max ratio, "
               "median / p90 | quasi-static: error median | abs error p50 / p90 / p99 | with leg gravity: error median "
               "| abs error p50 / p90 / p99 | landing, with leg gravity: error median | abs error p50 / p90 / p99 |"),
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    table_study("studies.estimator_probe_signal", __doc__, header, (case_row(*case) for case in CASES), argv)

if __name__ == "__main__":
    main()
