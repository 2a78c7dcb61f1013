"""A trained friction model in the control loop (``estimator=mlp|attention|linformer``).

Every control tick the runner calls :meth:`LearnedEstimator.step`. The estimator keeps a ring buffer of
``WINDOW_STEPS`` samples taken every ``WINDOW_DT_S`` seconds of episode time (the first tick at or after
each sample instant, as in :mod:`estimators.collect`). Until the buffer is full it returns ``prior_mu``
with ``ready=False``; afterwards, at each new sample it runs the model once (``torch.no_grad``, one CPU
thread by default) and holds the result between samples. The reported ``mu`` is the conservative bound
``max(mu_min, mean - conservative_k * sigma)``; ``sigma`` is the model's predicted standard deviation.
With ``bound="quantile"`` (models trained with a lower-quantile head, ``model.lower_quantile > 0``) it is
``max(mu_min, lower - conservative_k * sigma)`` instead. With ``hold_min_samples = n > 1`` the reported
``mu`` is the smallest bound of the last n model outputs: a drop in friction shows at once, a rise only
after n x 0.03 s (the window right after a drop still holds high-friction samples, and an over-estimate
lets the filter ask for more tangential force than the ground holds). A checkpoint trained with
``filter_mu_input`` also reads ``Proprioception.filter_mu`` (the friction the filter assumed on the tick
that produced ``tau_joints``; NaN without a filter) into every sample. A seed-ensemble checkpoint
(:class:`estimators.models.EnsembleModel`) runs all its members on each window; ``sigma`` is then the
ensemble's (members' variances plus their disagreement).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from estimators.checkpoint import CheckpointError, load_checkpoint
from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS, filter_channels, sample_vector
from estimators.models import VARIANTS
from taslel_bench.fields import ConfigError, integer, number
from taslel_bench.interfaces import MAX_FRICTION, FrictionEstimate, Proprioception

MAX_CONSERVATIVE_K = 10.0  # [sigmas] the shipped configs use 1-3


class LearnedEstimator:
    """Estimator protocol around a shipped (or given) checkpoint."""

    def __init__(
        self,
        variant: str = "linformer",
        checkpoint: str | Path | None = None,
        prior_mu: float = 0.5,
        conservative_k: float = 1.0,
        mu_min: float = 0.05,
        threads: int | None = 1,
        bound: str = "gaussian",
        hold_min_samples: int = 1,
    ) -> None:
        """``variant`` names the shipped checkpoint used when ``checkpoint`` is None; ``prior_mu`` [-] is
        returned until the window is full; ``conservative_k`` [-] sigmas are subtracted from the mean;
        ``mu_min`` [-] floors the result; ``threads`` sets ``torch.set_num_threads`` (None: leave it);
        ``hold_min_samples`` [samples of 0.03 s]: report the minimum bound of the last that many outputs."""
        if variant not in VARIANTS:
            raise ValueError(f"unknown variant {variant!r}; valid choices: {', '.join(VARIANTS)}")
        prior_mu = number("estimator.prior_mu", prior_mu, 0.0, MAX_FRICTION, lo_open=True)
        conservative_k = number("estimator.conservative_k", conservative_k, 0.0, MAX_CONSERVATIVE_K,
                                unit="sigmas")
        mu_min = number("estimator.mu_min", mu_min, 0.0, MAX_FRICTION)
        if bound not in ("gaussian", "quantile"):
            raise ValueError(f"unknown bound {bound!r}; valid choices: gaussian, quantile")
        integer("estimator.hold_min_samples", hold_min_samples, 1)
        if threads is not None:
            torch.set_num_threads(integer("estimator.threads", threads, 1))
        try:
            self.model, self.meta = load_checkpoint(checkpoint if checkpoint is not None else variant)
        except (CheckpointError, FileNotFoundError) as exc:  # the message names the file
            raise ConfigError(f"estimator.checkpoint={checkpoint!r} (variant {variant!r}): {exc}") from exc
        if self.meta["model"]["variant"] != variant:
            raise ValueError(
                f"checkpoint {checkpoint!r} holds a {self.meta['model']['variant']!r} model, not {variant!r}"
            )
        if bound == "quantile" and not float(self.meta["model"].get("lower_quantile", 0.0)) > 0:
            raise ValueError(f"bound='quantile' needs a checkpoint with a lower-quantile head ({checkpoint or variant})")
        self.bound = bound
        self.name = Path(checkpoint).stem if checkpoint is not None else variant
        self.prior_mu, self.k, self.mu_min = float(prior_mu), float(conservative_k), float(mu_min)
        self._hold = np.full(int(hold_min_samples), np.inf)  # ring of the last bounds [-]
        self.filter_mu_input = self.model.cfg.filter_mu_input
        n_raw = self.model.cfg.n_raw  # 36, or 38 with the filter features
        self._buf = np.zeros((WINDOW_STEPS, n_raw), np.float32)
        self._x = torch.zeros(1, WINDOW_STEPS, n_raw)
        self.reset()

    def reset(self) -> None:
        """Empty the window; the next estimates are the prior."""
        self._count = 0  # samples taken this episode
        self._n_out = 0  # model outputs this episode
        self._hold[:] = np.inf
        self._next_t = 0.0  # [s] next sample instant
        self._last = FrictionEstimate(mu=self.prior_mu, sigma=0.0, ready=False)
        self.mean, self.sigma, self.lower = float("nan"), float("nan"), float("nan")  # last raw model output

    def step(self, obs: Proprioception) -> FrictionEstimate:
        if obs.t_s + 1e-9 < self._next_t:
            return self._last
        row = self._buf[self._count % WINDOW_STEPS]
        row[:N_FEATURES] = sample_vector(obs.q_joints, obs.qd_joints, obs.tau_joints)
        if self.filter_mu_input:  # what the filter assumed on the tick that produced tau_joints
            row[N_FEATURES:] = filter_channels(obs.filter_mu)
        self._count += 1
        self._next_t += WINDOW_DT_S
        while self._next_t <= obs.t_s + 1e-9:  # ticks coarser than the sample period: skip instants
            self._next_t += WINDOW_DT_S
        if self._count >= WINDOW_STEPS:
            self._last = self._estimate()
        return self._last

    def _estimate(self) -> FrictionEstimate:
        start = self._count % WINDOW_STEPS  # oldest sample in the ring
        self._x[0] = torch.from_numpy(np.roll(self._buf, -start, axis=0))
        with torch.no_grad():
            mean, log_var, lower = self.model.predict(self._x)
        self.mean = float(mean[0])
        self.sigma = float(torch.exp(0.5 * log_var[0]))
        if lower is not None:
            self.lower = float(lower[0])
        base = self.lower if self.bound == "quantile" else self.mean
        self._hold[self._n_out % len(self._hold)] = max(self.mu_min, base - self.k * self.sigma)
        self._n_out += 1
        mu = float(self._hold.min())
        return FrictionEstimate(mu=mu, sigma=self.sigma, ready=True)
