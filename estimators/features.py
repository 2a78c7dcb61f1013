"""Window layout shared by collection, training and the in-loop estimator (numpy only).

A *window* is ``WINDOW_STEPS`` proprioceptive samples taken every ``WINDOW_DT_S`` seconds (1.2 s of
history). Each sample has ``N_FEATURES = 36`` features in the core joint order (legs FL, FR, RL, RR,
``[hip, thigh, calf]`` each): ``[q (12) [rad], qdot (12) [rad/s], tau (12) [N·m]]``. ``tau`` is the
joint torque commanded on the previous control tick (after clipping; the episode runner's
``Proprioception.tau_joints``) — what a real A1 reports from its motor currents — not the torque a
perturbed (weaker / stronger) motor actually delivers.

Models trained with ``filter_mu_input`` see ``N_FILTER_FEATURES = 2`` more features per sample
(:func:`filter_channels`): whether the safety filter was in the loop on the tick that produced ``tau``
(0 / 1) and the friction coefficient it assumed [-] (0 without a filter). A clipped torque pattern means
"mu >= what the filter allowed" only if the model knows what the filter allowed.
"""

from __future__ import annotations

import numpy as np

WINDOW_STEPS = 40  # samples per window
WINDOW_DT_S = 0.03  # [s] sample spacing
N_JOINTS = 12
N_CHANNELS = 3  # q, qdot, tau per joint
N_FEATURES = N_JOINTS * N_CHANNELS  # 36
N_FILTER_FEATURES = 2  # [filter in the loop (0 / 1), filter's mu [-] (0 without a filter)]


def sample_vector(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """One (36,) sample from joint positions [rad], velocities [rad/s], torques [N·m] (core order)."""
    return np.concatenate([q, qd, tau]).astype(np.float32)


def filter_channels(filter_mu: np.ndarray | float) -> np.ndarray:
    """Filter features (..., 2) from the friction the safety filter assumed [-] (NaN: no filter in the loop)."""
    mu = np.asarray(filter_mu, np.float64)
    on = np.isfinite(mu)
    return np.stack([on, np.where(on, mu, 0.0)], axis=-1).astype(np.float32)


def with_filter_channels(windows: np.ndarray, filter_mu: np.ndarray) -> np.ndarray:
    """(N, T, 36) windows + the filter's mu per window (N,) or per sample (N, T) [-] (NaN: no filter) ->
    (N, T, 38)."""
    n, t, f = windows.shape
    if f != N_FEATURES:
        raise ValueError(f"windows have {f} features per step; expected {N_FEATURES}")
    mu = np.asarray(filter_mu, np.float64)
    if mu.shape == (n,):
        mu = np.repeat(mu[:, None], t, axis=1)
    if mu.shape != (n, t):
        raise ValueError(f"filter_mu must have shape ({n},) or ({n}, {t}), got {mu.shape}")
    return np.concatenate([windows, filter_channels(mu)], axis=-1)


def to_joint_tokens(windows: np.ndarray) -> np.ndarray:
    """(N, T, 36) -> (N, T * 12, 3): one token per joint per time step, time-major, features (q, qd, tau)."""
    n, t, f = windows.shape
    if f != N_FEATURES:
        raise ValueError(f"windows have {f} features per step; expected {N_FEATURES}")
    return windows.reshape(n, t, N_CHANNELS, N_JOINTS).transpose(0, 1, 3, 2).reshape(n, t * N_JOINTS, N_CHANNELS)
