"""Per-foot friction from a base estimator and the slips proprioception sees (``estimator=slip_*``).

:class:`SlipBoundEstimator` wraps any estimator (a learned model, ``fixed``) and reports, per foot,

    mu_i = min(base_i, cap_i(t))

with ``base_i`` the base estimator's value for foot i (its ``mu_per_foot``, or its ``mu`` for all four) and
``cap_i`` what the slips of that foot -- and of the feet ahead of it on the path -- prove:

* **Slip** (:class:`estimators.slip.SlipDetector`: the foot's world velocity from leg kinematics, the
  trunk IMU and the holding feet's odometry): the moment foot i is confirmed slipping, a slip *event* is
  opened at the foot's (dead-reckoned) place with cap ``floor_mu`` (a slipping foot's ground holds less than
  the filter planned; nothing finer is known yet). When the slip ends (or after ``ratio_ticks`` slipping
  ticks) the cap becomes ``max(floor_mu, ratio_scale x the median torque-implied force ratio of the slipping
  ticks)``: while a foot slides its force ratio *is* the friction, measured through a quasi-static leg
  (it reads high; ``ratio_scale`` = 0 keeps the floor).
* **Gate** (``gate_margin``, for filters whose landings slide on any low floor, the paper's): a slip opens an
  event only if what it proves (``ratio_scale`` x its force ratio at onset) lies ``gate_margin`` below the
  foot's estimate -- a foot sliding at the friction the filter already assumes proves nothing new. Its
  onset cap is then that evidence, not the floor.
* **Who it caps**: the foot that slipped, until it is ``own_ahead_m`` past the place (None: wherever it
  walks); with ``propagate``, every other foot between ``behind_m`` behind and ``ahead_m`` ahead of the
  place along the direction of travel: surfaces are patches the robot walks into, so a hind foot stepping
  where a front foot slipped is capped before it loads, the other front foot too.
* **Relaxation**: each foot's cap from an event rises at ``rise_per_s`` [1/s] from the later of the slip
  and the foot's arrival at the place (a hind foot that arrives a second later starts from the event's
  cap, not from what it has relaxed to), up to the event's ceiling (``ceiling_scale`` x the median force ratio
  of its slip: what the slip proves). A foot that slips again opens a new event.

The reported ``mu`` is the lowest foot's; ``ready`` and ``sigma`` are the base's. Events are kept in arrays
(at most ``MAX_EVENTS``, the newest). Frames and units as in :mod:`estimators.slip`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from estimators import slip_kernel
from estimators.slip import FootState, SlipDetector, SlipSettings
from estimators.stance_proof import ProofSettings, StanceProof
from taslel_bench.interfaces import MAX_FRICTION, Estimator, FrictionEstimate, Proprioception, integer, number

MAX_EVENTS = 64  # slip events remembered (the newest)


class SlipBoundEstimator:
    """Per-foot caps from slips on top of a base estimator (module doc)."""

    reads_imu = True  # the slip detector's trunk velocity comes from the IMU (Proprioception.imu every tick)

    def __init__(self, base: Estimator, floor_mu: float = 0.1, rise_per_s: float = 0.1, ratio_scale: float = 0.8,
                 ratio_ticks: int = 20, behind_m: float = 0.05, ahead_m: float = 0.3,
                 own_ahead_m: float | None = None, propagate: bool = True, gate_margin: float | None = None,
                 ceiling_scale: float | None = None,
                 detector: dict[str, Any] | None = None, proof: dict[str, Any] | None = None,
                 name: str | None = None) -> None:
        """``base``: the estimator whose per-foot values are capped; ``floor_mu`` [-]: cap at a slip's
        onset (the lowest friction the deployment may meet); ``rise_per_s`` [1/s]: relaxation of a cap;
        ``ratio_scale`` [-]: factor on the median slipping force ratio (0: caps stay at the floor until they
        relax); ``ratio_ticks``: slipping ticks after which the ratio cap is applied even if the slip goes on;
        ``behind_m`` / ``ahead_m`` [m]: a slip caps the other feet from this far behind its place to this far
        ahead of it along the path (``propagate``); ``own_ahead_m`` [m]: the foot that slipped, up to this far
        past it (None: everywhere); ``gate_margin`` [-]: a slip opens an event only if its evidence cap (with
        ``ratio_scale`` > 0: ``ratio_scale`` x the force ratio of its first slipping tick) lies more than this
        below the foot's current estimate (None: every slip does); ``detector``:
        :class:`estimators.slip.SlipSettings` fields; ``proof``: :class:`estimators.stance_proof.ProofSettings`
        fields (None: off), each foot's base raised to what holding feet proved where it stands plus a step."""
        self.base = base
        self.floor_mu = number("estimator.floor_mu", floor_mu, 0.0, MAX_FRICTION, lo_open=True)
        self.rise_per_s = number("estimator.rise_per_s", rise_per_s, 0.0, 100.0, unit="1/s")
        self.ratio_scale = number("estimator.ratio_scale", ratio_scale, 0.0, 1.0)
        self.ratio_ticks = integer("estimator.ratio_ticks", ratio_ticks, 1)
        self.behind_m = number("estimator.behind_m", behind_m, 0.0, 5.0, unit="m")
        self.ahead_m = number("estimator.ahead_m", ahead_m, 0.0, 100.0, lo_open=True, unit="m")
        self.own_ahead_m = np.inf if own_ahead_m is None else number("estimator.own_ahead_m", own_ahead_m, 0.0, 100.0,
                                                                     lo_open=True, unit="m")
        self.propagate = bool(propagate)
        self.gate_margin = None if gate_margin is None else number("estimator.gate_margin", gate_margin, 0.0, 1.0)
        self.ceiling_scale = None if ceiling_scale is None else number("estimator.ceiling_scale", ceiling_scale,
                                                                       0.0, 5.0, lo_open=True)
        self.detector = SlipDetector(SlipSettings(**dict(detector or {})))
        self.proof = None if proof is None else StanceProof(ProofSettings(**dict(proof)))
        self.name = name if name is not None else f"slip_{getattr(base, 'name', 'base')}"
        self.reset()

    def reset(self) -> None:
        self.base.reset()
        self.detector.reset()
        if self.proof is not None:
            self.proof.reset()
        self._xy = np.zeros((0, 2))  # [m] event places (world)
        self._t = np.zeros(0)  # [s] time the event's cap was set
        self._cap = np.zeros(0)  # [-] the event's cap
        self._ceil = np.zeros(0)  # [-] the highest its cap relaxes to (inf: no ceiling)
        self._foot = np.zeros(0, int)  # the foot that slipped
        self._arrived = np.zeros((0, 4))  # [s] first time each foot was in the event's reach (inf: not yet)
        self._open = np.full(4, -1)  # row of each foot's ongoing slip event (-1: none)
        self._ratios: list[list[float]] = [[], [], [], []]  # force ratios of each foot's ongoing slip
        self.slips_detected = 0  # slip onsets (feet x events) this episode
        self.slips_ignored = 0  # slip onsets the gate let pass (their evidence was not below the estimate)
        self._last_mu = np.full(4, np.inf)  # [-] each foot's last reported estimate
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
        if self.proof is not None:
            self.proof.update(obs.t_s, feet)
            proven = self.proof.proven(np.ascontiguousarray(feet.feet_w[:, :2]))
            base = np.maximum(base, np.minimum(proven + self.proof.s.step, MAX_FRICTION))
        mu_feet = np.minimum(base, caps)
        self._last_mu = mu_feet
        return FrictionEstimate(mu=float(mu_feet.min()), sigma=est.sigma, ready=est.ready, mu_per_foot=mu_feet)

    def _update_events(self, t_s: float, feet: FootState) -> None:
        """Open an event at each slip onset (cap = floor); collect ratios while it slips; when it ends (or has
        ``ratio_ticks`` ratios) set its cap from the ratios."""
        for i in np.flatnonzero(feet.slipping | (self._open >= 0)):
            row = self._open[i]
            if not feet.slipping[i]:  # the slip ended
                if len(self._ratios[i]) < self.ratio_ticks:
                    self._settle(i)
                self._open[i] = -1
                continue
            if row < 0:
                if self._gated(i, feet.ratio[i]):
                    self.slips_ignored += 1
                    continue
                self._add(i, feet.feet_w[i, :2], t_s, self._onset_cap(feet.ratio[i]))
                if np.isfinite(feet.ratio[i]):
                    self._ratios[i].append(float(feet.ratio[i]))
                self.slips_detected += 1
                continue
            self._t[row] = t_s  # still slipping: its cap holds from now
            if np.isfinite(feet.ratio[i]) and len(self._ratios[i]) < self.ratio_ticks:
                self._ratios[i].append(float(feet.ratio[i]))
                if len(self._ratios[i]) == self.ratio_ticks:
                    self._settle(i)

    def _onset_cap(self, ratio: float) -> float:
        """[-] cap of a slip at its onset: the floor, or with ``gate_margin`` and ``ratio_scale`` > 0 the
        evidence of its first tick (``ratio_scale`` x its force ratio, at least the floor)."""
        if self.gate_margin is None or not self.ratio_scale > 0 or not np.isfinite(ratio):
            return self.floor_mu
        return max(self.floor_mu, self.ratio_scale * float(ratio))

    def _gated(self, foot: int, ratio: float) -> bool:
        """True if the slip's evidence (:meth:`_onset_cap`) does not lie ``gate_margin`` below the foot's
        estimate: it proves nothing the filter did not already plan with."""
        return self.gate_margin is not None and self._onset_cap(ratio) >= self._last_mu[foot] - self.gate_margin

    def _add(self, foot: int, xy_w: np.ndarray, t_s: float, cap: float | None = None) -> None:
        """A new event of ``foot`` at ``xy_w`` [m] with ``cap`` (None: the floor); the oldest is dropped
        beyond MAX_EVENTS."""
        arrived = np.full(4, np.inf)
        arrived[foot] = t_s
        if self.proof is not None:
            self.proof.forget_near(xy_w)
        dropped = max(0, len(self._t) + 1 - MAX_EVENTS)  # rows that fall off the front
        self._open = np.where(self._open >= dropped, self._open - dropped, -1)
        self._xy = np.vstack([self._xy, xy_w])[-MAX_EVENTS:]
        self._t = np.append(self._t, t_s)[-MAX_EVENTS:]
        self._cap = np.append(self._cap, self.floor_mu if cap is None else cap)[-MAX_EVENTS:]
        self._ceil = np.append(self._ceil, np.inf)[-MAX_EVENTS:]
        self._foot = np.append(self._foot, foot)[-MAX_EVENTS:]
        self._arrived = np.vstack([self._arrived, arrived])[-MAX_EVENTS:]
        self._open[foot] = len(self._t) - 1
        self._ratios[foot] = []

    def _settle(self, foot: int) -> None:
        """The cap (``ratio_scale``) and ceiling (``ceiling_scale``) of ``foot``'s ongoing event from its
        slipping force ratios (the floor and no ceiling without any)."""
        row, ratios = self._open[foot], self._ratios[foot]
        if row < 0 or not ratios:
            return
        if self.ratio_scale > 0:
            self._cap[row] = max(self.floor_mu, self.ratio_scale * float(np.median(ratios)))
        if self.ceiling_scale is not None:
            self._ceil[row] = self.ceiling_scale * float(np.median(ratios))

    def _caps(self, t_s: float, feet: FootState) -> np.ndarray:
        """(4,) [-] each foot's cap now over the events that reach it (module doc), each relaxed from the later
        of its time and the foot's arrival."""
        if not len(self._t):
            return np.full(4, np.inf)
        return slip_kernel.caps(self._xy, self._t, self._cap, self._ceil, self._foot, self._arrived,
                                np.ascontiguousarray(feet.feet_w[:, :2]), feet.heading_w, float(t_s), self.behind_m,
                                self.ahead_m, float(self.own_ahead_m), self.rise_per_s, self.propagate)

    # ---------------------------------------------------------------------------------------- extras
    def input_files(self) -> list[Path]:
        """The base estimator's files (checkpoints), part of the run's identity."""
        f = getattr(self.base, "input_files", None)
        return list(f()) if f is not None else []

    def diagnostics(self) -> dict[str, float]:
        """The base's counters plus ``foot_slips`` (slip onsets that capped, feet x events) and
        ``foot_slips_ignored`` (onsets the gate let pass) this episode."""
        d = getattr(self.base, "diagnostics", None)
        out = {**(d() if d is not None else {}), "foot_slips": self.slips_detected,
               "foot_slips_ignored": self.slips_ignored}
        if self.proof is not None:
            out["stance_proofs"] = self.proof.proofs
        return out
