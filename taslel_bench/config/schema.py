"""The run config's schema: Hydra structured configs (dataclasses registered in Hydra's ConfigStore) for the top
level, ``record``, ``health``, ``safety``, ``robot``, ``model``, ``filter`` and the trot ``controller``. Each key's
default, one-line meaning, unit and valid range live here once (:func:`taslel_bench.util.params.param`); where a core
dataclass already holds a default (the filter's, the model's, the plant's, the trot builder's), the field reads it
from there. The YAML options under ``conf/`` set only what differs from the schema; Hydra refuses a key the schema
does not have and a value of the wrong type while composing, and :func:`taslel_bench.config.validate.validate`
checks the ranges (:func:`taslel_bench.util.params.check_fields`) and the rules between keys.

Choices are strings checked against their list (``filter.fallback`` in ``nominal, hold_last``), not OmegaConf
enums: an enum value would change the text of every run's ``config.yaml`` and so its identity.
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf
from omegaconf.errors import ConfigKeyError, ValidationError

from taslel_bench.control.contact_estimate import ContactEstimateSettings
from taslel_bench.control.contact_plan_estimate import PlanEstimateSettings
from taslel_bench.control.policy import policy_controller
from taslel_bench.control.trot import trot_controller
from taslel_bench.filter.robust import RobustSettings
from taslel_bench.filter.safety_filter import (
    FALLBACKS,
    FORMULATIONS,
    FRICTION_CONES,
    REGULARIZATION_TARGETS,
    RELAXATIONS,
    STANCE_SOURCES,
    FilterSettings,
)
from taslel_bench.metrics.health import HealthLimits
from taslel_bench.metrics.verdict import SafetyLimits
from taslel_bench.plant.adapter import CONES, INTEGRATORS, PlantNames, PlantOverrides
from taslel_bench.robot.description import ROBOT_DEFAULTS, complete_robot_node
from taslel_bench.robot.model_options import ModelOptions
from taslel_bench.util.fields import ConfigError, plain_dict
from taslel_bench.util.params import config_copy, default_of, param

MAX_DURATION_S = 3600.0  # [s] one episode (and the latest filter start)
RATE_BOUND = "gain x control period <= 1"


def _trot_default(name: str) -> Any:
    """The default of the trot builder's argument ``name`` (:func:`taslel_bench.control.trot.trot_controller`)."""
    return inspect.signature(trot_controller).parameters[name].default


def _robot_default(name: str) -> Any:
    """A robot file's value for a key it leaves out (:data:`taslel_bench.robot.description.ROBOT_DEFAULTS`)."""
    value = ROBOT_DEFAULTS[name]
    return list(value) if isinstance(value, list) else value


def _as_list(value: Any) -> Any:
    """A tuple default as the list OmegaConf holds."""
    return list(value) if isinstance(value, tuple) else value


# the frozen core values as config nodes (same fields, defaults and specs; for a type checker, the values)
if TYPE_CHECKING:
    HealthConfig = HealthLimits
    SafetyConfig = SafetyLimits
    RobustConfig = RobustSettings
else:
    HealthConfig = config_copy(HealthLimits, "HealthConfig")
    SafetyConfig = config_copy(SafetyLimits, "SafetyConfig")
    RobustConfig = config_copy(RobustSettings, "RobustConfig")


# ------------------------------------------------------------------------------------------------- record
@dataclass
class RecordConfig:
    """``record``: what a run writes beside its summary."""

    mcap: bool = param(True, "write episode.mcap (Foxglove: the robot in the 3D panel, signals, events)")
    chunk_ticks: int | None = param(5000, "the episode is processed and written in chunks of this many ticks "
                                          "(memory independent of duration); null: the whole episode in memory "
                                          "(the same numbers)", lo=1)
    mcap_rate_hz: float | None = param(100.0, "ticks written to episode.mcap (null: every control tick); "
                                              "steps.parquet keeps all", unit="Hz", lo=0.0, lo_open=True,
                                       hi_key="control_rate_hz")
    video: bool = param(False, "render video.mp4 at the end of the run (needs EGL or OSMesa)")
    video_fps: int = param(30, "video frames per second of simulated time", unit="frames/s", lo=1, hi=240)
    video_width: int = param(480, "video width", unit="px", lo=16, hi=4096)
    video_height: int = param(360, "video height", unit="px", lo=16, hi=4096)
    qps: bool = param(False, "save every tick's QP and the solution used to qps.npz (replay: "
                             "taslel_bench.qp.replay)")
    qps_every: int = param(1, "with qps: keep every k-th control tick", lo=1)
    reference_every: int = param(10, "a tight reference solve of the backend's QP on every k-th filtered tick, off "
                                     "the clock (u_error_nm_max/p99, qp_wrong_rate); 0: off", lo=0)
    reference_tol_nm: float = param(1.0e-3, "a solved answer whose u is farther than this from the reference is "
                                            "wrong", unit="N·m", lo=0.0, lo_open=True)


