"""Domain randomisation for data collection: ranges and per-episode draws.

One :class:`EpisodeParams` is one world + one controller: ground friction, what a real A1 varies
(payload / trunk mass and CoM, joint damping and friction loss, motor strength: the fields of the core's
:class:`taslel_bench.interfaces.PlantPerturbation`, with its names and units, applied by its one
implementation) and what the operator varies (PD gains, commanded speed, gait period, swing height). Draws
use an explicit ``np.random.Generator``. The *shifted* ranges lie outside the training ranges (heavier
payload, larger CoM offset, more joint damping / friction loss, weaker motors) to test robustness, never
friction itself.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from taslel_bench.interfaces import PlantPerturbation

Range = tuple[float, float]


@dataclass(frozen=True)
class Ranges:
    """Uniform ranges (lo, hi) of every randomised quantity."""

    friction: Range = (0.1, 1.2)  # [-] floor Coulomb coefficient
    trunk_mass_scale: Range = (0.85, 1.5)  # [-] trunk mass and inertia x scale (payload up to +3 kg)
    trunk_com_shift_xy_m: Range = (-0.03, 0.03)  # [m] trunk CoM offset, x and y drawn independently
    joint_damping: Range = (0.0, 0.2)  # [N·m·s/rad] every leg joint
    joint_frictionloss: Range = (0.0, 0.3)  # [N·m] every leg joint
    motor_strength_scale: Range = (0.85, 1.1)  # [-] actuator gear scale (delivered / commanded torque)
    kp_scale: Range = (0.8, 1.2)  # [-] x nominal Kp (100 N·m/rad)
    kd_scale: Range = (0.7, 1.3)  # [-] x nominal Kd (3 N·m·s/rad)
    speed_mps: Range = (0.1, 0.5)  # [m/s] commanded forward speed
    period_s: Range = (0.3, 0.5)  # [s] trot period
    swing_height_m: Range = (0.04, 0.08)  # [m] swing apex


TRAIN_RANGES = Ranges()

# Outside the training ranges in every plant-side quantity (friction and operator settings unchanged).
SHIFTED_RANGES = Ranges(
    trunk_mass_scale=(1.6, 1.8),
    trunk_com_shift_xy_m=(0.03, 0.05),  # magnitude; the sign is drawn separately
    joint_damping=(0.2, 0.35),
    joint_frictionloss=(0.3, 0.5),
    motor_strength_scale=(0.75, 0.85),
)


@dataclass(frozen=True)
class EpisodeParams:
    """One episode's draw (units as in :class:`Ranges`)."""

    seed: int
    friction: float
    trunk_mass_scale: float
    trunk_com_shift_x_m: float
    trunk_com_shift_y_m: float
    joint_damping: float
    joint_frictionloss: float
    motor_strength_scale: float
    kp_scale: float
    kd_scale: float
    speed_mps: float
    period_s: float
    swing_height_m: float

    def perturbation(self) -> PlantPerturbation:
        """The plant edits of this draw (on the URDF's values, which are 0 for the joint losses)."""
        return PlantPerturbation(
            trunk_mass_scale=self.trunk_mass_scale,
            trunk_com_shift_m=(self.trunk_com_shift_x_m, self.trunk_com_shift_y_m, 0.0),
            joint_damping=(self.joint_damping,) * 12,
            joint_frictionloss=(self.joint_frictionloss,) * 12,
            motor_strength_scale=self.motor_strength_scale,
        )

    def as_row(self) -> list[float]:
        return [float(getattr(self, f.name)) for f in fields(self)]

    @staticmethod
    def columns() -> list[str]:
        return [f.name for f in fields(EpisodeParams)]


PLANT_FACTORS = ("trunk_mass_scale", "trunk_com_shift_xy_m", "joint_damping", "joint_frictionloss",
                 "motor_strength_scale")


def shifted_ranges(factors: tuple[str, ...] | list[str] = PLANT_FACTORS) -> Ranges:
    """:data:`SHIFTED_RANGES` for the given plant factors, the training ranges for the others (one-factor
    shifts show which plant change an estimator does not survive). The CoM offset of the shifted split is
    a magnitude with a random sign, so an unshifted CoM gets the training band as magnitude (0, 0.03)."""
    if bad := [f for f in factors if f not in PLANT_FACTORS]:
        raise ValueError(f"unknown plant factor(s) {bad}; valid factors: {', '.join(PLANT_FACTORS)}")
    if not factors:
        raise ValueError(f"give at least one plant factor to shift; valid factors: {', '.join(PLANT_FACTORS)}")
    moved = {f: getattr(SHIFTED_RANGES, f) for f in factors}
    if "trunk_com_shift_xy_m" not in moved:
        moved["trunk_com_shift_xy_m"] = (0.0, TRAIN_RANGES.trunk_com_shift_xy_m[1])
    return replace(TRAIN_RANGES, **moved)


