"""A terrain-following variant of the nominal trot (beyond the paper; ``controller.terrain_following=true``).

The paper's nominal (:class:`~taslel_bench.control.nominal.NominalController`) plans every foot at the same
height in its hip frame, as if the ground were flat. This variant asks the :class:`~taslel_bench.terrain.
terrain.Terrain` for the ground height [m, world z] under each foot and shifts each foot target along the
trunk's z axis by that height relative to the mean of the four:

* a **stance** foot keeps the ground height at which it touched down (latched at the swing -> stance switch);
* a **swing** foot's ground reference goes from its lift-off height up to ``h_top`` (the highest ground
  between the foot and its predicted touchdown point, a running maximum over the swing) in the first half of
  the swing and from ``h_top`` to the touchdown height in the second half (cosine-eased); the paper's
  half-sine lift (``swing_height``) rides on top of it. The touchdown point is predicted from the commanded
  speed: hip position now + (L/2 + speed x remaining swing time) along the heading.
* ``h_ref`` = mean of the four references; foot target z in the hip frame += reference - ``h_ref``, so the
  trunk stays ``stand_height`` above the mean ground and level when the ground under its feet is not.

* optionally (``footholds``, :mod:`taslel_bench.control.footholds`) each touchdown moves along the heading by
  an offset chosen at lift-off, away from edges and from footholds whose lower leg would rest on an edge; the
  offset eases in over the swing (the gait's own x profile) and holds through the stance that follows. With
  ``replan_phase`` in (0, 1) the offset is chosen again once the swing passes that phase, from the hip's
  position then (the prediction's error from a trunk slower than commanded shrinks with the time left); the
  offset eases from its value at that tick to the new plan over the rest of the swing (continuous).

* optionally (``swing_from_measured_hips``) swing feet are aimed from the measured hip heights rather than the
  gait's: the target z in the hip frame gains the stance legs' sag, ``stand_height`` - the mean of the stance
  legs' hip height [m, world z] above their ground + foot radius, low-passed. One value for every swing foot:
  a per-hip correction (each hip's own height) fed the trunk's pitch back into the swing feet (a nose-down
  trunk aims its front swing feet higher, so they catch it later) and the A1 fell on logs 7/10. Without it the
  trunk rides ~2 cm low under its own weight (PD stance legs), so a swing foot aimed ``stand_height`` below
  its hip lands at swing phase ~0.9 instead of 1 (URDF slope and steps: median 0.93, 10th percentile 0.83-0.87,
  every touchdown on a top counted a trip). The correction eases in over the first
  :data:`SWING_SAG_RAMP` of the swing (no step in the target at lift-off) and holds to touchdown.

What it reads: the trunk's position and yaw (world) and the terrain object (a map; a real robot would need a
height map from vision or from its footholds); with ``swing_from_measured_hips`` also the trunk's height and
tilt (the stance hips' heights; a real robot would estimate them from leg kinematics and its IMU). The shifts are
along the trunk's z, exact when the trunk is level. ``qd_des`` stays the flat gait's (the shift's rate is not fed
forward). The gait schedule (stance/swing, swing phase) is the paper's.
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.control.footholds import FootholdPlanner, heading_of
from taslel_bench.control.gait import TROT_OFFSETS_LIST
from taslel_bench.control.nominal import NominalController
from taslel_bench.robot import quadruped as quad
from taslel_bench.terrain.terrain import Terrain

PATH_SAMPLES = 8  # ground heights sampled between a swing foot and its predicted touchdown point
SWING_SAG_RAMP = 0.2  # [-] swing-phase span over which the measured-hip correction eases in
SAG_TIME_CONSTANT_S = 0.1  # [s] low-pass of the stance legs' measured sag
MAX_SAG_M = 0.04  # [m] the sag estimate is clamped to +-this
TOUCHDOWN_DESCENT_S = 0.03  # [s] a touchdown aim above the ground is taken back over this much of the stance


def _ease(x: float) -> float:
    """Cosine ease 0 -> 1 on x in [0, 1]."""
    return 0.5 * (1.0 - math.cos(math.pi * min(max(x, 0.0), 1.0)))


_NEEDS_POSE = "controller.terrain_following=true needs the trunk pose: compute(..., base_pose=q[:7])"


class TerrainFollowingController(NominalController):
    """The nominal trot with foot targets shifted by the ground height under each foot (module doc)."""

    def __init__(self, *args, terrain: Terrain, footholds: FootholdPlanner | None = None,
                 replan_phase: float = 0.0, swing_from_measured_hips: bool = False, touchdown_height_m: float = 0.0,
                 **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if not 0.0 <= replan_phase < 1.0:
            raise ValueError(f"replan_phase={replan_phase}: valid is 0 (plan at lift-off only) or a swing phase in (0, "
                             f"1)")
        self.terrain = terrain
        self.footholds = footholds
        self.replan_phase = replan_phase
        self.swing_from_measured_hips = swing_from_measured_hips
        self.touchdown_height_m = touchdown_height_m
        self.sag_m = 0.0  # [m] stance legs' sag, low-passed (swing_from_measured_hips)
        self.foothold_offset_m = np.zeros(4)  # [m, along the heading] each foot's touchdown offset this tick
        self._offset_from_m = np.zeros(4)  # [m] swing feet: offset when the current plan was made
        self._ease_from = np.zeros(4)  # [-] swing feet: the x ease's value when the current plan was made
        self._offset_plan_m = np.zeros(4)  # [m] swing feet: offset planned for the coming touchdown
        self._replanned = np.zeros(4, bool)  # swing feet: the plan at replan_phase is made
        self.ground_ref_m = np.zeros(4)  # [m, world z] each foot's ground reference this tick (last computed)
        self._latched_m = np.full(4, math.nan)  # [m] stance feet: ground height at touchdown
        self._lift_m = np.zeros(4)  # [m] swing feet: ground height at lift-off
        self._top_m = np.zeros(4)  # [m] swing feet: highest ground on the path so far this swing
        self._td_m = np.zeros(4)  # [m] swing feet: ground height at the predicted touchdown
        self._was_stance = np.ones(4, bool)
        self._has_swung = np.zeros(4, bool)  # touchdown_height_m: the leg has swung since the walk began
        self._hips_xy = self.robot.hip_positions_in_trunk[:, :2].tolist()  # [m] trunk axes, plain floats for the tick
        self._base_pose: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the latched ground heights (a new episode)."""
        self._latched_m[:] = math.nan
        self._was_stance[:] = True
        self._has_swung[:] = False
        self.foothold_offset_m[:] = self._offset_from_m[:] = self._offset_plan_m[:] = self._ease_from[:] = 0.0
        self._replanned[:] = False
        self.sag_m = 0.0

    def compute(self, t: float, q_joints: np.ndarray, qd_joints: np.ndarray, base_pose: np.ndarray | None = None,
                base_velocity: np.ndarray | None = None, tau_applied: np.ndarray | None = None) -> np.ndarray:
        """Nominal torques [N·m] at episode time ``t`` [s]; ``base_pose`` = Pinocchio's first 7 coordinates
        (trunk position [m, world], quaternion x, y, z, w); the trunk velocity and applied torques are not used."""
        if base_pose is None:
            raise ValueError(_NEEDS_POSE)
        self._base_pose = base_pose
        return super().compute(t, q_joints, qd_joints)

    def _pose(self) -> np.ndarray:
        """The trunk pose of the last :meth:`compute` call."""
        if self._base_pose is None:
            raise ValueError(_NEEDS_POSE)
        return self._base_pose

    def update_references(self, t: float) -> None:
        """The flat gait's ``q_des`` / ``qd_des``, then ``q_des`` from the terrain-shifted foot targets
        (``qd_des`` kept)."""
        super().update_references(t)
        rows = self.gait.foot_targets_list(self.gait_time(t))
        gs = self.contact_plan(t)
        ground = self._ground_references(gs, self._pose(), rows)
        h_ref = float(np.mean(ground))
        for i in range(quad.N_LEGS):
            rows[i][2] += ground[i] - h_ref
        if self.swing_from_measured_hips:
            self._lift_from_measured_hips(gs, rows, ground)
        if self.touchdown_height_m > 0.0 and self.gait_time(t) >= 0.0:
            self._aim_above_touchdown(gs, rows)
        self.q_des[:] = self._legs_ik_list(rows)

    def _aim_above_touchdown(self, gs, rows: list[list[float]]) -> None:
        """Foot target z (hip frame) += ``touchdown_height_m`` x a bump that eases in over the swing's second half
        and back out over the first :data:`TOUCHDOWN_DESCENT_S` of the stance (continuous): the swing ends that far
        above the expected ground and the foot meets it early in the stance, still descending, instead of
        before the schedule's touchdown (module doc); ``gs`` this tick's gait state."""
        p = self.gait.p
        for i, offset in enumerate(TROT_OFFSETS_LIST):
            if gs.in_stance[i]:
                if not self._has_swung[i]:  # the stance the walk starts in follows no swing
                    continue
                t_stance = ((gs.phi + offset) % 1.0) * p.period_s  # [s] since the scheduled touchdown
                bump = 1.0 - _ease(t_stance / TOUCHDOWN_DESCENT_S)
            else:
                self._has_swung[i] = True
                bump = _ease(2.0 * float(gs.swing_phase[i]) - 1.0)
            rows[i][2] += self.touchdown_height_m * bump

    def _lift_from_measured_hips(self, gs, rows: list[list[float]], ground: np.ndarray) -> None:
        """Swing feet's target z (hip frame) += the stance legs' sag (module doc): stand height - the mean of the
        stance legs' measured hip height [m, world z] above their ground + foot radius, low-passed
        (:data:`SAG_TIME_CONSTANT_S`) and eased in over the swing's start; ``gs`` this tick's gait state."""
        pose = self._pose()
        qx, qy, qz, qw = (float(v) for v in pose[3:7])
        r20, r21 = 2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx)  # trunk x, y axes' world z components
        heights = [float(pose[2]) + r20 * hx + r21 * hy - float(ground[i]) - self.robot.foot_radius_m
                   for i, (hx, hy) in enumerate(self._hips_xy) if gs.in_stance[i]]
        if heights:
            sag = self.gait.p.stand_height_m - sum(heights) / len(heights)
            self.sag_m += (min(max(sag, -MAX_SAG_M), MAX_SAG_M) - self.sag_m) * min(
                1.0, self.fd_dt_s / SAG_TIME_CONSTANT_S
            )
        for i in range(quad.N_LEGS):
            if not gs.in_stance[i]:
                rows[i][2] += self.sag_m * _ease(float(gs.swing_phase[i]) / SWING_SAG_RAMP)

    def _ground_references(self, gs, base_pose: np.ndarray, rows: list[list[float]]) -> np.ndarray:
        """(4,) ground reference [m, world z] of each foot this tick (module doc)."""
        x, y = float(base_pose[0]), float(base_pose[1])
        c, s = heading_of(base_pose)
        p = self.gait.p
        t_swing = p.period_s * (1.0 - p.duty)
        half = 0.5 * self.gait.step_length_m
        ground = self.ground_ref_m
        if self.footholds is not None:
            self._apply_foothold_offsets(gs, rows, (x, y), (c, s), half, t_swing)
        for i in range(quad.N_LEGS):
            hx, hy = self._hips_xy[i]
            fx, fy = hx + rows[i][0], hy + rows[i][1]  # foot target, trunk axes, from the trunk origin
            foot_w = (x + c * fx - s * fy, y + s * fx + c * fy)
            if math.isnan(self._latched_m[i]):  # first tick: the ground under the foot now
                self._latched_m[i] = self.terrain.height_at(*foot_w)
            if gs.in_stance[i]:
                if not self._was_stance[i]:  # touchdown: latch the last prediction
                    self._latched_m[i] = self._td_m[i]
                ground[i] = self._latched_m[i]
            else:
                phase = float(gs.swing_phase[i])
                td_w = self._touchdown_w(i, phase, fy, (x, y), (c, s), half, t_swing, self._offset_plan_m[i])
                self._td_m[i] = self.terrain.height_at(*td_w)
                if self._was_stance[i]:  # lift-off
                    self._lift_m[i] = self._top_m[i] = self._latched_m[i]
                path = self.terrain.highest_along(foot_w, td_w, PATH_SAMPLES)
                self._top_m[i] = max(self._top_m[i], path, self._td_m[i])
                if phase < 0.5:
                    ground[i] = self._lift_m[i] + (self._top_m[i] - self._lift_m[i]) * _ease(2.0 * phase)
                else:
                    ground[i] = self._top_m[i] + (self._td_m[i] - self._top_m[i]) * _ease(2.0 * phase - 1.0)
            self._was_stance[i] = bool(gs.in_stance[i])
        return ground

    def _touchdown_w(self, leg: int, phase: float, foot_y: float, trunk_xy: tuple[float, float],
                     heading: tuple[float, float], half: float, t_swing: float, offset: float) -> tuple[float, float]:
        """World (x, y) [m] where swing leg ``leg`` at swing ``phase`` is predicted to touch down: its hip moved on
        at the commanded speed for the rest of the swing, + half the stroke + ``offset`` along the trunk's x;
        ``foot_y`` [m] the foot target's y from the trunk origin (trunk axes)."""
        ahead = half + self.gait.p.speed_mps * (1.0 - phase) * t_swing + offset  # [m] hip -> touchdown, trunk x
        tx = self._hips_xy[leg][0] + ahead
        (x, y), (c, s) = trunk_xy, heading
        return x + c * tx - s * foot_y, y + s * tx + c * foot_y

    def _apply_foothold_offsets(self, gs, rows: list[list[float]], trunk_xy: tuple[float, float],
                                heading: tuple[float, float], half: float, t_swing: float) -> None:
        """Plan each lifting foot's touchdown offset (:class:`FootholdPlanner`; again at ``replan_phase``) and add
        this tick's offsets to the foot targets' x (hip frame, along the heading): eased in over a swing, held
        through a stance."""
        for i in range(quad.N_LEGS):
            if gs.in_stance[i]:
                if not self._was_stance[i]:  # touchdown: the planned offset holds through this stance
                    self.foothold_offset_m[i] = self._offset_plan_m[i]
            else:
                phase = float(gs.swing_phase[i])
                lift_off = bool(self._was_stance[i])
                replan = self.replan_phase > 0.0 and not self._replanned[i] and phase >= self.replan_phase
                if lift_off or replan:  # plan the coming touchdown from the hip's position now
                    self._replanned[i] = replan
                    self._offset_from_m[i] = self.foothold_offset_m[i]
                    self._ease_from[i] = 0.0 if lift_off else _ease(phase)
                    self._offset_plan_m[i] = self._plan_offset(i, phase, rows[i][1], trunk_xy, heading, half, t_swing)
                e0 = self._ease_from[i]
                done = (_ease(phase) - e0) / (1.0 - e0) if e0 < 1.0 else 1.0
                self.foothold_offset_m[i] = (
                    self._offset_from_m[i] + (self._offset_plan_m[i] - self._offset_from_m[i]) * done
                )
            rows[i][0] += self.foothold_offset_m[i]

    def _plan_offset(self, leg: int, phase: float, target_y: float, trunk_xy: tuple[float, float],
                     heading: tuple[float, float], half: float, t_swing: float) -> float:
        """The planner's touchdown offset [m] for swing leg ``leg`` at swing ``phase``; ``target_y`` [m] its foot
        target's y in the hip frame."""
        # at the commanded speed: the trunk's measured speed over the last period (it walks at 75-85 % of it) gave
        # more shin strikes on logs at lift-off planning, 2.4 against 1.1 per run (10 seeds)
        td = self._touchdown_w(leg, phase, self._hips_xy[leg][1] + target_y, trunk_xy, heading, half, t_swing, 0.0)
        target_td = [half, target_y, -self.gait.p.stand_height_m]
        ground_ref = float(np.mean(self.ground_ref_m))  # the trunk's, last tick
        assert self.footholds is not None  # called from _apply_foothold_offsets, only with a planner
        return self.footholds.offset(leg, td, heading, target_td, 2.0 * half, ground_ref)
