"""Robust option of the safety filter (``filter.robust``, off by default): margins that make the ECBF and
friction rows hold although the filter's model is wrong, input-to-state-safe style.

* ECBF rows: psi = hdot_e + a2 h_e >= delta [m/s²] instead of >= 0, with
  delta = ``ecbf_margin_mps2`` + ``adaptive_gain`` x (running RMS of the shortfall of the realised condition
  behind the planned one). The shortfall is measured online from the filter's own barrier values: for a foot
  that stayed in swing, psi_realised = (h_e(now) - h_e(previous tick)) / dt + a2 h_e(previous tick) against
  the psi the filter planned on the previous tick; the RMS is an exponential average over
  ``adaptive_time_constant_s``. A model that matches the plant leaves it near 0 (the one-tick difference of a
  matched model stays within ~1 m/s² in 99 % of swing ticks); unknown joint losses or mass raise it. delta is
  capped at ``max_margin_mps2``.
* Friction rows: the pyramid uses mu (1 - ``friction_margin``) instead of mu, and each per-foot cone its foot's
  mu_i (1 - ``friction_margin``) (whether or not ``enabled``, which switches the ECBF margins: ``filter=terrain``
  uses the friction margin alone). Before commit 4614b04 the per-foot values were not scaled: the margin was off
  wherever the estimator gave one value per foot (the oracle on a world of several frictions, the slip estimators).
* Disturbance observer (``observer_time_constant_s`` > 0): the equations of motion become
  M vdot + h = S u + J' lambda + d_hat, with d_hat [N·m] on the joint rows a low-pass (that time constant) of
  the residual the filter can compute from what a real controller knows: r = M vdot_measured + h - S u -
  J' lambda_planned over the previous tick (vdot_measured the finite difference of the measured velocity,
  lambda_planned its own contact-force plan) = the generalised force the model misses. Unknown joint losses
  or a weaker motor show in r; the trunk rows, dominated by errors of the contact-force plan, are not
  estimated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from taslel_bench.util.params import param


@dataclass(frozen=True)
class RobustSettings:
    """``filter.robust``: margins for a wrong model (module doc); off = the paper's rows."""

    enabled: bool = param(False, "switches the ECBF margins below (the friction margin applies either way)")
    ecbf_margin_mps2: float = param(0.0, "fixed margin on the ECBF condition psi = hdot_e + a2 h_e", unit="m/s²",
                                    lo=0.0, hi=100.0)
    adaptive_gain: float = param(0.0, "x running RMS of the shortfall of the realised psi behind the planned one",
                                 lo=0.0, hi=100.0)
    adaptive_time_constant_s: float = param(0.5, "time constant of that running RMS", unit="s", lo=0.0,
                                            lo_open=True, hi=60.0)
    max_margin_mps2: float = param(50.0, "cap on the total ECBF margin", unit="m/s²", lo=0.0, hi=1000.0)
    friction_margin: float = param(0.0, "the pyramids use mu (1 - friction_margin)", lo=0.0, hi=1.0, hi_open=True)
    observer_time_constant_s: float = param(0.0, "disturbance observer on the equations of motion (low-pass of the "
                                                 "residual); 0: off", unit="s", lo=0.0, hi=10.0)


class RobustMargin:
    """Online state of the adaptive ECBF margin for one episode (one per filter)."""

    def __init__(self, settings: RobustSettings, alpha2: float, control_dt_s: float) -> None:
        self.s, self.alpha2, self.dt = settings, alpha2, control_dt_s
        self._weight = 1.0 - math.exp(-control_dt_s / settings.adaptive_time_constant_s)
        self.reset()

    def reset(self) -> None:
        self.mean_square = 0.0  # [(m/s²)²] running mean of the squared shortfall
        self._previous: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # barrier id -> (h_e, psi planned)

    @property
    def ecbf_margin_mps2(self) -> float:
        delta = self.s.ecbf_margin_mps2 + self.s.adaptive_gain * math.sqrt(self.mean_square)
        return min(delta, self.s.max_margin_mps2) if self.s.enabled else 0.0

    def observe(self, barriers) -> None:
        """After a tick's rows are written (h_e of this tick) and before the new solve: compare the condition
        realised since the previous tick with the one planned then, per foot that stayed in swing."""
        shortfalls = []
        for barrier in barriers:
            previous = self._previous.get(id(barrier))
            if previous is not None:
                he_prev, psi_prev = previous
                realised = (barrier.h_e - he_prev) / self.dt + self.alpha2 * he_prev
                gap = psi_prev - realised
                shortfalls.extend(np.maximum(gap[np.isfinite(gap)], 0.0))
        for value in shortfalls:
            self.mean_square += self._weight * (value * value - self.mean_square)

    def remember(self, barriers) -> None:
        """After a solve: this tick's h_e and planned condition, for the next tick's comparison."""
        for barrier in barriers:
            self._previous[id(barrier)] = (barrier.h_e.copy(), barrier.psi_planned.copy())


class DisturbanceObserver:
    """d_hat [N·m] on the joint rows of swing legs: the generalised force the model misses there, from the
    previous tick's residual (see the module doc). A leg's estimate is updated only over ticks the leg swung
    (no contact force on it: its joint rows hold model error alone) and applied only while it swings. One
    per filter; :meth:`update` once per tick before the QP is built."""

    def __init__(self, time_constant_s: float, control_dt_s: float, nv: int) -> None:
        self.dt = control_dt_s
        self._weight = 1.0 - math.exp(-control_dt_s / time_constant_s)
        self.estimate = np.zeros(nv)  # running estimate per joint row
        self.d_hat = np.zeros(nv)  # what the EoM rows get this tick (swing legs only)
        self._previous: tuple | None = None  # (v, M, h - S u - J' lambda, swing joint rows)

    def reset(self) -> None:
        self.estimate[:] = 0.0
        self.d_hat[:] = 0.0
        self._previous = None

    def update(self, v: np.ndarray, in_stance: np.ndarray) -> None:
        """Fold the residual of the tick that ended at velocity ``v`` into the estimate of the legs that swung
        through it; set d_hat for the legs that swing now (``in_stance`` per leg)."""
        if self._previous is not None:
            v_prev, mass, rest, swung = self._previous
            residual = mass @ ((v - v_prev) / self.dt) + rest
            self.estimate[swung] += self._weight * (residual[swung] - self.estimate[swung])
        self.d_hat[:] = 0.0
        swing = _joint_rows(~np.asarray(in_stance, bool))
        self.d_hat[swing] = self.estimate[swing]

    def remember(self, v: np.ndarray, mass: np.ndarray, h: np.ndarray, u: np.ndarray,
                 jac_t_lambda: np.ndarray | None, in_stance: np.ndarray) -> None:  # fmt: skip
        """This tick's state, model terms and the filter's answer (None when it failed: no residual then)."""
        if jac_t_lambda is None:
            self._previous = None
            return
        rest = h.copy()
        rest[6:] -= u
        rest -= jac_t_lambda
        self._previous = (v.copy(), mass.copy(), rest, _joint_rows(~np.asarray(in_stance, bool)))


def _joint_rows(legs: np.ndarray) -> np.ndarray:
    """Pinocchio velocity rows of the joints of the selected legs (3 per leg after the 6 trunk rows)."""
    return np.flatnonzero(np.r_[np.zeros(6, bool), np.repeat(legs, 3)])
