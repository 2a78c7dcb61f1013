"""Per-tick record of an episode in preallocated arrays, turned into a typed table at the end.

Timing of the column groups within the row of tick k (control period dt, physics step dt_p):

* ``t_s`` = k dt: the tick's start; the controller and filter read the plant state at ``t_s``;
* commands (``u_nom_*``, ``u_*``), the filter's answer (``*_grf_filter_*``, ``qp_*``, ``*_barrier_*``), the
  gait schedule (``gait_phase``, ``*_scheduled_stance``, ``*_swing_phase``), the filter's stance set
  (``*_stance``: the schedule's, or the contact estimate's) and ``mu_hat``/``*_mu_hat_foot``/``mu_true``: computed at
  ``t_s`` from that state; ``u`` is held over [t_s, t_s + dt);
* the plant state (``base_*``, ``q_*``, ``qd_*``): the state at the end of the tick, t_s + dt (the state
  the next tick reads). ``base_*`` position and quaternion (wxyz), linear velocity in world axes, angular
  velocity in trunk axes, ``q``/``qd``: together a full MuJoCo (qpos, qvel), enough to restart the plant;
* contact and foot quantities (``*_contact``, ``*_grf_plant_*``, ``*_foot_*``, ``*_contact_point_speed``,
  ``*_obstacle_contact``, ``*_mu_foot``, ``*_clearance_m``, ``*_obstacle_clearance_m``): MuJoCo's sensors of
  the tick's last physics step, i.e. of its starting state at t_s + dt - dt_p (contact forces are the
  constraint forces applied during that step).

Frames in the column names: ``_w`` = world axes, ``_b`` = trunk axes; joint vectors in core order.

In the control loop :meth:`EpisodeTrace.record` only copies raw rows (``qpos``, ``qvel``, ``sensordata``,
the controller's and filter's vectors); :meth:`EpisodeTrace.finalize` derives the named quantities for all
ticks at once after the episode (vectorised: the same definitions, a fraction of the per-tick cost).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from taslel_bench.interfaces import FrictionEstimate
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.contact_frames import FLANK_COS, MAX_CONTACTS_PER_FOOT, ContactLog
from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.terrain import Terrain
from taslel_bench.util.jit import kernel

TICK_PARTS = ("controller", "model", "filter", "physics")
QP_STATUS_CODES = {"off": -1, "solved": 0}  # any other status string -> 1 (failure), text kept in events
MAX_QP_FAILURE_EVENTS = 1000  # QP failures listed as events (the rest counted: memory stays bounded)


class BarrierLog:
    """One barrier family's values per tick and leg (nan where its row was inactive): h [m], h_e [m/s], the
    ECBF condition psi = hdot_e + a2 h_e [m/s²] the filter planned, and the one realised (filled after the
    episode by :mod:`taslel_bench.metrics.residuals`)."""

    def __init__(self, name: str, capacity: int, rows: Sequence[str] = quad.LEGS) -> None:
        shape = (capacity, len(rows))
        self.name, self.rows = name, tuple(rows)
        self.per_leg = self.rows == quad.LEGS  # one row per leg: part of the per-leg readings
        self.h_m = np.full(shape, np.nan)
        self.he_mps = np.full(shape, np.nan)
        self.psi_planned_mps2 = np.full(shape, np.nan)
        self.psi_realized_mps2 = np.zeros((0, len(rows)))


class EpisodeTrace:
    """Arrays of length ``capacity``; ``n`` ticks are valid (derived arrays after :meth:`finalize`).
    ``barrier_names``: the filter's barrier families, in its order (one :class:`BarrierLog` each); ``barrier_rows``:
    the row names of those whose rows are not the legs (name -> rows)."""

    def __init__(self, capacity: int, filter_on: bool, nq: int = quad.NQ, nv: int = quad.NV,
                 nsensordata: int = 0, barrier_names: Sequence[str] = (),
                 barrier_rows: dict[str, tuple[str, ...]] | None = None) -> None:  # fmt: skip
        self._barrier_rows = dict(barrier_rows or {})
        c = capacity
        self.n = 0  # ticks recorded in the episode (global count)
        self.offset = 0  # global tick of row 0: the trace holds ticks offset .. n - 1 (see roll())
        self.capacity = capacity
        self.filter_on = filter_on
        self.finalized = False
        self._allocate_loop_rows(c, nq, nv, nsensordata, barrier_names)
        self._allocate_contact_frames(c)
        self._allocate_tick_timing(c)
        self._allocate_derived()
        block_fills = {id(block): init for block, init in self._blocks}  # a block's rows reset to their init row
        self._raw = [(a, block_fills.get(id(a), fill))
                     for a, fill in _raw_arrays([self, self.contact_log, *self.barriers.values()], c)]
        self._no_filter = (np.full(3 * quad.N_LEGS, np.nan), np.full(quad.NV, np.nan))  # (lambda, vdot) stand-ins
        self._mu_row = np.zeros(quad.N_LEGS)  # an estimate's one mu for every foot (record)

    def _allocate_loop_rows(self, c: int, nq: int, nv: int, nsensordata: int, barrier_names: Sequence[str]) -> None:
        """The raw rows the loop writes: plant state, torques, gait, the filter's outputs, leg contacts, the
        friction estimate and the tick's wall times. The float and the bool ones are column views of two
        blocks (``_FLOAT_ROW`` / ``_FLAG_ROW`` order: :meth:`record` copies one row of each in one compiled
        call, whose cost grows with the number of arrays it is handed)."""
        nl, nan = quad.N_LEGS, np.nan
        floats = _column_block(c, np.float64, (
            ((), 0.0),  # t_s [s]
            ((), 0.0),  # gait_phase
            ((), 0.0),  # mu_hat
            ((), 0.0),  # mu_true
            ((), 0.0),  # tick_us
            ((len(TICK_PARTS),), 0.0),  # tick_parts_s: wall time of the tick's parts [s] (see _allocate_tick_timing)
            ((), nan),  # qp_build_us
            ((), nan),  # qp_solve_us
            ((), 0.0),  # ecbf_margin_mps2
            ((nq,), 0.0),  # qpos_mj
            ((nv,), 0.0),  # qvel_mj
            ((nsensordata,), 0.0),  # sensordata_mj
            ((12,), 0.0),  # u_nom
            ((12,), 0.0),  # u
            ((nl,), 0.0),  # swing_phase
            ((nl,), nan),  # mu_hat_foot
            ((nl, 3), nan),  # grf_filter_w
            ((quad.NV,), nan),  # vdot_filter
        ))  # fmt: skip
        (self.t_s, self.gait_phase, self.mu_hat, self.mu_true, self.tick_us, self.tick_parts_s, self.qp_build_us,
         self.qp_solve_us, self.ecbf_margin_mps2, self.qpos_mj, self.qvel_mj, self.sensordata_mj, self.u_nom, self.u,
         self.swing_phase, self.mu_hat_foot, self.grf_filter_w, self.vdot_filter) = floats.views  # fmt: skip
        # t_s [s] = k dt; qpos/qvel/sensordata_mj: MuJoCo's after the tick; u_nom, u [N·m] (u applied);
        # grf_filter_w [N] the filter's lambda; vdot_filter the filter's predicted acceleration (Pinocchio);
        # ecbf_margin_mps2 [m/s²] the robust margin of the ECBF rows (filter.robust); mu_hat [-] the estimate's mu
        # (its lowest foot's), mu_hat_foot [-] its value for each foot (mu_per_foot, or mu for every foot)
        flags = _column_block(c, np.bool_, (
            ((nl,), False),  # in_stance: stance set used by the filter
            ((nl,), False),  # scheduled_stance: the gait schedule's stance (the filter's set may differ)
            ((), True),  # mu_hat_ready: the estimator's FrictionEstimate.ready (False: its prior)
            ((), False),  # nonfoot_obstacle_contact: a lower leg touched a physical obstacle (trip)
            ((), False),  # shin_floor_contact: a lower leg (not its foot) touched the floor
            ((), False),  # qp_fallback
        ))  # fmt: skip
        self.in_stance, self.scheduled_stance, self.mu_hat_ready, self.nonfoot_obstacle_contact, \
            self.shin_floor_contact, self.qp_fallback = flags.views  # fmt: skip
        self._floats, self._flags = floats.block, flags.block
        self._blocks = ((floats.block, floats.init), (flags.block, flags.init))
        self.qp_status = np.full(c, -1, np.int8)
        self.qp_iterations = np.full(c, -1, np.int32)
        # [N·m] max |u - u_ref| on reference-checked ticks (record.reference_every)
        self.qp_u_error_nm = np.full(c, np.nan)
        self.qp_solve_cpu_us = np.full(c, np.nan)  # [µs] thread CPU time of the solve (taslel_bench.sim.solve_clock)
        self.qp_setup = np.zeros(c, np.bool_)  # the backend's first build for this QP layout (sim.solve_clock)
        self.barriers = {name: BarrierLog(name, c, self._barrier_rows.get(name, quad.LEGS))  # the filter's families
                         for name in barrier_names}
        self.contact_log = ContactLog(c)  # raw contact rows of each tick's last physics step

    def _allocate_contact_frames(self, c: int) -> None:
        """Per-foot contact-frame arrays, filled from ``contact_log`` by finalize()."""
        nl = quad.N_LEGS
        # derived from contact_log by finalize() (taslel_bench.plant.contact_frames; zero until then): every
        # foot-terrain contact in MuJoCo's contact frame, per tick, leg and slot (K slots, zero / False unused):
        # f_n [N], |f_t| [N], the contact's mu [-], the normal out of the terrain (world axes), the contact
        # point's tangential speed [m/s], touching (distance <= 0), on an obstacle geom; per leg: a non-foot
        # link of the leg touching an obstacle, the same farther than FOOT_NEIGHBOURHOOD_M from its foot, a
        # non-foot link touching other terrain (the floor), and the foot's contacts beyond the K slots (dropped);
        # per tick, the contacts beyond the log's MAX_CONTACTS_LOGGED. K = 8: 1.9 kB per tick (10 s: 20 MB)
        k = MAX_CONTACTS_PER_FOOT
        self.contact_fn_n = np.zeros((c, nl, k))
        self.contact_ft_n = np.zeros((c, nl, k))
        self.contact_mu = np.zeros((c, nl, k))
        self.contact_normal_w = np.zeros((c, nl, k, 3))
        self.contact_slip_mps = np.zeros((c, nl, k))
        self.contact_touching = np.zeros((c, nl, k), bool)
        self.contact_on_obstacle = np.zeros((c, nl, k), bool)
        self.foot_contact_normal_w = np.zeros((c, nl, 3))  # [N] sum of f_n x normal over each foot's contacts
        self.leg_link_obstacle_contact = np.zeros((c, nl), bool)
        self.leg_link_obstacle_contact_off_foot = np.zeros((c, nl), bool)
        self.leg_link_floor_contact = np.zeros((c, nl), bool)
        self.foot_contacts = np.zeros((c, nl), np.int32)
        self.foot_contacts_dropped = np.zeros((c, nl), np.int32)
        self.contacts_not_logged = np.zeros(c, np.int32)

    def _allocate_tick_timing(self, c: int) -> None:
        """The event list (the friction estimate and the tick's wall times are loop rows: ``tick_parts_s`` [s] =
        state read + estimator + controller, controller model (bridge + Pinocchio), filter (QP build + solve +
        fallback), physics (+ fall and contact checks))."""
        self.events: list[dict[str, object]] = []  # QP failures, falls, errors (t_s, kind, message)
        self.qp_failures_not_listed = 0  # QP failures after the first MAX_QP_FAILURE_EVENTS (summary: qp_failed)
        self._context: tuple | None = None  # (bridge, contact reader, profile, terrain, frames): see bind()

    def _allocate_derived(self) -> None:
        """Empty arrays filled after the loop: model residuals and the quantities finalize() derives."""
        nl = quad.N_LEGS
        # --- the controller model's residuals, filled after the episode by taslel_bench.metrics.residuals.compute
        self.model_residual = np.zeros((0, quad.NV))  # [N, N·m] M vdot + h - S u - J'f (Pinocchio rows)
        self.foot_acc_error_w = np.zeros((0, nl, 3))  # [m/s²] predicted - realised foot acceleration
        # --- derived by finalize() (empty until then)
        self.tick_parts_us = np.zeros((0, len(TICK_PARTS)))  # [µs]
        self.base_pos_w = np.zeros((0, 3))  # [m] trunk origin
        self.base_quat_wxyz = np.zeros((0, 4))
        self.base_linvel_w = np.zeros((0, 3))  # [m/s]
        self.base_angvel_b = np.zeros((0, 3))  # [rad/s] trunk axes
        self.q = np.zeros((0, 12))  # [rad]
        self.qd = np.zeros((0, 12))  # [rad/s]
        self.foot_pos_w = np.zeros((0, nl, 3))  # [m] foot-sphere centres
        self.grf_plant_w = np.zeros((0, nl, 3))  # [N] contact force on each foot
        self.in_contact = np.zeros((0, nl), bool)
        self.slip_w = np.zeros((0, nl, 2))  # [m/s] horizontal velocity of each foot's contact point
        self.clearance_m = np.zeros((0, nl))  # swing foot bottom - z(s) [m] (nan in stance)
        self.obstacle_contact = np.zeros((0, nl), bool)  # foot sphere touches a physical obstacle
        self.obstacle_clearance_m = np.zeros((0, nl))  # [m] foot sphere to nearest obstacle (nan: none)
        self.mu_foot = np.zeros((0, nl))  # [-] true friction of the terrain under each foot

    def roll(self, m: int) -> None:
        """Drop the first ``m`` rows (a processed chunk): the rows after them move to the front, the rest
        are reset to their initial values, and ``offset`` advances by ``m``."""
        keep = self.n - self.offset - m
        for a, fill in self._raw:
            a[:keep] = a[m : m + keep]
            a[keep:] = fill
        self.offset += m
        self.finalized = False

    def record(self, k: int, t: float, plant: tuple[np.ndarray, np.ndarray, np.ndarray], gs, in_stance: np.ndarray,
               u_nom: np.ndarray, u: np.ndarray, fres, est: FrictionEstimate, mu_true: float,
               clock_s: tuple[float, float, float, float, float], barriers, nonfoot_obstacle_contact: bool,
               shin_floor_contact: bool) -> None:  # fmt: skip
        """Copy tick ``k``'s raw rows: ``plant`` = MuJoCo (qpos, qvel, sensordata) after the tick; the gait
        state ``gs``, the stance set, u_nom and u [N·m], the filter's result ``fres`` (None: no filter on this
        tick), the friction estimate (per foot too) and the truth under the trunk; ``clock_s`` = the
        perf_counter times [s] at the tick's start and at the end of each of its :data:`TICK_PARTS`; ``barriers``:
        the filter's barrier families (their h, h_e and planned condition now). One compiled call for the
        fixed-size rows."""
        r = k - self.offset
        qpos, qvel, sensordata = plant
        filtered = fres is not None
        if filtered:
            sol = fres.solve
            lam, vdot, build_us, margin = fres.lam, fres.vdot, fres.build_time_s * 1e6, fres.ecbf_margin_mps2
            solve_us = sol.solve_time_s * 1e6 if sol is not None else np.nan
            iterations = sol.iterations if sol is not None and sol.iterations is not None else -1
            fallback = fres.used_fallback
            self.qp_solve_cpu_us[r] = getattr(sol, "solve_cpu_time_s", np.nan) * 1e6 if sol is not None else np.nan
            self.qp_setup[r] = bool(getattr(sol, "setup", False))
        else:
            (lam, vdot), build_us, margin, solve_us, iterations, fallback = self._no_filter, np.nan, 0.0, np.nan, -1, \
                False  # fmt: skip
        mu_feet = est.mu_per_foot
        if mu_feet is None:  # one coefficient for every foot
            self._mu_row[:] = est.mu
            mu_feet = self._mu_row
        _copy_rows(r, t, gs.phi, est.mu, mu_true, *clock_s, build_us, solve_us, margin, est.ready,
                   nonfoot_obstacle_contact, shin_floor_contact, filtered, fallback, iterations, qpos, qvel, sensordata,
                   u_nom, u, gs.swing_phase, mu_feet, lam, vdot, in_stance, gs.in_stance, self._floats, self._flags,
                   self.qp_status, self.qp_iterations)  # fmt: skip
        if filtered:
            if fallback:
                if len(self.events) < MAX_QP_FAILURE_EVENTS:
                    self.events.append({"t_s": t, "kind": "qp_failure", "message": fres.status})
                else:
                    self.qp_failures_not_listed += 1
            for barrier in barriers:
                log = self.barriers[barrier.name]
                log.h_m[r] = barrier.h
                log.he_mps[r] = barrier.h_e
                log.psi_planned_mps2[r] = barrier.psi_planned if not fallback else np.nan
        self.n = k + 1

    def main_contact(self, ticks: slice = slice(None)) -> np.ndarray:
        """(n, 4) index of each foot's contact slot with the largest normal force."""
        return np.argmax(self.contact_fn_n[ticks], axis=2)

    def bind(self, br: StateBridge, contacts, profile, terrain: Terrain | None = None, frames=None) -> None:
        """What deriving the named quantities needs: the state bridge (index maps), the episode's
        :class:`taslel_bench.plant.contacts.FootContactReader` (sensor layout), the scenario's clearance
        profile or None (then ``clearance_m`` is all nan) and the terrain (friction under each foot,
        obstacles; None: the trunk's friction ``mu_true`` for every foot, no obstacles) and the
        :class:`taslel_bench.plant.contact_frames.ContactFrameReader` that filled ``contact_log`` (None: the
        contact-frame arrays stay as they are)."""
        self._context = (br, contacts, profile, terrain, frames)

    def contact_reader(self):
        """The episode's :class:`taslel_bench.plant.contacts.FootContactReader` (sensor layout of ``sensordata_mj``)."""
        if self._context is None:
            raise RuntimeError("EpisodeTrace.bind() must be called first")
        return self._context[1]

    def terrain(self) -> Terrain | None:
        """The terrain :meth:`bind` was given (None: unbound or no terrain)."""
        return self._context[3] if self._context is not None else None

    def derive(self, k0: int, k1: int) -> dict[str, np.ndarray]:
        """The named plant quantities of ticks ``k0:k1`` (episode ticks, held by the trace) from their raw
        rows (vectorised; the same definitions for a chunk as for the whole episode)."""
        k0, k1 = k0 - self.offset, k1 - self.offset
        if self._context is None:
            raise RuntimeError("EpisodeTrace.bind() must be called before deriving quantities")
        br, contacts, profile, terrain, frames = self._context
        a, dv, ticks = br.free_qadr, br.free_dadr, slice(k0, k1)
        qpos, qvel = self.qpos_mj[ticks], self.qvel_mj[ticks]
        plant_side = contacts.from_sensor_log(self.sensordata_mj[ticks])
        foot_pos = plant_side["foot_pos_in_world"]
        out = {
            "tick_parts_us": self.tick_parts_s[ticks] * 1e6,
            "base_pos_w": qpos[:, a : a + 3].copy(),
            "base_quat_wxyz": qpos[:, a + 3 : a + 7].copy(),
            "base_linvel_w": qvel[:, dv : dv + 3].copy(),
            "base_angvel_b": qvel[:, dv + 3 : dv + 6].copy(),
            "q": qpos[:, br.joint_qadr],
            "qd": qvel[:, br.joint_dadr],
            "foot_pos_w": foot_pos,
            "grf_plant_w": plant_side["forces_in_world"],
            "in_contact": plant_side["in_contact"],
            "slip_w": plant_side["slip_velocity_in_world"],
            "obstacle_contact": plant_side["obstacle_contact"],
            "mu_foot": friction_under_feet(terrain, foot_pos, self.mu_true[ticks]),
            "obstacle_clearance_m": obstacle_clearance(terrain, foot_pos, contacts.foot_radius_m),
        }
        clearance = np.full((k1 - k0, quad.N_LEGS), np.nan)
        if profile is not None and k1 > k0:
            swing = ~self.in_stance[ticks]
            z_obstacle = profile.evaluate(self.swing_phase[ticks][swing])[0]
            clearance[swing] = foot_pos[..., 2][swing] - contacts.foot_radius_m - z_obstacle
        out["clearance_m"] = clearance
        if frames is not None:
            out.update(frames.frames(self.contact_log, k0, k1, foot_pos))
        return out

    def finalize(self, rows: int | None = None) -> None:
        """Derive the named plant quantities of the first ``rows`` rows (default: every recorded tick the
        trace holds) into attributes (idempotent until :meth:`roll`)."""
        if self.finalized:
            return
        rows = self.n - self.offset if rows is None else rows
        derived = self.derive(self.offset, self.offset + rows)
        for name, value in derived.items():
            setattr(self, name, value)
        self._derived_names = tuple(derived)
        self.finalized = True

    def barrier_h_min(self, ticks: slice = slice(None)) -> np.ndarray:
        """(n, 4) the smallest h [m] over the barrier families per tick and leg (nan where none is active)."""
        rows = self.t_s[ticks].shape[0]
        return _fmin([log.h_m[ticks] for log in self.barriers.values() if log.per_leg], rows)

    # ------------------------------------------------------------------------------------------ derived
    def base_rpy(self) -> np.ndarray:
        """(n, 3) roll, pitch, yaw [rad] of the trunk (ZYX convention)."""
        return rpy_from_quat(self.base_quat_wxyz[: self.n - self.offset])

    def to_frame(self, dt: float | None = None) -> pd.DataFrame:
        """One row per control tick, typed columns, units in the names (every tick the trace holds)."""
        return self.frame(self.offset, self.n)

    def frame(self, k0: int, k1: int) -> pd.DataFrame:
        """Episode ticks ``k0:k1`` (held by the trace) as :meth:`to_frame` gives them (derived from the raw
        rows: usable during the episode, for streaming)."""
        t = slice(k0 - self.offset, k1 - self.offset)
        k0, k1 = t.start, t.stop
        if self.finalized:  # the derived arrays are already there: slice them
            d = {name: getattr(self, name)[t] for name in self._derived_names}
        else:
            d = self.derive(k0 + self.offset, k1 + self.offset)
        cols: dict[str, np.ndarray] = {"t_s": self.t_s[t]}
        self._state_columns(cols, d, t)
        self._leg_columns(cols, d, t)
        self._model_columns(cols, k0, k1)
        self._loop_columns(cols, d, t)
        return pd.DataFrame(cols)

    def _state_columns(self, cols: dict, d: dict, t: slice) -> None:
        """Trunk pose and velocity (world / trunk axes), joints, commands, gait phase."""
        _put(cols, "base_{}_w_m", "xyz", d["base_pos_w"])
        _put(cols, "base_quat_{}", "wxyz", d["base_quat_wxyz"])
        _put(cols, "base_v{}_w_mps", "xyz", d["base_linvel_w"])
        _put(cols, "base_w{}_b_radps", "xyz", d["base_angvel_b"])
        _put(cols, "base_{}_rad", ("roll", "pitch", "yaw"), rpy_from_quat(d["base_quat_wxyz"]))
        for j, jn in enumerate(quad.JOINT_NAMES):
            short = jn.removesuffix("_joint")
            cols[f"q_{short}_rad"] = d["q"][:, j]
            cols[f"qd_{short}_radps"] = d["qd"][:, j]
            cols[f"u_nom_{short}_nm"] = self.u_nom[t, j]
            cols[f"u_{short}_nm"] = self.u[t, j]
        cols["gait_phase"] = self.gait_phase[t]

    def _leg_columns(self, cols: dict, d: dict, t: slice) -> None:
        """Per leg: schedule, plant contact, foot, forces (plant and filter), barrier values, clearance."""
        slip = np.hypot(d["slip_w"][..., 0], d["slip_w"][..., 1])
        h_min = self.barrier_h_min(t)
        for i, leg in enumerate(quad.LEGS):
            cols[f"{leg}_stance"] = self.in_stance[t, i]
            cols[f"{leg}_scheduled_stance"] = self.scheduled_stance[t, i]
            cols[f"{leg}_contact"] = d["in_contact"][:, i]
            cols[f"{leg}_swing_phase"] = self.swing_phase[t, i]
            _put(cols, leg + "_foot_{}_w_m", "xyz", d["foot_pos_w"][:, i])
            cols[f"{leg}_contact_point_speed_mps"] = slip[:, i]
            _put(cols, leg + "_grf_plant_{}_w_n", "xyz", d["grf_plant_w"][:, i])
            _put(cols, leg + "_grf_filter_{}_w_n", "xyz", self.grf_filter_w[t, i])
            cols[f"{leg}_barrier_h_m"] = h_min[:, i]
            cols[f"{leg}_clearance_m"] = d["clearance_m"][:, i]
            cols[f"{leg}_mu_foot"] = d["mu_foot"][:, i]
            cols[f"{leg}_mu_hat_foot"] = self.mu_hat_foot[t, i]
            cols[f"{leg}_obstacle_contact"] = d["obstacle_contact"][:, i]
            cols[f"{leg}_obstacle_clearance_m"] = d["obstacle_clearance_m"][:, i]
            self._contact_frame_columns(cols, d, t, i, leg)
            for name, log in self.barriers.items():
                if log.per_leg:
                    cols[f"{leg}_barrier_{name}_h_m"] = log.h_m[t, i]
                    cols[f"{leg}_barrier_{name}_he_mps"] = log.he_mps[t, i]
        for name, log in self.barriers.items():  # families of other rows (the trunk's pitch and roll)
            for j, row in enumerate(log.rows if not log.per_leg else ()):
                cols[f"{row}_barrier_{name}_h_m"] = log.h_m[t, j]
                cols[f"{row}_barrier_{name}_he_mps"] = log.he_mps[t, j]

    def _contact_frame_columns(self, cols: dict, d: dict, t: slice, i: int, leg: str) -> None:
        """Leg ``i``'s contacts in MuJoCo's contact frame: the summed normal force, and the tangential force,
        friction, normal and contact-point slip of its most loaded contact (slot 0: sorted by normal force); its
        leg links on an obstacle; the foot touching any terrain, and touching a flank (normal more than 45 deg
        from vertical)."""
        def get(name: str) -> np.ndarray:
            return d[name][:, i] if name in d else getattr(self, name)[t, i]

        cols[f"{leg}_contact_frame_fn_n"] = get("contact_fn_n").sum(axis=1)
        cols[f"{leg}_contact_frame_ft_n"] = get("contact_ft_n")[:, 0]
        cols[f"{leg}_contact_frame_mu"] = get("contact_mu")[:, 0]
        _put(cols, leg + "_contact_frame_normal_{}_w", "xyz", get("contact_normal_w")[:, 0])
        cols[f"{leg}_contact_frame_slip_mps"] = get("contact_slip_mps")[:, 0]
        cols[f"{leg}_leg_link_obstacle_contact"] = get("leg_link_obstacle_contact")
        cols[f"{leg}_leg_link_obstacle_contact_off_foot"] = get("leg_link_obstacle_contact_off_foot")
        # what the trip rule reads of the foot's contacts (taslel_bench.metrics.clearance): any touching, a flank
        touching = get("contact_touching")
        cols[f"{leg}_foot_touching"] = touching.any(axis=1)
        cols[f"{leg}_foot_flank_contact"] = (touching & (get("contact_normal_w")[..., 2] < FLANK_COS)).any(axis=1)

    def _model_columns(self, cols: dict, k0: int, k1: int) -> None:
        """The controller model's residuals and barrier conditions (nan until computed after the episode)."""
        t = slice(k0, k1)
        residual = _rows(self.model_residual, k0, k1, quad.NV)
        cols["residual_trunk_force_n"] = np.linalg.norm(residual[:, :3], axis=1)
        cols["residual_trunk_torque_nm"] = np.linalg.norm(residual[:, 3:6], axis=1)
        cols["residual_joint_nm_max"] = np.abs(residual[:, 6:]).max(axis=1)
        acc_error = np.linalg.norm(_rows(self.foot_acc_error_w, k0, k1, quad.N_LEGS, 3), axis=2)
        legs = [log for log in self.barriers.values() if log.per_leg]
        psi_planned = _fmin([log.psi_planned_mps2[t] for log in legs], k1 - k0)
        psi_real = _fmin([_rows(log.psi_realized_mps2, k0, k1, quad.N_LEGS) for log in legs], k1 - k0)
        for i, leg in enumerate(quad.LEGS):
            cols[f"{leg}_foot_acc_error_mps2"] = acc_error[:, i]
            cols[f"{leg}_barrier_psi_planned_mps2"] = psi_planned[:, i]
            cols[f"{leg}_barrier_psi_realized_mps2"] = psi_real[:, i]

    def _loop_columns(self, cols: dict, d: dict, t: slice) -> None:
        """Leg-link contacts, the QP's status and timings, the friction estimate, the tick's cost."""
        cols["nonfoot_obstacle_contact"] = self.nonfoot_obstacle_contact[t]
        cols["shin_floor_contact"] = self.shin_floor_contact[t]
        cols["ecbf_margin_mps2"] = self.ecbf_margin_mps2[t]
        for name in ("qp_status", "qp_fallback", "qp_build_us", "qp_solve_us", "qp_solve_cpu_us", "qp_setup",
                     "qp_iterations", "qp_u_error_nm",
                     "mu_hat", "mu_true", "mu_hat_ready", "tick_us"):
            cols[name] = getattr(self, name)[t]
        _put(cols, "tick_{}_us", TICK_PARTS, d["tick_parts_us"])


