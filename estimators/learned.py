"""A trained friction model in the control loop (``estimator=mlp|attention|linformer``).

Every control tick the runner calls :meth:`LearnedEstimator.step`. The estimator keeps a ring buffer of
``WINDOW_STEPS`` samples taken every ``WINDOW_DT_S`` seconds of episode time (the first tick at or after
each sample instant, as in :mod:`estimators.collect`). At each new sample, once the window is full, it runs
the model (``torch.no_grad``, one CPU thread by default) and holds the result between samples.

The reported ``mu`` (what the safety filter uses) is

    max(mu_min, base - conservative_k * sigma - margin(mean))

with ``base`` the model's mean (``bound="gaussian"``) or its lower-quantile head (``bound="quantile"``,
models trained with ``model.lower_quantile > 0``), ``sigma`` its predicted standard deviation and
``margin`` the band-aware margin (:class:`estimators.safety.BandMargin`, ``band_margin``: an extra margin
that depends on the band of the raw mean, chosen on a shifted validation set). With
``hold_min_samples = n > 1`` it is the smallest such bound of the last n outputs.

**Startup**: until the window is full (1.17 s) the estimator returns ``prior_mu`` with ``ready=False``; the
default prior is the safe floor :data:`estimators.simple.SAFE_FLOOR_MU` (the lowest friction the deployment
must handle), so the startup window never claims more friction than such a floor holds.

**Friction drops** (``drop_detector``, :class:`DropDetector`): a detector beside the main model — a jump
of the main model's own raw mean (``checkpoint: null``), or a second model on the last few samples only
(``checkpoint``: a short-window model, e.g. 12 samples = 0.36 s). When it fires, the main window (which still
holds the old surface) is discarded: the estimator returns ``prior_mu`` (``ready=False``) until the window
has refilled with samples taken after the detection, as at startup.

**Inference off the control tick.** ``inference="staged"`` (a deadline-aware schedule, deterministic):
the tick that takes a sample only copies the window; the models then run one slice per control tick
(:meth:`estimators.models.FrictionModel.predict_stages`: the embedding, each attention and feed-forward
half-block, each MLP layer), and the result is applied on the tick at ``sample time + apply_delay_s``
(slices still left then run in that tick, counted in ``deadline_misses``). ``inference="thread"``: the models
run in a worker thread and the result is applied at the same due tick, which waits for the worker if it is
late (``deadline_misses``, ``wait_s``); in this single-process harness the worker competes with the
control loop for Python's GIL. ``inference="inline"``: the models run inside the tick that takes the sample
and the result applies at once (the earlier behaviour).

A checkpoint trained with ``filter_mu_input`` also reads ``Proprioception.filter_mu`` into every sample. A
seed-ensemble checkpoint (:class:`estimators.models.EnsembleModel`) runs all its members on each window.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Generator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import torch

from estimators.checkpoint import CheckpointError, checkpoint_paths, load_checkpoint
from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS, filter_channels, sample_vector
from estimators.models import VARIANTS, run_stages
from estimators.safety import BandMargin
from estimators.simple import SAFE_FLOOR_MU
from taslel_bench.interfaces import (
    MAX_FRICTION,
    ConfigError,
    FrictionEstimate,
    Proprioception,
    integer,
    number,
)

MAX_CONSERVATIVE_K = 10.0  # [sigmas] the shipped configs use 0.5-3

INFERENCE_MODES = ("inline", "staged", "thread")


class DropDetector:
    """Friction-drop detector, one of two kinds:

    * ``checkpoint`` given: a short-window model (its ``window_steps`` shorter than the main window) on the last
      samples; it fires when its upper bound ``mean_s + k sigma_s`` lies more than ``delta`` [-] below the mu
      about to be reported;
    * ``checkpoint=None`` (a jump detector, no model of its own): it fires when the main model's raw mean falls
      more than ``delta`` [-] below the largest of its last ``lookback`` outputs (a surface change shows as a
      sudden fall once the window holds the new contacts' signature).

    Either must fire on ``confirm`` consecutive samples."""

    def __init__(self, checkpoint: str | Path | None = None, k: float = 2.0, delta: float = 0.1, confirm: int = 1,
                 lookback: int = 3) -> None:
        if k < 0 or not math.isfinite(k):
            raise ValueError(f"drop_detector.k must be finite and >= 0, got {k!r}")
        if delta < 0 or not math.isfinite(delta):
            raise ValueError(f"drop_detector.delta must be finite and >= 0, got {delta!r}")
        if int(confirm) != confirm or confirm < 1:
            raise ValueError(f"drop_detector.confirm must be an integer >= 1, got {confirm!r}")
        if int(lookback) != lookback or lookback < 1:
            raise ValueError(f"drop_detector.lookback must be an integer >= 1, got {lookback!r}")
        self.k, self.delta, self.confirm, self.lookback = float(k), float(delta), int(confirm), int(lookback)
        self.model = None
        self.files: tuple[Path, ...] = ()
        if checkpoint is None:
            return
        self.model, self.meta = load_checkpoint(checkpoint)
        self.files = checkpoint_paths(checkpoint)
        self.steps = int(self.model.cfg.window_steps)
        if not 1 <= self.steps < WINDOW_STEPS:
            raise ValueError(f"drop_detector checkpoint {checkpoint!r} has a {self.steps}-sample window; it must be "
                             f"shorter than the main window ({WINDOW_STEPS})")
        if self.model.cfg.filter_mu_input:
            raise ValueError("drop_detector: models with filter_mu_input are not supported")

    def upper(self, window: np.ndarray) -> tuple[float, float, float]:
        """(mean, sigma, mean + k sigma) [-] of the short model on the last ``steps`` samples of ``window``."""
        x = torch.from_numpy(np.ascontiguousarray(window[-self.steps :, :N_FEATURES])).unsqueeze(0)
        with torch.no_grad():
            mean, log_var, _ = self.model.predict(x)
        m, s = float(mean[0]), float(torch.exp(0.5 * log_var[0]))
        return m, s, m + self.k * s

    def upper_stages(self, window: np.ndarray) -> Generator[None, None, tuple[float, float, float]]:
        """:meth:`upper` as a generator over the model's slices (``inference="staged"``)."""
        x = torch.from_numpy(np.ascontiguousarray(window[-self.steps :, :N_FEATURES])).unsqueeze(0)
        with torch.no_grad():
            mean, log_var, _ = yield from self.model.predict_stages(x)
        m, s = float(mean[0]), float(torch.exp(0.5 * log_var[0]))
        return m, s, m + self.k * s


def _outputs(mean: torch.Tensor, log_var: torch.Tensor, lower: torch.Tensor | None) -> tuple[Any, Any, Any]:
    """(mean, sigma, lower) [-] of a batch of one: floats, or (4,) arrays for a per-foot model (nan: no
    lower-quantile head)."""
    def out(t: torch.Tensor) -> Any:
        v = t[0].numpy().astype(float)
        return float(v) if v.ndim == 0 else v

    lo = out(lower) if lower is not None else math.nan
    return out(mean), out(torch.exp(0.5 * log_var)), lo


def _scalar_min(v: Any) -> float:
    return float(np.min(v))


class SlipFloor:
    """A foot slip seen in proprioception lets that foot's estimate go below the floor ``mu_min``.

    On every sample, from leg kinematics (:func:`estimators.models.slip_features`): foot i *slips* when it
    is a stance foot (height above the lowest foot < ``height_m`` [m], trunk axes) and its horizontal
    speed relative to its trot partner exceeds ``speed_mps`` [m/s] (two holding stance feet move together
    up to the trunk's rotation). For ``hold_s`` [s] after that the foot's estimate is at most the prior and
    at least ``floor_mu`` [-] (down to 0.1: the worlds the benchmark runs)."""

    def __init__(self, floor_mu: float = 0.1, speed_mps: float = 0.15, height_m: float = 0.02,
                 hold_s: float = 0.3) -> None:
        self.floor_mu = number("estimator.slip.floor_mu", floor_mu, 0.0, MAX_FRICTION, lo_open=True)
        self.speed_mps = number("estimator.slip.speed_mps", speed_mps, 0.0, 10.0, lo_open=True, unit="m/s")
        self.height_m = number("estimator.slip.height_m", height_m, 0.0, 0.2, lo_open=True, unit="m")
        self.hold_s = number("estimator.slip.hold_s", hold_s, 0.0, 5.0, unit="s")

    def detect(self, sample: np.ndarray) -> np.ndarray:
        """(4,) bool: the feet slipping in one 36-feature sample (q, qdot, tau; core order)."""
        from estimators.models import slip_features

        with torch.no_grad():
            f = slip_features(torch.from_numpy(np.asarray(sample, np.float32)).reshape(1, 1, -1))[0, 0].numpy()
        return (f[4:] < self.height_m) & (f[:4] > self.speed_mps)


class LearnedEstimator:
    """Estimator protocol around a shipped (or given) checkpoint."""

    def __init__(
        self,
        variant: str = "linformer",
        checkpoint: str | Path | None = None,
        prior_mu: float = SAFE_FLOOR_MU,
        conservative_k: float = 1.0,
        mu_min: float = 0.05,
        threads: int | None = 1,
        bound: str = "gaussian",
        hold_min_samples: int = 1,
        band_margin: dict[str, Any] | None = None,
        drop_detector: dict[str, Any] | None = None,
        inference: str = "inline",
        apply_delay_s: float = 0.02,
        slip: dict[str, Any] | None = None,
    ) -> None:
        """``variant`` names the shipped checkpoint used when ``checkpoint`` is None; ``prior_mu`` [-] is
        returned until the window is full (and after a detected drop); ``conservative_k`` [-] sigmas are
        subtracted from the base; ``mu_min`` [-] floors the result; ``threads`` sets
        ``torch.set_num_threads`` (None: leave it); ``hold_min_samples`` [samples of 0.03 s]: report the
        minimum bound of the last that many outputs; ``band_margin``: ``{"edges": [...], "margins": [...]}``
        (:class:`estimators.safety.BandMargin`; None: no margin); ``drop_detector``: ``{"checkpoint": ... or None,
        "k": ..., "delta": ..., "confirm": ..., "lookback": ...}`` (:class:`DropDetector`; None: none); ``inference``:
        ``"inline"``, ``"staged"`` or ``"thread"``; ``apply_delay_s`` [s]: with ``"staged"`` / ``"thread"``, the
        latency after which a sample's result is applied; ``slip``: ``{"floor_mu": ..., "speed_mps": ...,
        "height_m": ..., "hold_s": ...}`` (:class:`SlipFloor`; None: no slip floor)."""
        prior_mu, conservative_k, mu_min = self._checked_settings(
            variant, prior_mu, conservative_k, mu_min, bound, hold_min_samples, inference, apply_delay_s)
        if threads is not None:
            torch.set_num_threads(integer("estimator.threads", threads, 1))
        self.model, self.meta = self._load_model(variant, checkpoint, bound)
        self._files = checkpoint_paths(checkpoint if checkpoint is not None else variant)
        self.bound = bound
        self.name = Path(checkpoint).stem if checkpoint is not None else variant
        self.prior_mu, self.k, self.mu_min = float(prior_mu), float(conservative_k), float(mu_min)
        self.band_margin = BandMargin(**{k: tuple(v) for k, v in dict(band_margin).items()}) if band_margin else None
        self.detector = DropDetector(**dict(drop_detector)) if drop_detector else None
        self.inference, self.apply_delay_s = inference, float(apply_delay_s)
        self.slip = SlipFloor(**dict(slip)) if slip else None
        self.per_foot = bool(getattr(self.model.cfg, "per_foot", False))
        self._init_buffers(int(hold_min_samples))
        self.reset()

    @staticmethod
    def _checked_settings(variant: str, prior_mu: float, conservative_k: float, mu_min: float, bound: str,
                          hold_min_samples: int, inference: str,
                          apply_delay_s: float) -> tuple[float, float, float]:
        """Check the constructor's settings (ValueError / ConfigError naming the bad one); returns the checked
        ``(prior_mu [-], conservative_k [sigmas], mu_min [-])``."""
        if variant not in VARIANTS:
            raise ValueError(f"unknown variant {variant!r}; valid choices: {', '.join(VARIANTS)}")
        prior_mu = number("estimator.prior_mu", prior_mu, 0.0, MAX_FRICTION, lo_open=True)
        conservative_k = number("estimator.conservative_k", conservative_k, 0.0, MAX_CONSERVATIVE_K,
                                unit="sigmas")
        mu_min = number("estimator.mu_min", mu_min, 0.0, MAX_FRICTION)
        if bound not in ("gaussian", "quantile"):
            raise ValueError(f"unknown bound {bound!r}; valid choices: gaussian, quantile")
        integer("estimator.hold_min_samples", hold_min_samples, 1)
        if inference not in INFERENCE_MODES:
            raise ValueError(f"unknown inference {inference!r}; valid choices: {', '.join(INFERENCE_MODES)}")
        if not (0.0 <= apply_delay_s < WINDOW_DT_S):
            raise ValueError(f"apply_delay_s must be in [0, {WINDOW_DT_S}) s, got {apply_delay_s!r}")
        return prior_mu, conservative_k, mu_min

    @staticmethod
    def _load_model(variant: str, checkpoint: str | Path | None, bound: str) -> tuple[Any, dict[str, Any]]:
        """(model, metadata) of ``checkpoint`` (the shipped ``variant`` if None); ConfigError if it cannot be
        read, ValueError if it holds another variant or lacks the lower-quantile head ``bound="quantile"``
        needs."""
        try:
            model, meta = load_checkpoint(checkpoint if checkpoint is not None else variant)
        except (CheckpointError, FileNotFoundError) as exc:  # the message names the file
            raise ConfigError(f"estimator.checkpoint={checkpoint!r} (variant {variant!r}): {exc}") from exc
        if meta["model"]["variant"] != variant:
            raise ValueError(
                f"checkpoint {checkpoint!r} holds a {meta['model']['variant']!r} model, not {variant!r}"
            )
        if bound == "quantile" and not float(meta["model"].get("lower_quantile", 0.0)) > 0:
            raise ValueError(f"bound='quantile' needs a checkpoint with a lower-quantile head "
                             f"({checkpoint or variant})")
        return model, meta

    def _init_buffers(self, hold_min_samples: int) -> None:
        """The hold ring of the last ``hold_min_samples`` bounds [-], the sample window (WINDOW_STEPS x the
        model's raw features), and the (lazily started) worker thread with its lock."""
        n_est = 4 if self.per_foot else 1
        self._hold = np.full((hold_min_samples, n_est), np.inf)  # ring of the last bounds [-] (per foot)
        self.filter_mu_input = self.model.cfg.filter_mu_input
        n_raw = self.model.cfg.n_raw  # 36, or 38 with the filter features
        self._buf = np.zeros((WINDOW_STEPS, n_raw), np.float32)
        self._pool: ThreadPoolExecutor | None = None
        self._lock = threading.Lock()  # one model call at a time (torch modules are not re-entrant)

    # ------------------------------------------------------------------------------------------ state
    def reset(self) -> None:
        """Empty the window; the next estimates are the prior."""
        if getattr(self, "_job", None) is not None:  # a result still in flight belongs to the old episode
            self._job[0].result()
        self._count = 0  # samples taken this episode
        self._fill = 0  # samples taken since the last (re)start: the model runs once it reaches WINDOW_STEPS
        self._n_out = 0  # model outputs since the last (re)start
        self._hold[:] = np.inf
        self._bound = np.full(self._hold.shape[1], np.inf)  # [-] held bound per foot before the mu_min floor
        self._alarm = 0  # consecutive samples the drop detector fired
        self._recent: list[float] = []  # jump detector: the last raw means since the (re)start
        self._next_t = 0.0  # [s] next sample instant
        self._job: tuple[Future, float, int] | None = None  # (result, due time [s], fill at submission)
        self._stages: tuple[Generator, float, int] | None = None  # staged: (slices, due time [s], fill)
        self._stage_result: tuple[float, ...] | None = None
        self._last = FrictionEstimate(mu=self.prior_mu, sigma=0.0, ready=False)
        self.mean, self.sigma, self.lower = float("nan"), float("nan"), float("nan")  # last raw model output
        self.mean_per_foot = np.full(1, np.nan)  # [-] last raw mean per foot (one entry: a single-output model)
        self.short_mean, self.short_sigma = float("nan"), float("nan")  # last drop-detector output
        self.drops_detected = 0
        self.slips_detected = 0  # samples on which a foot's slip was detected (SlipFloor)
        self._slip_until = np.full(4, -np.inf)  # [s] per foot: the slip floor applies until then
        self._t = 0.0  # [s] episode time of the last tick
        self.deadline_misses = 0  # thread: results not ready at their due tick (that tick waited)
        self.wait_s = 0.0  # [s] wall time ticks waited for the worker

    def close(self) -> None:
        """Stop the worker thread (if any); the estimator restarts it when needed."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __del__(self) -> None:  # pragma: no cover - interpreter shutdown order varies
        with contextlib.suppress(Exception):  # never raise from a finaliser
            self.close()

    # ------------------------------------------------------------------------------------------ loop
    def step(self, obs: Proprioception) -> FrictionEstimate:
        if self._job is not None:
            self._poll(obs.t_s)
        if self._stages is not None:
            self._advance_staged(obs.t_s)
        if obs.t_s + 1e-9 < self._next_t:
            return self._last
        row = self._buf[self._count % WINDOW_STEPS]
        row[:N_FEATURES] = sample_vector(obs.q_joints, obs.qd_joints, obs.tau_joints)
        if self.slip is not None:
            slipped = self.slip.detect(row[:N_FEATURES])
            self.slips_detected += int(slipped.any())
            self._slip_until[slipped] = obs.t_s + self.slip.hold_s
            self._t = obs.t_s
            self._last = self._with_slip(self._last)
        if self.filter_mu_input:  # what the filter assumed on the tick that produced tau_joints
            row[N_FEATURES:] = filter_channels(obs.filter_mu)
        self._count += 1
        self._fill += 1
        self._next_t += WINDOW_DT_S
        while self._next_t <= obs.t_s + 1e-9:  # ticks coarser than the sample period: skip instants
            self._next_t += WINDOW_DT_S
        if self._fill >= WINDOW_STEPS:
            if self.inference == "inline":
                self._last = self._apply(self._compute(self._window()), self._fill)
            elif self.inference == "staged":
                if self._stages is not None:  # apply_delay_s >= the sample period: finish the previous one
                    self._finish_staged()
                self._stages = (self._compute_stages(self._window()), obs.t_s + self.apply_delay_s, self._fill)
                self._stage_result = None
            else:
                if self._job is not None:  # apply_delay_s < the sample period: only if ticks are that coarse
                    self._poll(math.inf)
                if self._pool is None:
                    self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="friction-estimator")
                fut = self._pool.submit(self._compute, self._window())
                self._job = (fut, obs.t_s + self.apply_delay_s, self._fill)
                if self.apply_delay_s == 0.0:
                    self._poll(obs.t_s)
        return self._last

    def _poll(self, t_s: float) -> None:
        """Thread mode: apply the pending result once it is due (waits for the worker only if it is late)."""
        fut, due, fill = self._job  # type: ignore[misc]
        if t_s + 1e-9 < due:
            return
        if not fut.done():
            self.deadline_misses += 1
            t0 = time.perf_counter()
            fut.result()
            self.wait_s += time.perf_counter() - t0
        self._job = None
        self._last = self._apply(fut.result(), fill)

    def _advance_staged(self, t_s: float) -> None:
        """Staged mode: one slice of the models per tick; apply the result at its due tick."""
        gen, due, _ = self._stages  # type: ignore[misc]
        if self._stage_result is None:
            try:
                next(gen)
            except StopIteration as stop:
                self._stage_result = stop.value
        if t_s + 1e-9 >= due:
            self._finish_staged()

    def _finish_staged(self) -> None:
        gen, _, fill = self._stages  # type: ignore[misc]
        if self._stage_result is None:
            self.deadline_misses += 1
            self._stage_result = run_stages(gen)
        self._stages = None
        self._last = self._apply(self._stage_result, fill)

    def _window(self) -> np.ndarray:
        """The last WINDOW_STEPS samples, oldest first (a copy)."""
        return np.roll(self._buf, -(self._count % WINDOW_STEPS), axis=0)

    def _compute(self, window: np.ndarray) -> tuple[float, float, float, float, float, float]:
        """Model outputs for one window: (mean, sigma, lower, short mean, short sigma, short upper) [-]
        (nan where absent). Runs in the worker thread with ``inference="thread"``."""
        with self._lock, torch.no_grad():
            mean, log_var, lower = self.model.predict(torch.from_numpy(window).unsqueeze(0))
            short = self.detector.upper(window) if self.detector is not None and self.detector.model is not None \
                else (math.nan,) * 3
        return (*_outputs(mean, log_var, lower), *short)

    def _compute_stages(self, window: np.ndarray) -> Generator[None, None, tuple[float, ...]]:
        """:meth:`_compute` as a generator yielding between slices of the models (``inference="staged"``)."""
        x = torch.from_numpy(window).unsqueeze(0)
        with torch.no_grad():
            mean, log_var, lower = yield from self.model.predict_stages(x)
        short = (math.nan,) * 3
        if self.detector is not None and self.detector.model is not None:
            yield
            short = yield from self.detector.upper_stages(window)
        return (*_outputs(mean, log_var, lower), *short)

    def _estimate(self) -> FrictionEstimate:
        """Run the models on the current window and apply the result (inline; tests drive this directly)."""
        self._fill = max(self._fill, WINDOW_STEPS)
        self._last = self._apply(self._compute(self._window()), self._fill)
        return self._last

    def _apply(self, raw: tuple[Any, ...], fill: int) -> FrictionEstimate:
        """Bound, band margin, hold and the drop detector on one model output (runs on the control thread).
        A per-foot model's outputs are (4,) arrays: each foot is bounded on its own, the reported ``mu`` is
        the lowest foot's and ``mu_per_foot`` the four; the drop detector watches the lowest foot's mean."""
        mean, sigma, lower, self.short_mean, self.short_sigma, short_upper = raw
        self.mean, self.sigma = _scalar_min(mean), _scalar_min(sigma)
        self.mean_per_foot = np.asarray(mean, float).reshape(-1)
        if not np.all(np.isnan(lower)):
            self.lower = lower
        if fill < WINDOW_STEPS or self._fill < WINDOW_STEPS:  # a reset since: the window is not refilled yet
            return self._with_slip(FrictionEstimate(mu=self.prior_mu, sigma=0.0, ready=False))
        base = np.asarray(self.lower if self.bound == "quantile" else mean, float).reshape(-1)
        b = base - self.k * np.asarray(sigma, float).reshape(-1)
        if self.band_margin is not None:
            b = b - np.asarray(self.band_margin.margin(self.mean_per_foot), float)
        self._hold[self._n_out % len(self._hold)] = b  # unclipped: a slipping foot may go below mu_min
        self._n_out += 1
        self._bound = self._hold.min(axis=0)
        mu_feet = np.maximum(self.mu_min, self._bound)
        mu = float(mu_feet.min())
        if (det := self.detector) is not None:
            if det.model is not None:
                fired = short_upper < mu - det.delta
            else:  # jump: the raw mean fell below the largest of its last `lookback` outputs
                fired = bool(self._recent) and self.mean < max(self._recent) - det.delta
                self._recent = (self._recent + [self.mean])[-det.lookback :]
            self._alarm = self._alarm + 1 if fired else 0
            if self._alarm >= det.confirm:  # friction dropped: discard the window, back to the prior
                self.drops_detected += 1
                self._alarm, self._fill, self._n_out, self._recent = 0, 0, 0, []
                self._hold[:] = np.inf
                self._bound[:] = np.inf
                return self._with_slip(FrictionEstimate(mu=self.prior_mu, sigma=0.0, ready=False))
        per_foot = mu_feet.astype(float) if self.per_foot else None
        return self._with_slip(FrictionEstimate(mu=mu, sigma=self.sigma, ready=True, mu_per_foot=per_foot))

    def _with_slip(self, est: FrictionEstimate) -> FrictionEstimate:
        """``est`` with the slip floor applied: a foot whose slip was detected within ``slip.hold_s`` gets
        max(slip.floor_mu, min(the model's bound for it before the ``mu_min`` floor, prior_mu)) -- at most the
        safe prior, possibly below ``mu_min``; ``mu`` becomes the lowest foot's. Unchanged without a slip
        floor or a recent slip."""
        if self.slip is None:
            return est
        slipping = self._slip_until >= self._t
        if not slipping.any():
            return est
        feet = np.full(4, est.mu) if est.mu_per_foot is None else np.array(est.mu_per_foot, float)
        bound = np.broadcast_to(self._bound if est.ready else np.inf, 4)
        feet[slipping] = np.maximum(self.slip.floor_mu, np.minimum(bound[slipping], self.prior_mu))
        return FrictionEstimate(mu=float(feet.min()), sigma=est.sigma, ready=est.ready, mu_per_foot=feet)

    def input_files(self) -> list[Path]:
        """The checkpoint files this estimator loaded (model and drop detector: weights and metadata), part of
        the run's identity."""
        return [*self._files, *(self.detector.files if self.detector is not None else ())]

    def diagnostics(self) -> dict[str, float]:
        """Counters of this episode: drops detected, samples, and with ``inference="thread"`` the deadline
        misses and the wall time [s] ticks waited for the worker."""
        return {"drops_detected": self.drops_detected, "slips_detected": self.slips_detected, "samples": self._count,
                "deadline_misses": self.deadline_misses, "wait_s": self.wait_s}