# -------------------------------------------------------------------------------------------------- robot
@dataclass
class PlantNamesConfig:
    """``robot.plant_names``: with ``robot.plant_mjcf`` only, its element names where they differ from the core's."""

    joints: Any = param(default_of(PlantNames, "joints"), "null (core names FL_hip_joint ...), {core name: name in "
                                                         "the file}, or a pattern with {leg} and {joint}")
    actuators: Any = param(default_of(PlantNames, "actuators"), "keyed by core joint name; null: the one actuator "
                                                               "driving each joint (servos become torque motors)")
    feet: Any = param(default_of(PlantNames, "feet"), "sphere foot geoms: null (FL_foot ...), a mapping or a "
                                                     "pattern with {leg}")
    trunk: str | None = param(default_of(PlantNames, "trunk"), "the body carrying the free joint (null: trunk)")
    floor: str | None = param(default_of(PlantNames, "floor"), "a world-body geom used as the floor (null: the "
                                                               "file's only plane, else one is added)")


@dataclass
class PlantOverridesConfig:
    """``robot.plant_overrides``: the plant's contact and integrator settings; null keeps the file's value (the
    time step is always 1/physics_rate_hz); changes are recorded in summary.json."""

    integrator: str | None = param(default_of(PlantOverrides, "integrator"),
                                   "MuJoCo integrator (the URDF plant: implicitfast)", choices=tuple(INTEGRATORS))
    cone: str | None = param(default_of(PlantOverrides, "cone"), "friction cone (elliptic: the friction "
                                                                 "configured is the friction applied)",
                             choices=tuple(CONES))
    noslip_iterations: int | None = param(default_of(PlantOverrides, "noslip_iterations"),
                                          "noslip solver iterations", lo=0, hi=1000)
    impratio: float | None = param(default_of(PlantOverrides, "impratio"), "frictional-to-normal impedance ratio "
                                                                           "(elliptic cone)", lo=0.0, lo_open=True,
                                   hi=100.0)
    contact_solref: list[float] | None = param(default_of(PlantOverrides, "contact_solref"),
                                               "[timeconst s, dampratio] of the four feet and the floor")
    contact_solimp: list[float] | None = param(default_of(PlantOverrides, "contact_solimp"),
                                               "[dmin, dmax, width m, midpoint, power] of the same geoms")
    foot_margin_m: float | None = param(default_of(PlantOverrides, "foot_margin_m"),
                                        "contact margin of the four foot geoms", unit="m", lo=0.0, hi=0.05)


