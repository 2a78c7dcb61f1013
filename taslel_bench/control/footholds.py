"""Foothold choice for the terrain-following trot (beyond the paper; ``controller.foothold_search > 0``).

The gait puts every touchdown at the same place relative to the hip, wherever the ground's edges are. On logs
and steps that sets stance feet just past a log or a riser, where the lower leg rests against the edge behind
the foot during stance, or on an edge itself, where the foot slides off. This planner moves each touchdown
along the trunk's heading by an offset ``delta`` [m] in [-search, +search] (steps of ``step_m``), chosen at
lift-off (and again at mid-swing with the controller's ``replan_phase``) from the terrain object:

* **shin clearance**: the lower-leg capsule of the filter's shin barrier (knee to the robot's ``shin_axis_fraction`` of
the
  way to the foot centre, radius ``shin_radius_m``) at the touchdown, mid-stance and lift-off poses of the
  planned stance, with the foot resting on the ground at the candidate point and the trunk level at the gait's
  height: its distance to the terrain should be >= ``shin_clearance_m`` (3 cm: with 2 cm, touchdowns moved far
  ahead left the calf nearly level and the shin still met the log in stance: 1.1 against 0.8 strikes per run on
  logs, 10 seeds);
* **edges**: the ground within ``edge_radius_m`` of the candidate (ahead, behind, left, right) should be
  within ``edge_rise_m`` of the candidate's height (a probe ``edge_rise_m`` above that height must be in free
  space and one ``edge_rise_m`` below it inside the ground);
* **a face ahead**: the ground up to ``riser_ahead_m`` ahead of the candidate (probes between ``edge_radius_m``
  and ``riser_ahead_m``) should stay below ``riser_rise_m`` above it: a stance foot set just before a riser
  starts its next swing against the riser's face. On the lossy plant a front foot set with its centre 3.7 cm
  before a 5 cm riser (its surface 2 cm from it) met the face in the next swing, the swing stalled and the trot
  walked backwards into a fall (steps, seed 5, 6.8 s). The probes sit 3 cm up, not 1 cm: a log's sloped side
  that low is no face (with 1 cm probes, URDF logs fell 1/10 and strikes rose, 10 seeds);

Each violation counts by how much [m]; the candidate of least total violation wins, ties (e.g. every candidate
clear) to the smallest ``|delta|`` (``delta = 0`` on flat ground and on a plane slope: the gait's own footholds).
All positions are world axes [m]; the knee comes from the leg's analytic kinematics in its hip frame.
"""

from __future__ import annotations

import math

import numpy as np

from taslel_bench.robot.description import default_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.terrain.terrain import Terrain

CAPSULE_POINTS = 7  # points along the shin capsule's axis per pose
STANCE_POSES = (0.0, 0.5, 1.0)  # [-] stance progress at which the shin is checked (touchdown, mid, lift-off)
SIZE_TIE = 1e-6  # [m of violation per m of |delta|] prefers the gait's own foothold among equally clear ones


