"""The trunk IMU the estimators read (:class:`taslel_bench.interfaces.ImuSample`), from the plant's free joint.

Ideal sensor at the trunk origin: attitude, gyro (trunk axes) and an accelerometer whose reading is the mean
specific force over the last control tick, ``R' ((v_w(t) - v_w(t - dt)) / dt - g_w)`` [m/s²] (world-axes
trunk velocity v_w [m/s], gravity g_w [m/s²]). No noise or bias: a study adds its own.
"""

from __future__ import annotations

import numpy as np

from taslel_bench.interfaces import ImuSample
from taslel_bench.plant.bridge import quat_wxyz_to_matrix


class TrunkImu:
    """Per-episode state of the accelerometer (the trunk velocity of the previous tick)."""

    def __init__(self, gravity_w: np.ndarray, dt_s: float) -> None:
        self.gravity_w = np.asarray(gravity_w, float).copy()  # [m/s²] world axes
        self.dt_s = float(dt_s)  # [s] control tick
        self._v_prev_w = np.zeros(3)

    def reset(self, v_trunk_w: np.ndarray) -> None:
        """Start of an episode: the trunk velocity [m/s] (world axes) of the initial state."""
        self._v_prev_w = np.array(v_trunk_w, float)

    def read(self, q_pin: np.ndarray, v_pin: np.ndarray, v_trunk_w: np.ndarray) -> ImuSample:
        """The sample of this tick from the Pinocchio configuration / velocity (``q_pin[3:7]`` quaternion xyzw,
        ``v_pin[3:6]`` angular velocity in trunk axes) and the plant's world-axes trunk velocity [m/s]. The
        arrays are new each tick (an estimator may keep them)."""
        quat = np.array([q_pin[6], q_pin[3], q_pin[4], q_pin[5]])
        rot_world_from_trunk = quat_wxyz_to_matrix(quat)
        acc_w = (v_trunk_w - self._v_prev_w) / self.dt_s - self.gravity_w
        self._v_prev_w = np.array(v_trunk_w, float)
        return ImuSample(quat, np.array(v_pin[3:6], float), rot_world_from_trunk.T @ acc_w)
