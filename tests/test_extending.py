"""Extending the harness without touching the core (docs/guides/extending.md): a barrier family and a kind of
terrain defined here, in a test module, reach the filter, the plant, the trace, the MCAP and the metrics
through config and the public interface only."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
import pandas as pd
import pytest

from scenarios.flat import FlatGround
from taslel_bench.control.plan import ContactPlan, NominalControl
from taslel_bench.filter.barriers.base import Barrier, BarrierWorld
from taslel_bench.filter.layout import VDOT
from taslel_bench.interfaces import OBSTACLE, Plane, QPProblem, Terrain, quad
from taslel_bench.record.mcap import read_messages
from taslel_bench.robot.description import RobotDescription, load_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg

SHORT = ["duration=1.0", "progress=false"]
FOOT_RADIUS_M = load_robot("a1").foot_radius_m  # [m]


class HoldStand:
    """A toy nominal controller: joint PD to the stand pose, every foot planned in stance (a controller without
    a gait clock). Built from ``controller._target_`` with the robot and the control period."""

    def __init__(self, robot: RobotDescription, control_dt_s: float, terrain=None, stand_duration: float = 0.5,
                 kp: float = 80.0, kd: float = 2.0) -> None:
        self.robot, self.stand_duration_s, self.kp, self.kd = robot, stand_duration, kp, kd
        self.stand_height_m, self.commanded_speed_mps, self.stance_swing_s = robot.stand_height_m, 0.0, (0.2, 0.2)
        feet = [[0.0, g.lateral_m, -robot.stand_height_m] for g in robot.legs]
        self._stand = LegKinematics(robot).legs_ik(feet)  # [rad]
        self._plan = ContactPlan(math.nan, 0.0, np.ones(4, bool), np.zeros(4), 0.0)

    def compute(self, t, q_joints, qd_joints, base_pose=None):
        u = self.kp * (self._stand - q_joints) - self.kd * qd_joints
        return np.clip(u, -self.robot.torque_limits, self.robot.torque_limits)

    def contact_plan(self, t):
        return self._plan

    def stand_configuration(self):
        return self._stand.copy()

    def reset(self):
        pass


class FootCeiling(Barrier):
    """A toy barrier: every swing foot's sphere bottom stays below ``ceiling_m`` [m] (h = ceiling - bottom),
    as an exponential CBF: J_z vdot <= a2 h_e + a1 hdot - (J̇v)_z with hdot = -v_z, h_e = hdot + a1 h."""

    def __init__(self, world: BarrierWorld, name: str, ceiling_m: float = 0.04) -> None:
        super().__init__(world, name)
        self.ceiling_m = ceiling_m

    def write(self, qp: QPProblem, x) -> None:
        m = x.model
        for i in range(quad.N_LEGS):
            r = self.start + i
            if x.in_stance[i]:
                qp.G[r], qp.h[r], self.h[i], self.h_e[i] = 0.0, 1e6, np.nan, np.nan
                continue
            h = self.ceiling_m - (m.foot_pos_in_world[i, 2] - self.foot_radius_m)
            hdot = -m.foot_vel_in_world[i, 2]
            h_e = hdot + self.alpha1 * h
            qp.G[r, VDOT] = m.foot_jac_in_world[i, 2]
            qp.h[r] = self.alpha2 * h_e + self.alpha1 * hdot - m.foot_jdotv_in_world[i, 2]
            self.h[i], self.h_e[i] = h, h_e


def test_a_barrier_family_is_one_class_and_one_config_entry(tmp_path):
    toy = f"+filter.barriers.ceiling={{_target_:{__name__}.FootCeiling,ceiling_m:0.04}}"
    built = Built(compose_cfg([*SHORT, toy]))
    assert [b.name for b in built.filter.barriers] == ["ceiling"]  # flat floor: the other families do not apply
    assert "FL_ceiling" in built.filter.problem.row_labels
    summary = run(compose_cfg([*SHORT, toy]), tmp_path / "toy", {"scenario": "flat", "solver": "daqp"})
    run(compose_cfg(SHORT), tmp_path / "plain", {"scenario": "flat", "solver": "daqp"})
    assert summary["status"] in ("ok", "degraded") and summary["qp_failed_rate"] == 0.0
    steps = pd.read_parquet(tmp_path / "toy" / "steps.parquet")
    walking = steps[steps.t_s >= 0.5]
    h = walking[[f"{leg}_barrier_ceiling_h_m" for leg in quad.LEGS]].to_numpy()
    assert np.isfinite(h).any() and np.nanmin(h) > -5e-3  # the swing feet were kept (nearly) below 4 cm
    plain_steps = pd.read_parquet(tmp_path / "plain" / "steps.parquet")
    apex = {name: (s[s.t_s >= 0.5]["FL_foot_z_w_m"] - FOOT_RADIUS_M).max()
            for name, s in (("toy", steps), ("plain", plain_steps))}
    assert apex["plain"] > 0.05 and apex["toy"] < 0.045  # the trot lifts the feet ~6 cm without it
    fields = next(msg for topic, _, msg in read_messages(tmp_path / "toy" / "episode.mcap") if topic == "/barrier")
    assert all("ceiling_h_m" in fields[leg] and "ceiling_h_e_mps" in fields[leg] for leg in quad.LEGS)
    assert math.isfinite(summary["barrier_negative_rate"])  # the metrics judged the toy family


@dataclass(frozen=True)
class Pebble:
    """A toy terrain part: a sphere of radius ``radius_m`` [m] centred at ``centre_m`` [m], an obstacle."""

    centre_m: tuple[float, float, float]
    radius_m: float
    friction: float = 1.0
    role: str = OBSTACLE

    def add_to(self, spec, body, name, rng) -> None:
        geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[self.radius_m, 0, 0],
                             pos=list(self.centre_m))
        geom.friction = [self.friction, 0.005, 0.0001]
        geom.priority, geom.contype, geom.conaffinity, geom.condim = 1, 0, 1, 3

    def top_z(self, x, y) -> float:
        d2 = (x - self.centre_m[0]) ** 2 + (y - self.centre_m[1]) ** 2
        return self.centre_m[2] + math.sqrt(self.radius_m**2 - d2) if d2 <= self.radius_m**2 else -math.inf

    def normal(self, x, y) -> np.ndarray:
        p = np.array([x, y, self.top_z(x, y)])
        return (p - np.asarray(self.centre_m)) / self.radius_m

    def friction_at(self, x, y) -> float:
        return self.friction

    def sphere_distance(self, centres, radius):
        c = np.asarray(centres, float).reshape(-1, 3)
        delta = c - np.asarray(self.centre_m)
        dist = np.linalg.norm(delta, axis=1)
        normal = delta / np.maximum(dist, 1e-12)[:, None]
        return dist - self.radius_m - radius, normal, np.asarray(self.centre_m) + self.radius_m * normal


class PebbleField(FlatGround):
    """A toy scenario: pebbles on the path (a kind of terrain the core has never seen)."""

    def __init__(self, name: str = "pebbles", friction: float = 1.0) -> None:
        super().__init__(name=name, friction=friction)
        pebbles = [Pebble((0.35 + 0.08 * i, y, -0.01), 0.03) for i in range(6) for y in (-0.13, 0.13)]
        self.terrain = Terrain((Plane(self.friction), *pebbles))


def test_a_kind_of_terrain_is_one_class(tmp_path):
    cfg = compose_cfg([*SHORT, "duration=2.0", "filter.enabled=false"])
    cfg.scenario = {"_target_": f"{__name__}.PebbleField", "name": "pebbles", "friction": 1.0}
    built = Built(cfg)
    m = built.mj_model
    assert m.body("obstacles").id >= 0 and m.ngeom >= 12 + 4  # the pebbles are in the plant, as obstacles
    terrain = built.scenario.terrain
    assert terrain.height_at(0.35, -0.13) == pytest.approx(0.02)
    summary = run(cfg, tmp_path, {"scenario": "pebbles"})
    # the metrics read the toy terrain: clearance of the feet to the pebbles, and the plant's contacts on them
    assert math.isfinite(summary["obstacle_clearance_min_m"]) and summary["obstacle_clearance_min_m"] < 0.05
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    touched = steps[[f"{leg}_obstacle_contact" for leg in quad.LEGS]].to_numpy().any()
    assert touched and math.isfinite(summary["obstacle_touch_swing_rate"])


def test_a_nominal_controller_is_one_class_and_one_config_group_entry(tmp_path):
    """A controller defined here, chosen by ``controller._target_``, runs under the paper's filter on every shipped
    robot's description it is given; the plan it returns is the stance set the filter and the trace use."""
    over = ["~controller", f"+controller._target_={__name__}.HoldStand", "+controller.stand_duration=0.3",
            "robot=go1"]
    built = Built(compose_cfg([*SHORT, *over]))
    assert isinstance(built.controller, HoldStand) and isinstance(built.controller, NominalControl)
    assert built.controller.robot.name == "go1"
    summary = run(compose_cfg([*SHORT, *over]), tmp_path / "hold", {"scenario": "flat", "solver": "daqp"})
    assert summary["robot"] == "go1" and not summary["fell"] and summary["qp_failed"] == 0
    steps = pd.read_parquet(tmp_path / "hold" / "steps.parquet")
    assert steps[[f"{leg}_scheduled_stance" for leg in quad.LEGS]].all().all()  # the plan, recorded
    assert abs(summary["distance_m"]) < 0.05  # it stands