class FootholdPlanner:
    """Touchdown offsets along the heading (module doc) for one terrain."""

    def __init__(self, terrain: Terrain, search_m: float, step_m: float = 0.01, shin_clearance_m: float = 0.03,
                 edge_radius_m: float = 0.03, edge_rise_m: float = 0.01, riser_ahead_m: float = 0.045,
                 riser_rise_m: float = 0.03, kinematics: LegKinematics | None = None) -> None:
        """``kinematics``: the robot's legs (None: the default robot's); its foot radius and shin capsule are
        checked."""
        self.terrain = terrain
        self.kinematics = kinematics if kinematics is not None else LegKinematics(default_robot())
        robot = self.kinematics.robot
        self._foot_radius_m, self._shin_radius_m = robot.foot_radius_m, robot.shin_radius_m
        n = round(search_m / step_m)
        offsets = step_m * np.arange(-n, n + 1)
        self.offsets_m = offsets[np.argsort(np.abs(offsets), kind="stable")]  # 0, -s, +s, -2s, ... (ties: nearest)
        self.shin_clearance_m = shin_clearance_m
        self.edge_radius_m = edge_radius_m
        self.edge_rise_m = edge_rise_m
        self.riser_ahead_m = riser_ahead_m
        self.riser_rise_m = riser_rise_m
        s = np.linspace(0.0, robot.shin_axis_fraction, CAPSULE_POINTS)
        self._axis_s = s[None, :, None]  # (1, points, 1) knee -> foot fractions

    def offset(self, leg: int, touchdown_xy_w: tuple[float, float], heading: tuple[float, float],
               foot_in_hip_td: list[float], stroke_m: float, ground_ref_m: float) -> float:
        """``delta`` [m] along the heading for leg ``leg`` whose gait touchdown is ``touchdown_xy_w`` [m, world],
        ``heading`` = (cos yaw, sin yaw), the gait's touchdown foot target ``foot_in_hip_td`` [m] (hip frame,
        z at the stand height), ``stroke_m`` the stance stroke (foot travel back relative to the hip) and
        ``ground_ref_m`` the trunk's ground reference (mean of the four) [m, world z]."""
        return float(self.offsets_m[int(np.argmin(self.violations(leg, touchdown_xy_w, heading, foot_in_hip_td,
                                                                       stroke_m, ground_ref_m)))])

    def violations(self, leg: int, touchdown_xy_w: tuple[float, float], heading: tuple[float, float],
                   foot_in_hip_td: list[float], stroke_m: float, ground_ref_m: float) -> np.ndarray:
        """Total violation [m] of each candidate of :attr:`offsets_m` (plus the size tie-break)."""
        c, s = heading
        x0, y0 = touchdown_xy_w
        px = x0 + c * self.offsets_m
        py = y0 + s * self.offsets_m
        h = np.array([self.terrain.height_at(float(a), float(b)) for a, b in zip(px, py, strict=True)])
        feet_w = np.stack([px, py, h + self._foot_radius_m], axis=1)  # (n, 3) foot centres resting on the ground
        return (self._shin_violation(leg, feet_w, h, heading, foot_in_hip_td, stroke_m, ground_ref_m)
                + self._edge_violation(feet_w, h, heading) + SIZE_TIE * np.abs(self.offsets_m))

    def _shin_violation(self, leg, feet_w, h, heading, foot_in_hip_td, stroke_m, ground_ref_m) -> np.ndarray:
        c, s = heading
        x_td, y_hip, z_stand = foot_in_hip_td
        points = []
        for k, delta in enumerate(self.offsets_m):
            z = z_stand + float(h[k]) - ground_ref_m  # the terrain-following shift of this foothold
            for progress in STANCE_POSES:
                knee, foot = self.kinematics.knee_and_foot(leg, x_td + float(delta) - progress * stroke_m, y_hip, z)
                dx, dy, dz = knee[0] - foot[0], knee[1] - foot[1], knee[2] - foot[2]  # hip (= level trunk) axes
                knee_w = feet_w[k] + (c * dx - s * dy, s * dx + c * dy, dz)
                points.append(knee_w + self._axis_s[0] * (feet_w[k] - knee_w))
        pts = np.concatenate(points).reshape(-1, 3)
        d = self.terrain.near_distance(pts, self._shin_radius_m)[0].reshape(len(self.offsets_m), -1)
        return np.maximum(0.0, self.shin_clearance_m - d.min(axis=1))

    def _edge_violation(self, feet_w, h, heading) -> np.ndarray:
        c, s = heading
        r, e = self.edge_radius_m, self.edge_rise_m
        around = np.array([(c * r, s * r), (-c * r, -s * r), (-s * r, c * r), (s * r, -c * r)])  # ahead, back, l, r
        ahead = np.array([(c * a, s * a) for a in np.linspace(r, self.riser_ahead_m, 3)[1:]])  # riser probes
        probes = [(around, h + e), (around, h - e), (ahead, h + self.riser_rise_m)]  # (xy offsets, probe z)
        pts = [np.concatenate([feet_w[:, None, :2] + xy[None], np.broadcast_to(z[:, None, None], (len(h), len(xy), 1))],
                              axis=2).reshape(-1, 3) for xy, z in probes]
        d = self.terrain.near_distance(np.concatenate(pts), 0.0)[0]
        above, below, riser = np.split(d, np.cumsum([len(p) for p in pts])[:-1])
        n = len(h)
        rise = np.maximum(0.0, -above).reshape(n, -1).sum(axis=1)  # ground above h + e nearby: a riser, a log's side
        drop = np.maximum(0.0, below).reshape(n, -1).sum(axis=1)  # free space below h - e: an edge to slide off
        face = np.maximum(0.0, -riser).reshape(n, -1).sum(axis=1)  # a face ahead the next swing starts against
        return rise + drop + face


def heading_of(base_pose: np.ndarray) -> tuple[float, float]:
    """(cos yaw, sin yaw) of Pinocchio's base pose (position, quaternion x, y, z, w)."""
    qx, qy, qz, qw = (float(v) for v in base_pose[3:7])
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return math.cos(yaw), math.sin(yaw)
