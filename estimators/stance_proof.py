"""Friction proven by the feet that hold: a lower bound that lets a per-foot estimate rise above its base.

Under ``filter=terrain`` the filter keeps every stance force inside the cone it plans with, so a floor above the
plan leaves no trace in proprioception (``studies/notes/estimators/round8.md``). But the stance feet do use the
cone they are given: with the plan at 0.2 the largest force ratio of a stance (after its landing) is 0.18 in the
median stance, with the oracle's 0.5 it is 0.39 (``studies/estimator_probe_signal.py``). A foot that *holds*
(no slip) while the ground carries a force ratio r proves the friction there is at least r (Coulomb). Planning
each foot a small ``step`` above what has been proven where it stands lets the next stances use, and prove, a
little more: the estimate climbs stance by stance up to what the floor holds, and a floor that does not hold
the step shows a slip (:class:`estimators.slip.SlipDetector`), which the caller turns into a cap and a
:meth:`StanceProof.forget_near`.

The ratio is the slip detector's torque-implied ``|f_xy| / f_z`` (quasi-static leg), which reads high: by
+0.044 to +0.053 in the median support tick on flat floors 0.5 and 1.0 against MuJoCo's contact forces, error
p90 0.07-0.08 (``studies/estimator_probe_signal.py``). A proof is therefore the ratio less ``bias``, held over
``hold_ticks`` consecutive loaded, non-slipping ticks (the window's smallest value: one spike proves nothing),
after the first ``settle_s`` of the stance (the landing, whose transient ratios are the least accurate).

Proofs are places: each holds the best ratio a foot proved during one stance and where the foot stood (dead
reckoned, world axes). A foot's proven friction is the best proof within ``reach_m`` of where it is now, so
a foot that walks onto another surface leaves its proofs behind (a drop is met at the base's value, not at the
old floor's), and a hind foot stepping where a front foot held inherits that proof. Units: m, s; ratios [-].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.slip import FootState
from taslel_bench.interfaces import integer, number

MAX_PROOFS = 64  # proofs remembered (the newest)


@dataclass
class ProofSettings:
    """Fields of ``estimator.proof`` (:class:`StanceProof`)."""

    step: float = 0.05  # [-] each foot is planned this far above what is proven where it stands
    bias: float = 0.05  # [-] subtracted from the torque-implied ratio (it reads high by about this)
    hold_ticks: int = 10  # consecutive holding ticks whose smallest ratio is a proof
    settle_s: float = 0.03  # [s] start of a stance not used (the landing)
    reach_m: float = 0.25  # [m] a proof applies to feet within this horizontal distance of its place

    def __post_init__(self) -> None:
        number("estimator.proof.step", self.step, 0.0, 1.0)
        number("estimator.proof.bias", self.bias, 0.0, 1.0)
        integer("estimator.proof.hold_ticks", self.hold_ticks, 1, 1000)
        number("estimator.proof.settle_s", self.settle_s, 0.0, 1.0, unit="s")
        number("estimator.proof.reach_m", self.reach_m, 0.0, 10.0, lo_open=True, unit="m")


class StanceProof:
    """Proofs of friction from holding stance feet (module doc). Call :meth:`update` every tick with the slip
    detector's output, then :meth:`proven` for the four feet."""

    def __init__(self, settings: ProofSettings) -> None:
        self.s = settings
        self.reset()

    def reset(self) -> None:
        s = self.s
        self._xy = np.zeros((0, 2))  # [m] proof places (world)
        self._value = np.zeros(0)  # [-] proven friction at each place
        self._open = np.full(4, -1)  # each foot's proof row of its current stance (-1: none yet)
        self._stance_ticks = np.zeros(4, np.int64)  # loaded ticks of each foot's current stance
        self._window = np.full((s.hold_ticks, 4), np.nan)  # ring of the last holding ticks' ratios
        self._held = np.zeros(4, np.int64)  # consecutive holding ticks (after the landing)
        self._t_loaded = np.full(4, np.inf)  # [s] each foot's stance start
        self.proofs = 0  # proofs opened this episode (stances that proved something)

    def update(self, t_s: float, feet: FootState) -> None:
        """Extend each holding foot's proof; a foot that slips or lifts off ends its stance's proof."""
        s = self.s
        for i in range(4):
            if not feet.loaded[i]:
                self._t_loaded[i], self._open[i], self._held[i] = np.inf, -1, 0
                continue
            if not np.isfinite(self._t_loaded[i]):
                self._t_loaded[i] = t_s
            if feet.slipping[i] or not np.isfinite(feet.ratio[i]):
                self._open[i], self._held[i] = -1, 0  # a slipping foot proves nothing this stance
                continue
            if t_s - self._t_loaded[i] < s.settle_s:
                continue
            self._window[self._held[i] % s.hold_ticks, i] = feet.ratio[i]
            self._held[i] += 1
            if self._held[i] < s.hold_ticks:
                continue
            value = float(self._window[:, i].min()) - s.bias
            if value <= 0.0:
                continue
            row = self._open[i]
            if row < 0:
                self._open[i] = self._add(feet.feet_w[i, :2], value)
            elif value > self._value[row]:
                self._value[row] = value
                self._xy[row] = feet.feet_w[i, :2]

    def _add(self, xy_w: np.ndarray, value: float) -> int:
        dropped = max(0, len(self._value) + 1 - MAX_PROOFS)
        self._open = np.where(self._open >= dropped, self._open - dropped, -1)
        self._xy = np.vstack([self._xy, xy_w])[-MAX_PROOFS:]
        self._value = np.append(self._value, value)[-MAX_PROOFS:]
        self.proofs += 1
        return len(self._value) - 1

    def proven(self, feet_xy_w: np.ndarray) -> np.ndarray:
        """(4,) [-] the best proof within ``reach_m`` of each foot's place (world xy, m); 0 where none."""
        if not len(self._value):
            return np.zeros(4)
        d2 = ((feet_xy_w[:, None, :] - self._xy[None, :, :]) ** 2).sum(axis=2)  # (4, proofs)
        near = d2 <= self.s.reach_m**2
        return np.where(near, self._value[None, :], 0.0).max(axis=1)

    def forget_near(self, xy_w: np.ndarray) -> None:
        """Drop the proofs within ``reach_m`` of a slip's place: the surface there held less than they say."""
        if not len(self._value):
            return
        keep = ((self._xy - xy_w) ** 2).sum(axis=1) > self.s.reach_m**2
        self._xy, self._value = self._xy[keep], self._value[keep]
        self._open[:] = -1  # rows moved: every holding foot starts a new proof