def draw(rng: np.random.Generator, ranges: Ranges, seed: int, symmetric_com: bool = True,
         plant_beta: float = 1.0) -> EpisodeParams:
    """Draw one episode. ``symmetric_com=False`` reads ``trunk_com_shift_xy_m`` as a magnitude range and draws
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
        cx, cy = plant(ranges.trunk_com_shift_xy_m), plant(ranges.trunk_com_shift_xy_m)
    else:
        cx, cy = (plant(ranges.trunk_com_shift_xy_m) * float(rng.choice([-1.0, 1.0])) for _ in range(2))
    return EpisodeParams(
        seed=seed,
        friction=u(ranges.friction),
        trunk_mass_scale=plant(ranges.trunk_mass_scale),
        trunk_com_shift_x_m=cx,
        trunk_com_shift_y_m=cy,
        joint_damping=plant(ranges.joint_damping),
        joint_frictionloss=plant(ranges.joint_frictionloss),
        motor_strength_scale=plant(ranges.motor_strength_scale),
        kp_scale=u(ranges.kp_scale),
        kd_scale=u(ranges.kd_scale),
        speed_mps=u(ranges.speed_mps),
        period_s=round(u(ranges.period_s), 3),  # a whole number of 1 kHz ticks: the controller's tables apply
        swing_height_m=u(ranges.swing_height_m),
    )


def ranges_dict(r: Ranges) -> dict[str, list[float]]:
    return {k: list(v) for k, v in asdict(r).items()}


# ------------------------------------------------------------------------------------- surface patches


@dataclass(frozen=True)
class SurfacePatch:
    """A strip of floor across the path with another friction: world x in [``start_m``, ``start_m`` +
    ``length_m``) has friction ``friction`` [-], the rest of the floor the episode's. The trot starts with
    the trunk at x = 0 (front feet ~0.18 m ahead) and walks along +x."""

    start_m: float  # [m] world x of the near edge
    length_m: float  # [m] along x; a patch longer than the walk is a single step change
    friction: float  # [-]

    def edges_and_frictions(self, floor_mu: float) -> tuple[tuple[float, float], tuple[float, float, float]]:
        """(edges [m], frictions [-]) of the floor strips: floor, patch, floor."""
        return (self.start_m, self.start_m + self.length_m), (floor_mu, self.friction, floor_mu)


@dataclass(frozen=True)
class PatchRanges:
    """How patches are drawn: near edge ~ U(``start_m``), length log-uniform in ``length_m`` (short patches
    cover one or two footfalls, long ones are a step change), friction ~ U(``friction``) resampled until it
    differs from the floor's by at least ``min_change`` [-] (both drops and rises)."""

    start_m: Range = (0.3, 1.3)  # [m]
    length_m: Range = (0.1, 3.0)  # [m]
    friction: Range = (0.1, 1.2)  # [-]
    min_change: float = 0.15  # [-]


PATCH_RANGES = PatchRanges()
PATCH_COLUMNS = ("start_m", "length_m", "friction")  # a collection's per-episode ``patch`` rows (nan: no patch)


def draw_patch(rng: np.random.Generator, floor_mu: float, r: PatchRanges = PATCH_RANGES) -> SurfacePatch:
    """One patch for a floor of friction ``floor_mu`` [-] (see :class:`PatchRanges`)."""
    lo, hi = r.friction
    if max(hi - floor_mu, floor_mu - lo) < r.min_change:
        raise ValueError(f"patch friction range {r.friction} has no value {r.min_change} away from the floor's "
                         f"{floor_mu}")
    start = float(rng.uniform(*r.start_m))
    length = float(np.exp(rng.uniform(np.log(r.length_m[0]), np.log(r.length_m[1]))))
    mu = float(rng.uniform(lo, hi))
    while abs(mu - floor_mu) < r.min_change:
        mu = float(rng.uniform(lo, hi))
    return SurfacePatch(start, length, mu)
