"""Window layout shared by collection, training and the in-loop estimator (numpy only).

A *window* is ``WINDOW_STEPS`` proprioceptive samples taken every ``WINDOW_DT_S`` seconds (1.2 s of
history). Each sample has ``N_FEATURES = 36`` features in the core joint order (legs FL, FR, RL, RR,
``[hip, thigh, calf]`` each): ``[q (12) [rad], qdot (12) [rad/s], tau (12) [N·m]]``. ``tau`` is the
joint torque commanded on the previous control tick (after clipping; the episode runner's
``Proprioception.tau_joints``) — what a real A1 reports from its motor currents — not the torque a
perturbed (weaker / stronger) motor actually delivers.
"""

from __future__ import annotations

import numpy as np

WINDOW_STEPS = 40  # samples per window
WINDOW_DT_S = 0.03  # [s] sample spacing
N_JOINTS = 12
N_CHANNELS = 3  # q, qdot, tau per joint
N_FEATURES = N_JOINTS * N_CHANNELS  # 36


def sample_vector(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """One (36,) sample from joint positions [rad], velocities [rad/s], torques [N·m] (core order)."""
    return np.concatenate([q, qd, tau]).astype(np.float32)


def to_joint_tokens(windows: np.ndarray) -> np.ndarray:
    """(N, T, 36) -> (N, T * 12, 3): one token per joint per time step, time-major, features (q, qd, tau)."""
    n, t, f = windows.shape
    if f != N_FEATURES:
        raise ValueError(f"windows have {f} features per step; expected {N_FEATURES}")
    return windows.reshape(n, t, N_CHANNELS, N_JOINTS).transpose(0, 1, 3, 2).reshape(n, t * N_JOINTS, N_CHANNELS)