@dataclass
class RobotConfig:
    """``robot``: one of ``conf/robot/<name>.yaml`` (the robot's facts: names, heights, limits), read with its URDF
    by :func:`taslel_bench.robot.description.describe_robot`; keys without a default are the robot file's."""

    name: str = param(MISSING, "the robot's short name (e.g. a1)")
    urdf: str = param(MISSING, "a path, or <distribution>:<path inside it>")
    trunk_link: str = param(MISSING, "URDF link carrying the free joint")
    legs: list[str] = param(MISSING, "the robot's leg prefixes, core order: front-left, front-right, rear-left, "
                                     "rear-right")
    joint_roles: list[str] = param(factory=lambda: _robot_default("joint_roles"),
                                   doc="the robot's words for the abduction, hip-flexion and knee joints")
    joints: str = param(MISSING, "URDF joint names from a leg prefix and a joint word, e.g. {leg}_{joint}_joint")
    feet: str = param(MISSING, "URDF foot links from a leg prefix, e.g. {leg}_foot")
    foot_radius_m: float | None = param(_robot_default("foot_radius_m"),
                                        "null: the foot link's collision sphere in the URDF", unit="m", lo=0.0,
                                        lo_open=True)
    knee_forward: list[bool] = param(factory=lambda: _robot_default("knee_forward"),
                                     doc="per leg: true where the knee points forwards")
    torque_limit_nm: Any = param(_robot_default("torque_limit_nm"), "motor limit (plant ctrlrange, filter bounds): "
                                                                    "one value, 12, or null (URDF effort)",
                                 unit="N·m")
    velocity_limit_radps: Any = param(_robot_default("velocity_limit_radps"),
                                      "joint speed limit: one value, 12, or null (URDF)", unit="rad/s")
    shin_radius_m: float = param(MISSING, "calf capsule radius the leg barriers guard", unit="m", lo=0.0,
                                 lo_open=True)
    shin_axis_fraction: float = param(_robot_default("shin_axis_fraction"),
                                      "guarded shin: knee -> this fraction of the way to the foot centre", lo=0.0,
                                      lo_open=True, hi=1.0)
    stand_height_m: float = param(MISSING, "hip joint -> foot centre height in the stand and in stance", unit="m",
                                  lo=0.0, lo_open=True)
    fall_height_m: float = param(MISSING, "trunk origin below this ends the episode as a fall", unit="m", lo=0.0,
                                 lo_open=True)
    fall_tilt_deg: float = param(_robot_default("fall_tilt_deg"), "trunk tilt beyond this ends the episode as a fall",
                                 unit="deg", lo=0.0, lo_open=True, hi=180.0)
    init_joint_noise_rad: float = param(_robot_default("init_joint_noise_rad"),
                                        "std of the seeded initial joint perturbation", unit="rad", lo=0.0, hi=0.5)
    init_base_vel_noise_mps: float = param(_robot_default("init_base_vel_noise_mps"),
                                           "std of the seeded initial trunk velocity", unit="m/s", lo=0.0, hi=2.0)
    plant_mjcf: str | None = param(None, "path of another MJCF of the robot to simulate; null: the URDF (the "
                                         "controller's model is the model group)")
    plant_names: PlantNamesConfig = param(factory=PlantNamesConfig, doc="plant_mjcf only: its element names")
    plant_overrides: PlantOverridesConfig = param(factory=PlantOverridesConfig,
                                                  doc="the plant's contact and integrator settings")


# -------------------------------------------------------------------------------------------------- model
# generated __init__, __repr__ and __eq__ would spell the keyword ``from`` as an attribute: __init__ below
@dataclass(init=False, repr=False, eq=False)
class ModelConfig:
    """``model``: the controller's model of the robot (Pinocchio), what the filter's M vdot + h = S u + J' lambda
    believes; the defaults are the URDF as is. Joint fields: one number for all 12 leg joints, or 12 in the core
    order; the fields shared with ``scenario=perturbed`` have its meanings and units."""

    urdf: str | None = param(default_of(ModelOptions, "urdf"), "another URDF of the robot (same joint and foot "
                                                               "names); null: the robot's")
    # ``from`` is a Python keyword: the field is declared through the class namespace (a key ``model.from``)
    __annotations__["from"] = "str | None"
    vars()["from"] = param(None, "a model file (YAML, a `model:` mapping of these keys, e.g. written by python -m "
                                 "taslel_bench.identify) whose values set them; null: none", unit="path")
    joint_damping: Any = param(default_of(ModelOptions, "joint_damping"), "viscous joint loss added to the URDF's: "
                                                                          "h += d qdot", unit="N·m·s/rad")
    armature: Any = param(default_of(ModelOptions, "armature"), "rotor inertia added to the joint's diagonal "
                                                                "entry of M", unit="kg·m²")
    joint_frictionloss: Any = param(default_of(ModelOptions, "joint_frictionloss"),
                                    "Coulomb joint friction added to the URDF's: h += F tanh(qdot / v_eps)", unit="N·m")
    frictionloss_smoothing_radps: float = param(default_of(ModelOptions, "frictionloss_smoothing_radps"),
                                                "v_eps of that tanh", unit="rad/s", lo=0.0, lo_open=True, hi=10.0)
    trunk_mass_scale: float = param(default_of(ModelOptions, "trunk_mass_scale"),
                                    "the trunk link's mass and inertia (about its CoM) scaled together")
    trunk_com_shift_m: list[float] = param(factory=lambda: _as_list(default_of(ModelOptions, "trunk_com_shift_m")),
                                           doc="trunk link CoM shift, trunk frame", unit="m")
    payload_mass_kg: float = param(default_of(ModelOptions, "payload_mass_kg"), "point mass fixed to the trunk ...",
                                   unit="kg")
    payload_pos_m: list[float] = param(factory=lambda: _as_list(default_of(ModelOptions, "payload_pos_m")),
                                       doc="... at this position, trunk frame", unit="m")
    implicit_damping_dt_s: float = param(default_of(ModelOptions, "implicit_damping_dt_s"),
                                         "dt x damping on the joint diagonal of M, as MuJoCo's implicit integrators "
                                         "(the physics step); 0: continuous model", unit="s", lo=0.0, hi=0.1)

    def __init__(self, **values: Any) -> None:
        """Every field at its default, ``values`` (by key, ``from`` included) instead where given."""
        for f in dataclasses.fields(self):
            default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
            setattr(self, f.name, values.pop(f.name, default))
        if values:
            raise TypeError(f"ModelConfig: unknown keys {sorted(values)}")


