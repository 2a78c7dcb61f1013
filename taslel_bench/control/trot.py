"""``controller=trot``: the paper's trot for any robot, built from the ``controller`` group (its keys, defaults and
units: :class:`taslel_bench.config.schema.TrotConfig`). Values left null come from the robot
(:class:`taslel_bench.control.gait.TrotScaling`); ``terrain_following`` gives the terrain-following variant (beyond the
paper)."""

from __future__ import annotations

from taslel_bench.control.footholds import FootholdPlanner
from taslel_bench.control.gait import GaitParams, TrotScaling
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.control.terrain_following import TerrainFollowingController
from taslel_bench.robot.description import RobotDescription
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.terrain.terrain import Terrain


def trot_values(robot: RobotDescription, scaling: TrotScaling, **given: float | None) -> dict[str, float]:
    """speed [m/s], swing_height [m], stand_height [m], kp [N·m/rad], kd [N·m·s/rad]: ``given`` where not None,
    else the robot's (``scaling``)."""
    defaults = scaling.values(robot.mass_kg, robot.leg_length_m, robot.stand_height_m)
    return {key: float(v) if (v := given.get(key)) is not None else value for key, value in defaults.items()}


def trot_controller(
    robot: RobotDescription,
    control_dt_s: float,
    terrain: Terrain | None = None,
    *,
    period: float,
    duty: float,
    stand_duration: float,
    scaling: dict[str, float],
    speed: float | None = None,
    swing_height: float | None = None,
    stand_height: float | None = None,
    kp: float | None = None,
    kd: float | None = None,
    terrain_following: bool = False,
    foothold_search: float = 0.0,
    foothold_replan_phase: float = 0.0,
    swing_from_measured_hips: bool = False,
    touchdown_height: float = 0.0,
) -> NominalController:
    """The trot of ``robot`` at the control period ``control_dt_s`` [s]; the keys are ``controller=trot``'s
    (meanings and units there). ``terrain_following`` needs the world's ``terrain``."""
    v = trot_values(
        robot, TrotScaling(**scaling), speed=speed, swing_height=swing_height, stand_height=stand_height, kp=kp, kd=kd
    )
    gait = GaitParams(period_s=float(period), duty=float(duty), swing_height_m=v["swing_height"],
                      stand_height_m=v["stand_height"], speed_mps=v["speed"])
    gains = PDGains(kp=v["kp"], kd=v["kd"])
    common = {"stand_duration_s": float(stand_duration), "fd_dt_s": float(control_dt_s), "robot": robot}
    if not terrain_following:
        return NominalController(gait, gains, **common)
    if terrain is None:
        raise ValueError("controller.terrain_following=true needs the world's terrain")
    footholds = (FootholdPlanner(terrain, float(foothold_search), kinematics=LegKinematics(robot))
                 if foothold_search > 0.0 else None)
    return TerrainFollowingController(gait, gains, terrain=terrain, footholds=footholds,
                                      replan_phase=float(foothold_replan_phase),
                                      swing_from_measured_hips=bool(swing_from_measured_hips),
                                      touchdown_height_m=float(touchdown_height), **common)
