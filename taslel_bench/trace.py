"""Per-tick record of an episode in preallocated arrays, turned into a typed table at the end.

Every plant quantity is read from MuJoCo after the tick's physics steps: the state (trunk pose and
velocity, joints) is the one after the tick; foot positions, contact forces and contact-point velocities
are those MuJoCo computed in the tick's last physics step (its starting state, 1 physics step earlier).
Frames in the column names: ``_w`` = world axes, joint vectors in core order.

In the control loop :meth:`EpisodeTrace.record` only copies raw rows (``qpos``, ``qvel``, ``sensordata``,
the controller's and filter's vectors); :meth:`EpisodeTrace.finalize` derives the named quantities for all
ticks at once after the episode (vectorised: the same definitions, a fraction of the per-tick cost).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from taslel_bench import robot
from taslel_bench.bridge import StateBridge

TICK_PARTS = ("controller", "model", "filter", "physics")
QP_STATUS_CODES = {"off": -1, "solved": 0}  # any other status string -> 1 (failure), text kept in events


class EpisodeTrace:
    """Arrays of length ``capacity``; ``n`` ticks are valid (derived arrays after :meth:`finalize`)."""

    def __init__(self, capacity: int, filter_on: bool, nq: int = robot.NQ, nv: int = robot.NV,
                 nsensordata: int = 0) -> None:  # fmt: skip
        c, nl = capacity, robot.N_LEGS
        self.n = 0
        self.filter_on = filter_on
        self.finalized = False
        # --- raw rows written in the loop
        self.t_s = np.zeros(c)
        self.qpos_mj = np.zeros((c, nq))  # MuJoCo qpos / qvel / sensordata after the tick
        self.qvel_mj = np.zeros((c, nv))
        self.sensordata_mj = np.zeros((c, nsensordata))
        self.u_nom = np.zeros((c, 12))  # [N·m]
        self.u = np.zeros((c, 12))  # [N·m] applied
        self.gait_phase = np.zeros(c)
        self.in_stance = np.zeros((c, nl), bool)  # stance set used by the filter
        self.swing_phase = np.zeros((c, nl))
        self.grf_filter_w = np.full((c, nl, 3), np.nan)  # [N] filter's lambda
        self._grf_filter_flat = self.grf_filter_w.reshape(c, 3 * nl)
        self.qp_status = np.full(c, -1, np.int8)
        self.qp_fallback = np.zeros(c, bool)
        self.qp_build_us = np.full(c, np.nan)
        self.qp_solve_us = np.full(c, np.nan)
        self.qp_iterations = np.full(c, -1, np.int32)
        self.barrier_h_m = np.full((c, nl), np.nan)  # ECBF h per foot (nan in stance / no ECBF)
        self.barrier_he_mps = np.full((c, nl), np.nan)
        self.mu_hat = np.zeros(c)
        self.mu_true = np.zeros(c)
        self.mu_hat_ready = np.ones(c, bool)  # the estimator's FrictionEstimate.ready (False: its prior)
        self.tick_us = np.zeros(c)
        # wall time of the tick's parts [s until finalize(), then µs]: state read + estimator + controller,
        # controller model (bridge + Pinocchio), filter (QP build + solve + fallback), physics (+ contact check)
        self.tick_parts_us = np.zeros((c, len(TICK_PARTS)))
        self.events: list[dict[str, object]] = []  # QP failures, falls, errors (t_s, kind, message)
        # --- derived by finalize() (empty until then)
        self.base_pos_w = np.zeros((0, 3))  # [m] trunk origin
        self.base_quat_wxyz = np.zeros((0, 4))
        self.base_linvel_w = np.zeros((0, 3))  # [m/s]
        self.q = np.zeros((0, 12))  # [rad]
        self.qd = np.zeros((0, 12))  # [rad/s]
        self.foot_pos_w = np.zeros((0, nl, 3))  # [m] foot-sphere centres
        self.grf_plant_w = np.zeros((0, nl, 3))  # [N] contact force on each foot
        self.in_contact = np.zeros((0, nl), bool)
        self.slip_w = np.zeros((0, nl, 2))  # [m/s] horizontal velocity of each foot's contact point
        self.clearance_m = np.zeros((0, nl))  # swing foot bottom - z(s) [m] (nan in stance)

    def record(self, k, t, qpos, qvel, sensordata, gs, in_stance, u_nom, u, fres, mu_hat, mu_true, tick_s,
               ecbf) -> None:  # fmt: skip
        """Copy tick ``k``'s raw rows (MuJoCo qpos, qvel, sensordata after the tick; controller and filter
        outputs)."""
        self.t_s[k] = t
        self.qpos_mj[k] = qpos
        self.qvel_mj[k] = qvel
        self.sensordata_mj[k] = sensordata
        self.u_nom[k] = u_nom
        self.u[k] = u
        self.gait_phase[k] = gs.phi
        self.in_stance[k] = in_stance
        self.swing_phase[k] = gs.swing_phase
        self.mu_hat[k] = mu_hat
        self.mu_true[k] = mu_true
        self.tick_us[k] = tick_s * 1e6
        if fres is not None:
            self._grf_filter_flat[k] = fres.lam
            if fres.used_fallback:
                self.qp_status[k] = 1
                self.qp_fallback[k] = True
                self.events.append({"t_s": t, "kind": "qp_failure", "message": fres.status})
            else:
                self.qp_status[k] = 0
            self.qp_build_us[k] = fres.build_time_s * 1e6
            sol = fres.solve
            if sol is not None:
                self.qp_solve_us[k] = sol.solve_time_s * 1e6
                if sol.iterations is not None:
                    self.qp_iterations[k] = sol.iterations
            if ecbf is not None:
                self.barrier_h_m[k] = ecbf.h
                self.barrier_he_mps[k] = ecbf.h_e
        self.n = k + 1

    def finalize(self, br: StateBridge, contacts, profile) -> None:
        """Derive the named plant quantities of the ``n`` recorded ticks (idempotent).

        ``contacts``: the episode's :class:`taslel_bench.plant.FootContactReader` (sensor layout);
        ``profile``: the scenario's clearance profile or None (then ``clearance_m`` is all nan)."""
        if self.finalized:
            return
        n, a, dv = self.n, br.free_qadr, br.free_dadr
        self.tick_parts_us[:n] *= 1e6
        qpos, qvel = self.qpos_mj[:n], self.qvel_mj[:n]
        self.base_pos_w = qpos[:, a : a + 3].copy()
        self.base_quat_wxyz = qpos[:, a + 3 : a + 7].copy()
        self.base_linvel_w = qvel[:, dv : dv + 3].copy()
        self.q = qpos[:, br.joint_qadr]
        self.qd = qvel[:, br.joint_dadr]
        plant_side = contacts.from_sensor_log(self.sensordata_mj[:n])
        self.foot_pos_w = plant_side["foot_pos_in_world"]
        self.grf_plant_w = plant_side["forces_in_world"]
        self.in_contact = plant_side["in_contact"]
        self.slip_w = plant_side["slip_velocity_in_world"]
        self.clearance_m = np.full((n, robot.N_LEGS), np.nan)
        if profile is not None and n:
            swing = ~self.in_stance[:n]
            z_obstacle = profile.evaluate(self.swing_phase[:n][swing])[0]
            self.clearance_m[swing] = self.foot_pos_w[..., 2][swing] - robot.FOOT_RADIUS_M - z_obstacle
        self.finalized = True

    # ------------------------------------------------------------------------------------------ derived
    def base_rpy(self) -> np.ndarray:
        """(n, 3) roll, pitch, yaw [rad] of the trunk (ZYX convention)."""
        w, x, y, z = self.base_quat_wxyz[: self.n].T
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        return np.stack([roll, pitch, yaw], axis=1)

    def to_frame(self, dt: float) -> pd.DataFrame:
        """One row per control tick, typed columns, units in the names."""
        n = self.n
        cols: dict[str, np.ndarray] = {"t_s": self.t_s[:n]}
        for j, ax in enumerate("xyz"):
            cols[f"base_{ax}_w_m"] = self.base_pos_w[:n, j]
        for j, ax in enumerate("xyz"):
            cols[f"base_v{ax}_w_mps"] = self.base_linvel_w[:n, j]
        for j, name in enumerate(("roll", "pitch", "yaw")):
            cols[f"base_{name}_rad"] = self.base_rpy()[:, j]
        for j, jn in enumerate(robot.JOINT_NAMES):
            short = jn.removesuffix("_joint")
            cols[f"q_{short}_rad"] = self.q[:n, j]
            cols[f"qd_{short}_radps"] = self.qd[:n, j]
            cols[f"u_nom_{short}_nm"] = self.u_nom[:n, j]
            cols[f"u_{short}_nm"] = self.u[:n, j]
        cols["gait_phase"] = self.gait_phase[:n]
        slip = np.hypot(self.slip_w[:n, :, 0], self.slip_w[:n, :, 1])
        for i, leg in enumerate(robot.LEGS):
            cols[f"{leg}_stance"] = self.in_stance[:n, i]
            cols[f"{leg}_contact"] = self.in_contact[:n, i]
            cols[f"{leg}_swing_phase"] = self.swing_phase[:n, i]
            for j, ax in enumerate("xyz"):
                cols[f"{leg}_foot_{ax}_w_m"] = self.foot_pos_w[:n, i, j]
            cols[f"{leg}_contact_point_speed_mps"] = slip[:, i]
            for j, ax in enumerate("xyz"):
                cols[f"{leg}_grf_plant_{ax}_w_n"] = self.grf_plant_w[:n, i, j]
                cols[f"{leg}_grf_filter_{ax}_w_n"] = self.grf_filter_w[:n, i, j]
            cols[f"{leg}_barrier_h_m"] = self.barrier_h_m[:n, i]
            cols[f"{leg}_barrier_he_mps"] = self.barrier_he_mps[:n, i]
            cols[f"{leg}_clearance_m"] = self.clearance_m[:n, i]
        cols["qp_status"] = self.qp_status[:n]
        cols["qp_fallback"] = self.qp_fallback[:n]
        cols["qp_build_us"] = self.qp_build_us[:n]
        cols["qp_solve_us"] = self.qp_solve_us[:n]
        cols["qp_iterations"] = self.qp_iterations[:n]
        cols["mu_hat"] = self.mu_hat[:n]
        cols["mu_true"] = self.mu_true[:n]
        cols["mu_hat_ready"] = self.mu_hat_ready[:n]
        cols["tick_us"] = self.tick_us[:n]
        for j, part in enumerate(TICK_PARTS):
            cols[f"tick_{part}_us"] = self.tick_parts_us[:n, j]
        return pd.DataFrame(cols)