# ------------------------------------------------------------------------------------------------- filter
@dataclass
class EcbfConfig:
    """``filter.ecbf``: the gains every barrier family uses."""

    enabled: bool = param(default_of(FilterSettings, "ecbf_enabled"), "false drops all barrier rows")
    alpha1: float = param(default_of(FilterSettings, "ecbf_alpha1"), "first ECBF gain", unit="1/s", lo=0.0,
                          lo_open=True, hi_key="control_rate_hz", why=RATE_BOUND)
    alpha2: float = param(default_of(FilterSettings, "ecbf_alpha2"), "second ECBF gain", unit="1/s", lo=0.0,
                          lo_open=True, hi_key="control_rate_hz", why=RATE_BOUND)


@dataclass
class ContactEstimateConfig:
    """``filter.contact_estimate``: the stance estimate of ``stance_source: estimate``."""

    force_threshold_n: float = param(default_of(ContactEstimateSettings, "force_threshold_n"),
                                     "contact force norm that makes a late-swing foot a stance foot", unit="N",
                                     lo=0.0, hi=1000.0)
    min_swing_phase: float = param(default_of(ContactEstimateSettings, "min_swing_phase"),
                                   "earlier in the swing a force is a scuff, not a touchdown", lo=0.0, hi=1.0)
    min_force_vertical_share: float = param(default_of(ContactEstimateSettings, "min_force_vertical_share"),
                                            "f_z / |f| of a touchdown (a toe stubbed on a riser is pushed back)",
                                            lo=0.0, hi=1.0)
    late_touchdown_max_s: float = param(default_of(ContactEstimateSettings, "late_touchdown_max_s"),
                                        "a scheduled stance foot not loaded yet stays swing up to this long (0: off)",
                                        unit="s", lo=0.0, hi=1.0)


