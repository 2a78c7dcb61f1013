"""Domain randomisation for data collection: ranges, per-episode draws, and how they edit the plant.

One :class:`EpisodeParams` is one world + one controller: ground friction, what a real A1 varies
(payload / trunk mass and CoM, joint damping and friction loss, motor strength) and what the operator
varies (PD gains, commanded speed, gait period, swing height). Draws use an explicit
``np.random.Generator``. The *shifted* ranges lie outside the training ranges (heavier payload, larger CoM
offset, more joint damping / friction loss, weaker motors) to test robustness, never friction itself.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import mujoco
import numpy as np

from taslel_bench.robot import a1

Range = tuple[float, float]


@dataclass(frozen=True)
class Ranges:
    """Uniform ranges (lo, hi) of every randomised quantity."""

    friction: Range = (0.1, 1.2)  # [-] floor Coulomb coefficient
    trunk_mass_scale: Range = (0.85, 1.5)  # [-] trunk mass and inertia x scale (payload up to +3 kg)
    com_shift_xy_m: Range = (-0.03, 0.03)  # [m] trunk CoM offset, x and y drawn independently
    joint_damping: Range = (0.0, 0.2)  # [N·m·s/rad] every leg joint
    joint_frictionloss: Range = (0.0, 0.3)  # [N·m] every leg joint
    motor_strength: Range = (0.85, 1.1)  # [-] actuator gear scale (delivered / commanded torque)
    kp_scale: Range = (0.8, 1.2)  # [-] x nominal Kp (100 N·m/rad)
    kd_scale: Range = (0.7, 1.3)  # [-] x nominal Kd (3 N·m·s/rad)
    speed_mps: Range = (0.1, 0.5)  # [m/s] commanded forward speed
    period_s: Range = (0.3, 0.5)  # [s] trot period
    swing_height_m: Range = (0.04, 0.08)  # [m] swing apex


TRAIN_RANGES = Ranges()

# Outside the training ranges in every plant-side quantity (friction and operator settings unchanged).
SHIFTED_RANGES = Ranges(
    trunk_mass_scale=(1.6, 1.8),
    com_shift_xy_m=(0.03, 0.05),  # magnitude; the sign is drawn separately
    joint_damping=(0.2, 0.35),
    joint_frictionloss=(0.3, 0.5),
    motor_strength=(0.75, 0.85),
)


@dataclass(frozen=True)
class EpisodeParams:
    """One episode's draw (units as in :class:`Ranges`)."""

    seed: int
    friction: float
    trunk_mass_scale: float
    com_shift_x_m: float
    com_shift_y_m: float
    joint_damping: float
    joint_frictionloss: float
    motor_strength: float
    kp_scale: float
    kd_scale: float
    speed_mps: float
    period_s: float
    swing_height_m: float

    def as_row(self) -> list[float]:
        return [float(getattr(self, f.name)) for f in fields(self)]

    @staticmethod
    def columns() -> list[str]:
        return [f.name for f in fields(EpisodeParams)]


PLANT_FACTORS = ("trunk_mass_scale", "com_shift_xy_m", "joint_damping", "joint_frictionloss", "motor_strength")


def shifted_ranges(factors: tuple[str, ...] | list[str] = PLANT_FACTORS) -> Ranges:
    """:data:`SHIFTED_RANGES` for the given plant factors, the training ranges for the others (one-factor
    shifts show which plant change an estimator does not survive). The CoM offset of the shifted split is
    a magnitude with a random sign, so an unshifted CoM gets the training band as magnitude (0, 0.03)."""
    if bad := [f for f in factors if f not in PLANT_FACTORS]:
        raise ValueError(f"unknown plant factor(s) {bad}; valid factors: {', '.join(PLANT_FACTORS)}")
    if not factors:
        raise ValueError(f"give at least one plant factor to shift; valid factors: {', '.join(PLANT_FACTORS)}")
    moved = {f: getattr(SHIFTED_RANGES, f) for f in factors}
    if "com_shift_xy_m" not in moved:
        moved["com_shift_xy_m"] = (0.0, TRAIN_RANGES.com_shift_xy_m[1])
    return replace(TRAIN_RANGES, **moved)