def _raw_arrays(owners: list, capacity: int) -> list[tuple[np.ndarray, object]]:
    """(array, initial value) of every per-tick array (first axis ``capacity``) of ``owners`` that owns its
    data: the rows :meth:`EpisodeTrace.roll` moves and resets."""
    out = []
    for owner in owners:
        for value in vars(owner).values():
            if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == capacity and value.base is None:
                out.append((value, value.flat[0] if value.size else 0))
    return out


class _Block:
    """Columns of one (capacity, width) array: ``views`` (one per column group, first axis the tick), ``init``
    (the initial row)."""

    def __init__(self, block: np.ndarray, init: np.ndarray, views: list[np.ndarray]) -> None:
        self.block, self.init, self.views = block, init, views


def _column_block(capacity: int, dtype, columns: Sequence[tuple[tuple[int, ...], object]]) -> _Block:
    """One array holding ``columns`` side by side, each (shape of one tick's value, initial value), and a view
    of shape (capacity, *shape) per column group (no copies: rows are written through the block)."""
    widths = [int(np.prod(shape)) for shape, _ in columns]
    init = np.concatenate([np.full(w, fill, dtype) for w, (_, fill) in zip(widths, columns, strict=True)])
    block = np.empty((capacity, init.shape[0]), dtype)
    block[:] = init
    views, start = [], 0
    for w, (shape, _) in zip(widths, columns, strict=True):
        view = block[:, start : start + w]
        view = view[:, 0] if shape == () else view.reshape(capacity, *shape)
        assert np.shares_memory(view, block) or capacity * w == 0  # a view, never a copy
        views.append(view)
        start += w
    return _Block(block, init, views)


