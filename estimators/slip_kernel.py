"""One control tick of the slip detector (:class:`estimators.slip.SlipDetector`) in a compiled kernel.

The detector's rules (module doc of :mod:`estimators.slip`) and the torque-implied forces of
:func:`estimators.legs.foot_forces_from_torques` (tested against it), for the four legs in one call: the numpy
version cost ~270 µs per tick, which would double a filtered tick. The leg kinematics come in computed by
:func:`taslel_bench.robot.leg_chain.feet_and_jacobians_into` (the robot package's chain, compiled there: a kernel
cached here would not see edits to that file). Frames: ``_b`` trunk axes, ``_w`` world axes; units m, m/s, N, s.
All state arrays are updated in place.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# indices of the float settings vector given to tick()
P_CONTACT, P_TOUCHDOWN, P_SPEED, P_AVERAGE, P_CONFIRM, P_FAST_TOUCHDOWN, P_FAST_SPEED, P_FAST_CONFIRM, P_TAU, \
    P_SLOW = range(10)
N_PARAMS = 10
GRAVITY_Z = -9.81  # [m/s²] world z


@njit(cache=True)
def _rotation(quat: np.ndarray, rot: np.ndarray) -> None:
    """World <- trunk rotation of a quaternion (w, x, y, z), normalised, into ``rot`` (3, 3)."""
    n = np.sqrt(quat[0] ** 2 + quat[1] ** 2 + quat[2] ** 2 + quat[3] ** 2)
    w, x, y, z = quat[0] / n, quat[1] / n, quat[2] / n, quat[3] / n
    rot[0, 0], rot[0, 1], rot[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    rot[1, 0], rot[1, 1], rot[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    rot[2, 0], rot[2, 1], rot[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@njit(cache=True)
def _solve_transposed(jac: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = -J'^-1 b (Cramer's rule; a singular leg gives zeros: no force read)."""
    a = jac.T
    det = (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]) - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
           + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))
    if abs(det) < 1e-12:
        out[:] = 0.0
        return
    for c in range(3):
        m = a.copy()
        m[:, c] = b
        out[c] = -(m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
                   + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])) / det


@njit(cache=True)
def _matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """a (3, 3) @ x (3,) without BLAS."""
    out = np.empty(3)
    for r in range(3):
        out[r] = a[r, 0] * x[0] + a[r, 1] * x[1] + a[r, 2] * x[2]
    return out