def draw(rng: np.random.Generator, ranges: Ranges, seed: int, symmetric_com: bool = True,
         plant_beta: float = 1.0) -> EpisodeParams:
    """Draw one episode. ``symmetric_com=False`` reads ``com_shift_xy_m`` as a magnitude range and draws
    the sign (used for the shifted set, whose offsets lie outside the symmetric training band).

    ``plant_beta`` = a: the :data:`PLANT_FACTORS` are drawn as lo + (hi - lo) x Beta(a, a) instead of
    uniformly (a = 1, the default, is the uniform draw, unchanged stream). a < 1 puts more episodes near
    the edges of each range, so corners of the box (heavy trunk *and* weak motors *and* stiff joints),
    rare under independent uniform draws, are seen in training; the ranges themselves do not change."""
    if plant_beta <= 0:
        raise ValueError(f"plant_beta must be > 0, got {plant_beta!r}")

    def u(r: Range) -> float:
        return float(rng.uniform(r[0], r[1]))

    def plant(r: Range) -> float:
        return u(r) if plant_beta == 1.0 else float(r[0] + (r[1] - r[0]) * rng.beta(plant_beta, plant_beta))

    if symmetric_com:
        cx, cy = plant(ranges.com_shift_xy_m), plant(ranges.com_shift_xy_m)
    else:
        cx, cy = (plant(ranges.com_shift_xy_m) * float(rng.choice([-1.0, 1.0])) for _ in range(2))
    return EpisodeParams(
        seed=seed,
        friction=u(ranges.friction),
        trunk_mass_scale=plant(ranges.trunk_mass_scale),
        com_shift_x_m=cx,
        com_shift_y_m=cy,
        joint_damping=plant(ranges.joint_damping),
        joint_frictionloss=plant(ranges.joint_frictionloss),
        motor_strength=plant(ranges.motor_strength),
        kp_scale=u(ranges.kp_scale),
        kd_scale=u(ranges.kd_scale),
        speed_mps=u(ranges.speed_mps),
        period_s=u(ranges.period_s),
        swing_height_m=u(ranges.swing_height_m),
    )


class PlantRandomiser:
    """Applies :class:`EpisodeParams` to a compiled plant in place (no recompilation per episode).

    Keeps the nominal values of every field it touches so each episode starts from the nominal plant.
    """

    def __init__(self, model: mujoco.MjModel, floor_geom: str = "floor") -> None:
        self.model = model
        self.floor_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, floor_geom)
        self.trunk_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, a1.TRUNK_BODY)
        if self.floor_id < 0 or self.trunk_id < 0:
            raise ValueError(f"plant has no geom {floor_geom!r} or body {a1.TRUNK_BODY!r}")
        leg_joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in a1.JOINT_NAMES]
        self.leg_dofs = np.array([model.jnt_dofadr[j] for j in leg_joints])
        self._nominal = {
            "body_mass": model.body_mass.copy(),
            "body_inertia": model.body_inertia.copy(),
            "body_ipos": model.body_ipos.copy(),
            "dof_damping": model.dof_damping.copy(),
            "dof_frictionloss": model.dof_frictionloss.copy(),
            "actuator_gear": model.actuator_gear.copy(),
            "geom_friction": model.geom_friction.copy(),
        }

    def apply(self, p: EpisodeParams) -> None:
        m, b = self.model, self.trunk_id
        for name, value in self._nominal.items():
            getattr(m, name)[:] = value
        m.geom_friction[self.floor_id, 0] = p.friction
        m.body_mass[b] *= p.trunk_mass_scale
        m.body_inertia[b] *= p.trunk_mass_scale
        m.body_ipos[b, 0] += p.com_shift_x_m
        m.body_ipos[b, 1] += p.com_shift_y_m
        m.dof_damping[self.leg_dofs] = p.joint_damping
        m.dof_frictionloss[self.leg_dofs] = p.joint_frictionloss
        m.actuator_gear[:, 0] = p.motor_strength


def ranges_dict(r: Ranges) -> dict[str, list[float]]:
    return {k: list(v) for k, v in asdict(r).items()}