@dataclass
class FilterConfig:
    """``filter``: the ID-CBF-QP safety filter (the paper's rows by default; ``filter=terrain`` is the variant
    beyond the paper)."""

    enabled: bool = param(default_of(FilterSettings, "enabled"), "false: the nominal torques pass unfiltered")
    start_time: float = param(0.0, "episode time the filter starts (before: the nominal passes)", unit="s", lo=0.0,
                              hi=MAX_DURATION_S)
    regularization: float = param(default_of(FilterSettings, "regularization"), "eps on vdot and lambda in P",
                                  lo=0.0, lo_open=True, hi=1.0)
    regularization_target: str = param(default_of(FilterSettings, "regularization_target"),
                                       "nominal (no bias on u when nothing binds) | zero (textbook, biased)",
                                       choices=REGULARIZATION_TARGETS)
    lambda_min_n: float = param(default_of(FilterSettings, "lambda_min_n"), "minimum normal force of a stance foot",
                                unit="N", lo=0.0, hi=100.0, why="about the A1's weight")
    contact_velocity_gain: float = param(default_of(FilterSettings, "contact_velocity_gain"),
                                         "k_v of the stance rows J vdot + J̇v = -k_v J v; 0: the paper's eq. (3)",
                                         unit="1/s", lo=0.0, hi_key="control_rate_hz", why=RATE_BOUND)
    ecbf: EcbfConfig = param(factory=EcbfConfig, doc="exponential CBF gains")
    barriers: dict[str, Any] = param(factory=dict, doc="barrier families, rows in this order (name: {_target_: "
                                                       "<Barrier class>, options}; null drops one)")
    fallback: str = param(default_of(FilterSettings, "fallback"), "on QP failure: nominal (pass u_nom) | "
                                                                  "hold_last (last filtered u)", choices=FALLBACKS)
    stance_source: str = param(default_of(FilterSettings, "stance_source"), "schedule (the controller's plan) | "
                                                                            "contact (plant contact flags) | "
                                                                            "estimate (plan + foot forces)",
                               choices=STANCE_SOURCES)
    formulation: str = param(default_of(FilterSettings, "formulation"),
                             "condensed (equalities eliminated, the backend solves in u only) | full (the paper's QP "
                             "in X = (vdot, u, lambda))", choices=FORMULATIONS)
    friction_cone: str = param(default_of(FilterSettings, "friction_cone"),
                               "pyramid (the paper's: world z, one mu) | terrain (per foot about the terrain normal)",
                               choices=FRICTION_CONES)
    cone_edge_downhill: bool = param(default_of(FilterSettings, "cone_edge_downhill"),
                                     "terrain cone: a pyramid edge down the slope (full mu there), not world x")
    cone_edge_along_nominal: bool = param(default_of(FilterSettings, "cone_edge_along_nominal"),
                                          "terrain cone: each stance pyramid turned per tick so an edge lies along "
                                          "the nominal's tangential force on that foot (full mu where it pushes)")
    release_lifted_feet: bool = param(default_of(FilterSettings, "release_lifted_feet"),
                                      "a stance foot the nominal torques pull off the ground (normal force under "
                                      "the stance model below lambda_min) is swing for that tick")
    relaxation: str = param(default_of(FilterSettings, "relaxation"),
                            "none (infeasible QP -> fallback) | priority (drop barrier families, last first)",
                            choices=RELAXATIONS)
    correction_limit_stance_nm: float | None = param(None, "|u - u_nom| at most this per joint of a stance leg "
                                                           "(null: no limit, the paper's)", unit="N·m", lo=0.0)
    correction_limit_swing_nm: float | None = param(None, "|u - u_nom| at most this per joint of a swing leg "
                                                          "(null: no limit, the paper's)", unit="N·m", lo=0.0)
    correction_limit_stance_unless_sliding: bool = param(False, "the stance limit is lifted for a leg whose "
                                                                 "foot the nominal's force would slide (outside "
                                                                 "its cone at the estimate's mu, no margin)")
    sliding_ratio_max: float | None = param(None, "with the option above: a stance foot whose nominal force is beyond "
                                                  "this ratio of tangential to normal is neither held nor moved: "
                                                  "out of the contact model, its leg at u_nom (null: every sliding "
                                                  "foot is held)", lo=0.0, lo_open=True)
    support_min_normal_z: float | None = param(None, "a stance foot whose terrain normal has n_z below this gets no "
                                                     "contact rows or cone (a toe on a riser face; null: off)",
                                               lo=-1.0, hi=1.0)
    robust: RobustConfig = param(factory=RobustConfig, doc="margins for a wrong model (off: the paper's rows)")
    contact_estimate: ContactEstimateConfig = param(factory=ContactEstimateConfig,
                                                    doc="the stance estimate of stance_source: estimate")


# --------------------------------------------------------------------------------------------- controller
@dataclass
class TrotScalingConfig:
    """``controller.scaling``: the trot's values of a robot of mass m [kg] and leg length L [m] (the A1: 0.4 m/s,
    6 cm, 100 N·m/rad, 3 N·m·s/rad)."""

    speed_per_sqrt_leg: float = param(0.6325, "speed = this x sqrt(L) (equal Froude number)", unit="m^0.5/s",
                                      lo=0.0, lo_open=True)
    swing_per_leg: float = param(0.15, "swing height = this x L", lo=0.0, lo_open=True)
    kp_per_mass_leg: float = param(18.19, "kp = this x m L (the torque that holds the robot up)",
                                   unit="N·m/rad per kg·m", lo=0.0, lo_open=True)
    kd_per_sqrt_mass_leg: float = param(1.2796, "kd = this x sqrt(m L)", unit="N·m·s/rad per sqrt(kg·m)", lo=0.0,
                                        lo_open=True)