@njit(cache=True)
def tick(p_b, jac, qd, tau, quat, gyro_b, accel_b, t_s, dt, prm, started, v_w, p_w, heading, loaded_since,
         judged_n, speeds, above, above_fast, loaded, slipping, speed, ratio, feet_w) -> bool:
    """One tick: reads the feet ``p_b`` (4, 3) [m] and the leg Jacobians ``jac`` (4, 3, 3) [m/rad] (trunk axes,
    at this tick's joint angles), qd [rad/s] and tau [N·m] (12,), the IMU (quat wxyz, gyro [rad/s], accel [m/s²]),
    t_s, dt [s] and the settings ``prm`` (P_* indices); updates the observer state (``v_w``, ``p_w``,
    ``heading``) and the per-foot state (``loaded_since`` [s], ``judged_n``, ``speeds`` ring, ``above``,
    ``above_fast``); writes the outputs ``loaded``, ``slipping``, ``speed`` [m/s], ``ratio``, ``feet_w`` [m].
    Returns whether the trunk velocity is known (``started``)."""
    rot = np.empty((3, 3))
    _rotation(quat, rot)
    if started:  # accelerometer: v += dt (R a + g)
        for k in range(3):
            v_w[k] += dt * (rot[k, 0] * accel_b[0] + rot[k, 1] * accel_b[1] + rot[k, 2] * accel_b[2])
        v_w[2] += dt * GRAVITY_Z
        for k in range(3):
            p_w[k] += dt * v_w[k]
    f_b = np.empty(3)
    vrel_w = np.empty((4, 3))
    n_avg = int(prm[P_AVERAGE])
    judged = np.zeros(4, np.bool_)
    fast = np.zeros(4, np.bool_)
    for i in range(4):
        p = p_b[i]
        vr = np.empty(3)  # omega x p + J qd, trunk axes
        vr[0] = gyro_b[1] * p[2] - gyro_b[2] * p[1]
        vr[1] = gyro_b[2] * p[0] - gyro_b[0] * p[2]
        vr[2] = gyro_b[0] * p[1] - gyro_b[1] * p[0]
        for r in range(3):
            vr[r] += jac[i, r, 0] * qd[3 * i] + jac[i, r, 1] * qd[3 * i + 1] + jac[i, r, 2] * qd[3 * i + 2]
        _solve_transposed(jac[i], tau[3 * i : 3 * i + 3], f_b)
        f_w = _matvec(rot, f_b)
        vrel_w[i] = _matvec(rot, vr)
        loaded[i] = f_w[2] > prm[P_CONTACT]
        ratio[i] = np.hypot(f_w[0], f_w[1]) / max(f_w[2], 1e-9) if loaded[i] else np.nan
        speed[i] = np.hypot(v_w[0] + vrel_w[i, 0], v_w[1] + vrel_w[i, 1]) if started else 0.0
        if loaded[i]:
            loaded_since[i] = min(loaded_since[i], t_s)
        else:
            loaded_since[i] = np.inf
        judged[i] = loaded[i] and t_s - loaded_since[i] >= prm[P_TOUCHDOWN] - 1e-9
        judged_n[i] = judged_n[i] + 1 if judged[i] else 0
        if judged[i]:
            speeds[(judged_n[i] - 1) % n_avg, i] = speed[i]
        fast[i] = prm[P_SLOW] > 0 and judged_n[i] >= n_avg and speeds[:, i].mean() > prm[P_SPEED]
        above[i] = above[i] + 1 if fast[i] else 0
        quick = loaded[i] and t_s - loaded_since[i] >= prm[P_FAST_TOUCHDOWN] - 1e-9 and speed[i] > prm[P_FAST_SPEED]
        above_fast[i] = above_fast[i] + 1 if quick else 0
        slipping[i] = above[i] >= prm[P_CONFIRM] or above_fast[i] >= prm[P_FAST_CONFIRM]
    # odometry from the feet that hold: judged (past the landing), no slip, not 4x the slip speed this tick
    hold = np.zeros(4, np.bool_)
    for i in range(4):
        hold[i] = judged[i] and not fast[i] and speed[i] < 4 * prm[P_SPEED]
    nh = hold.sum()
    if nh > 0:
        odo = np.empty((nh, 3))
        j = 0
        for i in range(4):
            if hold[i]:
                odo[j] = -vrel_w[i]
                j += 1
        for k in range(3):
            med = np.median(odo[:, k])
            if started:
                v_w[k] += min(1.0, dt / prm[P_TAU]) * (med - v_w[k])
            else:
                v_w[k] = med
        started = True
    vxy = np.hypot(v_w[0], v_w[1])
    if vxy > 0.05:  # [m/s] below that the heading keeps its last value
        heading[0], heading[1] = v_w[0] / vxy, v_w[1] / vxy
    for i in range(4):
        feet_w[i] = p_w + _matvec(rot, p_b[i])
    return started


@njit(cache=True)
def caps(xy, t, cap, ceil, foot, arrived, feet_xy, heading, t_s, behind_m, ahead_m, own_ahead_m, rise_per_s,
         propagate) -> np.ndarray:
    """(4,) [-] each foot's cap over the slip events (rows of ``xy`` [m], ``t`` [s], ``cap`` [-], ``foot``):
    an event reaches its own foot up to ``own_ahead_m`` past its place and (``propagate``) the other feet
    from ``behind_m`` behind to ``ahead_m`` ahead of it along ``heading``; a foot's cap relaxes at
    ``rise_per_s`` [1/s] from the later of the event's time and the foot's first tick in reach, which is
    written into ``arrived`` (E, 4) [s] (inf: not yet), up to the event's ``ceil`` [-] (never below its
    cap). Feet no event reaches get inf."""
    out = np.full(4, np.inf)
    for e in range(len(t)):
        for j in range(4):
            ahead = (feet_xy[j, 0] - xy[e, 0]) * heading[0] + (feet_xy[j, 1] - xy[e, 1]) * heading[1]
            own = foot[e] == j  # the event's own foot reaches ahead only; the others both ways (propagate)
            reach = ahead <= own_ahead_m if own else propagate and -behind_m <= ahead <= ahead_m
            if not reach:
                continue
            if np.isinf(arrived[e, j]):
                arrived[e, j] = t_s
            c = min(cap[e] + rise_per_s * max(0.0, t_s - max(t[e], arrived[e, j])), max(ceil[e], cap[e]))
            out[j] = min(out[j], c)
    return out