@kernel
def _copy_rows(k, t, phi, mu_hat, mu_true, clock0, clock1, clock2, clock3, clock4, build_us, solve_us, margin,
               mu_hat_ready, nonfoot, shin, filtered, fallback, iterations, qpos, qvel, sensordata, u_nom, u,
               swing_phase, mu_feet, lam, vdot, in_stance, scheduled, F, B, qp_status,
               qp_iterations):  # pragma: no cover - compiled  # fmt: skip
    """Row ``k`` of the float block ``F`` and the flag block ``B`` (column order:
    :meth:`EpisodeTrace._allocate_loop_rows`) and of ``qp_status``, ``qp_iterations``: the tick's wall time and its
    parts from the perf_counter times ``clock0`` .. ``clock4`` [s]; the filter's columns only when ``filtered`` (else
    they keep their initial values: nan, status -1)."""
    F[k, 0], F[k, 1], F[k, 2], F[k, 3] = t, phi, mu_hat, mu_true
    F[k, 4] = (clock4 - clock0) * 1e6
    F[k, 5], F[k, 6], F[k, 7], F[k, 8] = clock1 - clock0, clock2 - clock1, clock3 - clock2, clock4 - clock3
    c = _put_row(F, k, 12, qpos)
    c = _put_row(F, k, c, qvel)
    c = _put_row(F, k, c, sensordata)
    c = _put_row(F, k, c, u_nom)
    c = _put_row(F, k, c, u)
    c = _put_row(F, k, c, swing_phase)
    c = _put_row(F, k, c, mu_feet)
    n = in_stance.shape[0]
    for i in range(n):
        B[k, i] = in_stance[i]
        B[k, n + i] = scheduled[i]
    B[k, 2 * n], B[k, 2 * n + 1], B[k, 2 * n + 2] = mu_hat_ready, nonfoot, shin
    if not filtered:
        return
    B[k, 2 * n + 3] = fallback
    qp_status[k] = 1 if fallback else 0
    F[k, 9], F[k, 11] = build_us, margin
    if not np.isnan(solve_us):
        F[k, 10] = solve_us
    if iterations >= 0:
        qp_iterations[k] = iterations
    _put_row(F, k, _put_row(F, k, c, lam), vdot)