TROT_TARGET = f"{trot_controller.__module__}.{trot_controller.__name__}"


@dataclass
class TrotConfig:
    """``controller=trot``: the paper's trot for any robot (open-loop foot trajectories in the hip frames, analytic
    IK, joint PD); keys left null take the robot's values from ``scaling``."""

    _target_: str = param(TROT_TARGET, "the builder")
    speed: float | None = param(_trot_default("speed"), "commanded forward speed; null: scaling", unit="m/s")
    period: float = param(0.4, "gait period", unit="s", lo=0.0, lo_open=True, hi=5.0)
    duty: float = param(0.5, "stance fraction", lo=0.0, lo_open=True, hi=1.0, hi_open=True)
    swing_height: float | None = param(_trot_default("swing_height"), "swing apex above the stance height; null: "
                                                                      "scaling", unit="m", lo=0.0, hi=0.2)
    stand_height: float | None = param(_trot_default("stand_height"), "hip joint -> foot centre during stance; "
                                                                      "null: the robot's stand_height_m", unit="m")
    stand_duration: float = param(0.5, "initial stand before walking", unit="s", lo=0.0, hi=60.0)
    kp: float | None = param(_trot_default("kp"), "joint PD stiffness; null: scaling", unit="N·m/rad")
    kd: float | None = param(_trot_default("kd"), "joint PD damping; null: scaling", unit="N·m·s/rad")
    scaling: TrotScalingConfig = param(factory=TrotScalingConfig, doc="the robot's values from its mass and legs")
    terrain_following: bool = param(_trot_default("terrain_following"),
                                    "foot targets follow the ground under each foot (beyond the paper)")
    foothold_search: float = param(_trot_default("foothold_search"), "> 0 (with terrain_following): each touchdown "
                                                                     "may move up to this along the heading",
                                   unit="m", lo=0.0, hi=0.08, why="half the 0.16 m between touchdowns of one foot")
    foothold_replan_phase: float = param(_trot_default("foothold_replan_phase"),
                                         "in (0, 1): the touchdown is chosen again at this swing phase (0: at "
                                         "lift-off only)", lo=0.0, hi=1.0, hi_open=True)
    swing_from_measured_hips: bool = param(_trot_default("swing_from_measured_hips"),
                                           "(with terrain_following) swing-foot heights from the measured hips")
    touchdown_height: float = param(_trot_default("touchdown_height"),
                                    "> 0 (with terrain_following): each swing ends this far above the expected "
                                    "ground, then descends over the stance's first 30 ms", unit="m", lo=0.0, hi=0.03)


POLICY_TARGET = f"{policy_controller.__module__}.{policy_controller.__name__}"
_PLAN = PlanEstimateSettings()


@dataclass
class PlanEstimateConfig:
    """``controller.plan``: the contact plan estimated from joint torques, kinematics and the IMU (a policy has no
    gait clock; :mod:`taslel_bench.control.contact_plan_estimate`)."""

    touchdown_force_n: float = param(_PLAN.touchdown_force_n, "estimated vertical ground force above which a swing "
                                     "foot has landed", unit="N", lo=0.0, lo_open=True, hi=1e4)
    liftoff_force_n: float = param(_PLAN.liftoff_force_n, "below which a stance foot has lifted off (below "
                                   "touchdown_force_n)", unit="N", lo=0.0, hi=1e4)
    min_stance_s: float = param(_PLAN.min_stance_s, "shortest stance (debounce)", unit="s", lo=0.0, hi=1.0)
    min_swing_s: float = param(_PLAN.min_swing_s, "shortest swing (debounce)", unit="s", lo=0.0, hi=1.0)


