"""Per-tick record of an episode in preallocated arrays, turned into a typed table at the end.

Every plant quantity is read from MuJoCo after the tick's physics steps: the state (trunk pose and
velocity, joints) is the one after the tick; foot positions, contact forces and contact-point velocities
are those MuJoCo computed in the tick's last physics step (its starting state, 1 physics step earlier).
Frames in the column names: ``_w`` = world axes, joint vectors in core order.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from taslel_bench import robot
from taslel_bench.bridge import StateBridge

QP_STATUS_CODES = {"off": -1, "solved": 0}  # any other status string -> 1 (failure), text kept in events


class EpisodeTrace:
    """Arrays of length ``capacity``; ``n`` ticks are valid."""

    def __init__(self, capacity: int, filter_on: bool) -> None:
        c, nl = capacity, robot.N_LEGS
        self.n = 0
        self.filter_on = filter_on
        self.t_s = np.zeros(c)
        self.base_pos_w = np.zeros((c, 3))  # [m] trunk origin
        self.base_quat_wxyz = np.zeros((c, 4))
        self.base_linvel_w = np.zeros((c, 3))  # [m/s]
        self.q = np.zeros((c, 12))  # [rad]
        self.qd = np.zeros((c, 12))  # [rad/s]
        self.u_nom = np.zeros((c, 12))  # [N·m]
        self.u = np.zeros((c, 12))  # [N·m] applied
        self.gait_phase = np.zeros(c)
        self.in_stance = np.zeros((c, nl), bool)  # stance set used by the filter
        self.swing_phase = np.zeros((c, nl))
        self.foot_pos_w = np.zeros((c, nl, 3))  # [m] foot-sphere centres
        self.grf_plant_w = np.zeros((c, nl, 3))  # [N] contact force on each foot
        self.in_contact = np.zeros((c, nl), bool)
        self.slip_w = np.zeros((c, nl, 2))  # [m/s] horizontal velocity of each foot's contact point
        self.grf_filter_w = np.full((c, nl, 3), np.nan)  # [N] filter's lambda
        self.qp_status = np.full(c, -1, np.int8)
        self.qp_fallback = np.zeros(c, bool)
        self.qp_build_us = np.full(c, np.nan)
        self.qp_solve_us = np.full(c, np.nan)
        self.qp_iterations = np.full(c, -1, np.int32)
        self.barrier_h_m = np.full((c, nl), np.nan)  # ECBF h per foot (nan in stance / no ECBF)
        self.barrier_he_mps = np.full((c, nl), np.nan)
        self.clearance_m = np.full((c, nl), np.nan)  # swing foot bottom - z(s) [m] (nan in stance)
        self.mu_hat = np.zeros(c)
        self.mu_true = np.zeros(c)
        self.tick_us = np.zeros(c)
        self.events: list[dict[str, object]] = []  # QP failures, falls, errors (t_s, kind, message)

    def record(self, k, t, d, br: StateBridge, trunk, foot_sites, gs, in_stance, u_nom, u, fres, contacts,
               mu_hat, mu_true, tick_s, profile, ecbf) -> None:
        self.t_s[k] = t
        a = br.free_qadr  # trunk pose from qpos: the state after the tick, like q and qd
        self.base_pos_w[k] = d.qpos[a : a + 3]
        self.base_quat_wxyz[k] = d.qpos[a + 3 : a + 7]
        self.base_linvel_w[k] = d.qvel[br.free_dadr : br.free_dadr + 3]
        self.q[k] = d.qpos[br.joint_qadr]
        self.qd[k] = d.qvel[br.joint_dadr]
        self.u_nom[k] = u_nom
        self.u[k] = u
        self.gait_phase[k] = gs.phi
        self.in_stance[k] = in_stance
        self.swing_phase[k] = gs.swing_phase
        self.foot_pos_w[k] = d.site_xpos[foot_sites]
        self.grf_plant_w[k] = contacts.forces_in_world
        self.in_contact[k] = contacts.in_contact
        self.slip_w[k] = contacts.slip_velocity_in_world
        self.mu_hat[k] = mu_hat
        self.mu_true[k] = mu_true
        self.tick_us[k] = tick_s * 1e6
        if profile is not None:
            for i in range(robot.N_LEGS):
                if not in_stance[i]:
                    z = profile(float(gs.swing_phase[i]))[0]
                    self.clearance_m[k, i] = d.site_xpos[foot_sites[i], 2] - robot.FOOT_RADIUS_M - z
        if fres is not None:
            self.grf_filter_w[k] = fres.lam.reshape(robot.N_LEGS, 3)
            self.qp_status[k] = 0 if not fres.used_fallback else 1
            self.qp_fallback[k] = fres.used_fallback
            self.qp_build_us[k] = fres.build_time_s * 1e6
            if fres.solve is not None:
                self.qp_solve_us[k] = fres.solve.solve_time_s * 1e6
                if fres.solve.iterations is not None:
                    self.qp_iterations[k] = fres.solve.iterations
            if fres.used_fallback:
                self.events.append({"t_s": t, "kind": "qp_failure", "message": fres.status})
            if ecbf is not None:
                self.barrier_h_m[k] = ecbf.h
                self.barrier_he_mps[k] = ecbf.h_e
        self.n = k + 1

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
        cols["tick_us"] = self.tick_us[:n]
        return pd.DataFrame(cols)