@kernel
def _put_row(F, k, c, src):  # pragma: no cover - compiled
    """F[k, c : c + len(src)] = src; returns the next column."""
    for i in range(src.shape[0]):
        F[k, c + i] = src[i]
    return c + src.shape[0]


def _fmin(arrays: list[np.ndarray], n: int) -> np.ndarray:
    """Element-wise minimum ignoring nan of (n, 4) arrays (all nan when there are none)."""
    out = np.full((n, quad.N_LEGS), np.nan)
    for a in arrays:
        out = np.fmin(out, a)
    return out


def _rows(values: np.ndarray, k0: int, k1: int, *shape: int) -> np.ndarray:
    """Rows k0:k1 of an array filled after the episode, or nan rows while it is not filled yet."""
    return values[k0:k1] if values.shape[0] >= k1 else np.full((k1 - k0, *shape), np.nan)


def _put(cols: dict[str, np.ndarray], pattern: str, names, values: np.ndarray) -> None:
    """cols[pattern.format(name)] = values[:, j] for each name."""
    for j, name in enumerate(names):
        cols[pattern.format(name)] = values[:, j]


def rpy_from_quat(quat_wxyz: np.ndarray) -> np.ndarray:
    """(n, 3) roll, pitch, yaw [rad] (ZYX convention) of (n, 4) unit quaternions (w, x, y, z)."""
    w, x, y, z = quat_wxyz.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=1)


def friction_under_feet(terrain: Terrain | None, foot_pos_w: np.ndarray, mu_trunk: np.ndarray) -> np.ndarray:
    """(n, 4) true friction coefficient [-] of the terrain under each foot-sphere centre (the terrain's
    friction at the foot's world (x, y)); without a terrain the trunk's, for every foot."""
    if terrain is None:
        return np.repeat(mu_trunk[:, None], quad.N_LEGS, axis=1)
    return terrain.friction_under(foot_pos_w[:, :, :2])


def obstacle_clearance(terrain: Terrain | None, foot_pos_w: np.ndarray, foot_radius_m: float) -> np.ndarray:
    """(n, 4) signed distance [m] from each foot sphere (radius ``foot_radius_m``) to the nearest obstacle of the
    terrain (a log, ...):
    <= 0 means touching. NaN without obstacles."""
    n = foot_pos_w.shape[0]
    if terrain is None or not terrain.has_obstacles:
        return np.full((n, quad.N_LEGS), np.nan)
    d, _, _ = terrain.obstacle_distance(foot_pos_w.reshape(-1, 3), foot_radius_m)
    return d.reshape(n, quad.N_LEGS)
