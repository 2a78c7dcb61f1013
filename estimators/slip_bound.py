"""Per-foot friction from a base estimator and the slips proprioception sees (``estimator=slip_*``).

:class:`SlipBoundEstimator` wraps any estimator (a learned model, ``fixed``) and reports, per foot,

    mu_i = min(base_i, cap_i(t))

with ``base_i`` the base estimator's value for foot i (its ``mu_per_foot``, or its ``mu`` for all four) and
``cap_i`` what the slips of that foot -- and of the feet ahead of it on the path -- prove:

* **Slip** (:class:`estimators.slip.SlipDetector`: the foot's world velocity from leg kinematics, the
  trunk IMU and the holding feet's odometry): the moment foot i is confirmed slipping, ``cap_i = floor_mu``
  (a slipping foot's ground holds less than the filter planned; nothing finer is known yet). When the slip
  ends (or after ``ratio_ticks`` slipping ticks) the cap becomes ``max(floor_mu, ratio_scale x the median
  torque-implied force ratio of the slipping ticks)``: while a foot slides its force ratio *is* the
  friction, measured through a quasi-static leg (noisy; ``ratio_scale`` < 1 takes the bias into account).
* **Ahead on the path**: surfaces are patches the robot walks into, so a slip at path coordinate s (the
  dead-reckoned foot position along the direction of travel) caps every foot at or beyond ``s - behind_m``
  on the path, by the same value, as soon as it gets there (a hind foot stepping where a front foot slipped
  is capped before it loads; the other front foot too).
* **Relaxation**: a cap rises at ``rise_per_s`` [1/s] after the slip that set it (a foot that slips again is
  capped again); it stops mattering when it passes the base.

The reported ``mu`` is the lowest foot's; ``ready`` and ``sigma`` are the base's. Frames and units as in
:mod:`estimators.slip`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimators.slip import FootState, SlipDetector, SlipSettings
from taslel_bench.interfaces import MAX_FRICTION, Estimator, FrictionEstimate, Proprioception, integer, number


@dataclass
class SlipEvent:
    """A slip seen at one place on the path: caps the feet that reach it."""

    xy_w: np.ndarray  # [m] (2,) where the foot slipped (dead reckoning, world axes)
    t_s: float  # [s] time the cap was last set
    cap: float  # [-] cap at t_s
    foot: int  # the foot that slipped (LEGS order)
    ratios: list[float] = field(default_factory=list)  # [-] torque-implied force ratios while slipping


class SlipBoundEstimator:
    """Per-foot caps from slips on top of a base estimator (module doc)."""

    def __init__(self, base: Estimator, floor_mu: float = 0.1, rise_per_s: float = 0.1, ratio_scale: float = 0.8,
                 ratio_ticks: int = 20, behind_m: float = 0.05, ahead_m: float = 0.3, propagate: bool = True,
                 detector: dict[str, Any] | None = None, name: str | None = None) -> None:
        """``base``: the estimator whose per-foot values are capped; ``floor_mu`` [-]: cap at a slip's
        onset (the lowest friction the deployment may meet); ``rise_per_s`` [1/s]: relaxation of a cap;
        ``ratio_scale`` [-]: factor on the median slipping force ratio (0: caps stay at the floor until they
        relax); ``ratio_ticks``: slipping ticks after which the ratio cap is applied even if the slip goes on;
        ``behind_m`` / ``ahead_m`` [m]: a slip caps the other feet from this far behind its place to this far
        ahead of it along the path (``propagate``);
        ``detector``: :class:`estimators.slip.SlipSettings` fields."""
        self.base = base
        self.floor_mu = number("estimator.floor_mu", floor_mu, 0.0, MAX_FRICTION, lo_open=True)
        self.rise_per_s = number("estimator.rise_per_s", rise_per_s, 0.0, 100.0, unit="1/s")
        self.ratio_scale = number("estimator.ratio_scale", ratio_scale, 0.0, 1.0)
        self.ratio_ticks = integer("estimator.ratio_ticks", ratio_ticks, 1)
        self.behind_m = number("estimator.behind_m", behind_m, 0.0, 5.0, unit="m")
        self.ahead_m = number("estimator.ahead_m", ahead_m, 0.0, 100.0, lo_open=True, unit="m")
        self.propagate = bool(propagate)
        self.detector = SlipDetector(SlipSettings(**dict(detector or {})))
        self.name = name if name is not None else f"slip_{getattr(base, 'name', 'base')}"
        self.reset()

    def reset(self) -> None:
        self.base.reset()
        self.detector.reset()
        self.events: list[SlipEvent] = []
        self._open: list[SlipEvent | None] = [None] * 4  # the event of each foot's ongoing slip
        self.slips_detected = 0  # slip onsets (feet x events) this episode
        self.last_feet: FootState | None = None
        self.last_caps = np.full(4, np.inf)

    # ---------------------------------------------------------------------------------------- loop
    def step(self, obs: Proprioception) -> FrictionEstimate:
        est = self.base.step(obs)
        feet = self.detector.step(obs)
        self.last_feet = feet
        self._update_events(obs.t_s, feet)
        caps = self._caps(obs.t_s, feet)
        self.last_caps = caps
        base = np.full(4, est.mu) if est.mu_per_foot is None else np.asarray(est.mu_per_foot, float)
        mu_feet = np.minimum(base, caps)
        return FrictionEstimate(mu=float(mu_feet.min()), sigma=est.sigma, ready=est.ready, mu_per_foot=mu_feet)

    def _update_events(self, t_s: float, feet: FootState) -> None:
        """Open an event at each slip onset (cap = floor); collect ratios while it slips; when it ends (or has
        ``ratio_ticks`` ratios) set its cap from the ratios."""
        for i in range(4):
            ev = self._open[i]
            if feet.slipping[i]:
                if ev is None:
                    ev = SlipEvent(feet.feet_w[i, :2].copy(), t_s, self.floor_mu, i)
                    self.events.append(ev)
                    self._open[i] = ev
                    self.slips_detected += 1
                else:
                    ev.t_s, ev.cap = t_s, min(ev.cap, self.floor_mu) if len(ev.ratios) < self.ratio_ticks else ev.cap
                if math.isfinite(feet.ratio[i]):
                    ev.ratios.append(float(feet.ratio[i]))
                if len(ev.ratios) == self.ratio_ticks:
                    self._settle(ev)
            elif ev is not None:
                if len(ev.ratios) < self.ratio_ticks:
                    self._settle(ev)
                self._open[i] = None
        keep = [e for e in self.events if e.cap + self.rise_per_s * (t_s - e.t_s) < MAX_FRICTION]
        self.events = keep[-64:]  # old events have relaxed past any friction

    def _settle(self, ev: SlipEvent) -> None:
        """The cap of an event from its slipping force ratios (never above the floor it had if none)."""
        if ev.ratios and self.ratio_scale > 0:
            ev.cap = max(self.floor_mu, self.ratio_scale * float(np.median(ev.ratios)))

    def _caps(self, t_s: float, feet: FootState) -> np.ndarray:
        """(4,) [-] each foot's cap now: its own events, and (``propagate``) the other feet's events it has
        reached and not left behind (from ``behind_m`` behind to ``ahead_m`` ahead of their place along the
        direction of travel)."""
        caps = np.full(4, np.inf)
        for ev in self.events:
            c = ev.cap + self.rise_per_s * max(0.0, t_s - ev.t_s)
            ahead = (feet.feet_w[:, :2] - ev.xy_w) @ feet.heading_w  # [m] along the direction of travel
            hit = (ahead >= -self.behind_m) & (ahead <= self.ahead_m) if self.propagate else np.zeros(4, bool)
            hit[ev.foot] = True  # the foot that slipped: until the cap has relaxed, wherever it walks
            caps[hit] = np.minimum(caps[hit], c)
        return caps

    # ---------------------------------------------------------------------------------------- extras
    def input_files(self) -> list[Path]:
        """The base estimator's files (checkpoints), part of the run's identity."""
        f = getattr(self.base, "input_files", None)
        return list(f()) if f is not None else []

    def diagnostics(self) -> dict[str, float]:
        """The base's counters plus ``foot_slips``: slip onsets detected this episode (feet x events)."""
        d = getattr(self.base, "diagnostics", None)
        return {**(d() if d is not None else {}), "foot_slips": self.slips_detected}