@dataclass
class PolicyControllerConfig:
    """``controller=policy``: a learned policy (ONNX, run with onnxruntime) under its contract, the ``policy`` group
    (``policy=<name>``, ``conf/policy/<name>.yaml``)."""

    _target_: str = param(POLICY_TARGET, "the builder")
    contract: Any = param("${policy}", "the policy's contract (the policy group's node)")
    command: list[float] = param(factory=lambda: [0.5, 0.0, 0.0], doc="velocity command after the stand: forward "
                                 "[m/s], lateral [m/s], yaw rate [rad/s]")
    stand_duration: float = param(0.5, "initial stand (the policy runs with a zero command)", unit="s", lo=0.0,
                                  hi=60.0)
    plan: PlanEstimateConfig = param(factory=PlanEstimateConfig, doc="the estimated contact plan")


CONTROLLER_SCHEMAS: dict[str, type] = {TROT_TARGET: TrotConfig, POLICY_TARGET: PolicyControllerConfig}


# --------------------------------------------------------------------------------------------------- root
@dataclass
class RunConfig:
    """The run config: one MuJoCo episode of a quadruped (``conf/config.yaml`` picks the groups' options)."""

    robot: RobotConfig = param(MISSING, "the robot (conf/robot/<name>.yaml)")
    model: ModelConfig = param(factory=ModelConfig, doc="the controller's model of the robot")
    controller: Any = param(MISSING, "the nominal controller (conf/controller/)")
    policy: Any = param(None, "a learned policy's contract (conf/policy/<name>.yaml), read by controller=policy")
    filter: FilterConfig = param(factory=FilterConfig, doc="the safety filter")
    scenario: Any = param(MISSING, "the world (conf/scenario/)")
    solver: Any = param(MISSING, "the QP backend (conf/solver/)")
    estimator: Any = param(MISSING, "the friction estimator (conf/estimator/)")
    tracker: Any = param(None, "the sweep's experiment tracker (not part of a run's config)")
    seed: int = param(0, "controls all randomness (initial-state perturbation, scenario draws)", lo=0,
                      hi=2**63 - 1)
    duration: float = param(10.0, "walking time after the initial stand", unit="s", lo=0.0, lo_open=True,
                            hi=MAX_DURATION_S)
    physics_rate_hz: int = param(1000, "MuJoCo step rate", unit="Hz", lo=100, hi=100_000,
                                 why="MuJoCo is unstable on these robots beyond 10 ms steps")
    control_rate_hz: int = param(1000, "controller and filter rate; must divide physics_rate_hz", unit="Hz", lo=10,
                                 hi_key="physics_rate_hz")
    record: RecordConfig = param(factory=RecordConfig, doc="what a run writes beside its summary")
    health: HealthConfig = param(factory=HealthConfig, doc="a run that crosses one of these ends degraded, not ok")
    safety: SafetyConfig = param(factory=SafetyConfig, doc="the verdict's limits: summary.json safe and "
                                                           "unsafe_reasons")
    max_memory_gb: float = param(8.0, "refuse a run whose estimated peak memory exceeds this", unit="GB", lo=0.0,
                                 lo_open=True, hi=1e4)
    force: bool = param(False, "rerun even if the run folder already holds a complete summary.json")
    progress: bool = param(True, "print simulated time while running")


SCHEMA_NAME = "run_schema"  # conf/config.yaml's first default


def load_run_config(path: Path) -> DictConfig:
    """A run folder's ``config.yaml`` over the schema: a key the run's version did not write yet takes the schema's
    default (a run written before robots were described was an A1 run); a key the schema no longer has is refused,
    naming the file."""
    saved = OmegaConf.load(path)
    if not isinstance(saved, DictConfig):
        raise ConfigError(f"{path}: not a run config (a mapping)")
    if isinstance(saved.get("robot"), DictConfig):
        saved.robot = complete_robot_node(plain_dict(saved.robot, "robot"))
    try:
        merged = OmegaConf.merge(OmegaConf.structured(RunConfig), saved)
    except (ValidationError, ConfigKeyError) as exc:
        raise ConfigError(f"{path}: not a run config of this version: {str(exc).splitlines()[0]}") from None
    assert isinstance(merged, DictConfig)
    return merged


def register() -> None:
    """Store the schema in Hydra's ConfigStore: ``run_schema`` (the root) and ``schema/controller/trot`` (the trot
    options' base). Idempotent; called before any composition."""
    store = ConfigStore.instance()
    store.store(name=SCHEMA_NAME, node=RunConfig)
    store.store(group="schema/controller", name="trot", node=TrotConfig)
    store.store(group="schema/controller", name="policy", node=PolicyControllerConfig)


register()
