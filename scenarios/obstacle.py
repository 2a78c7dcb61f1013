"""Swing-foot obstacle profile z(s) for the ground-clearance ECBF (paper, "Ground Clearance")."""

from __future__ import annotations

from collections.abc import Sequence

from scenarios.flat import FlatGround
from taslel_bench.interfaces import ClearanceProfile, fail, number, numbers

MAX_HEIGHT_M = 0.2  # [m] highest obstacle under a swing foot (the trot lifts the feet 6 cm; legs are 0.4 m)


def bump_coefficients(height_m: float) -> tuple[float, ...]:
    """4th-order bump 16 H s² (1 - s)²: zero with zero slope at lift-off and touch-down, peak H at s = 0.5."""
    return (0.0, 0.0, 16.0 * height_m, -32.0 * height_m, 16.0 * height_m)


class ObstacleProfile(FlatGround):
    """Flat floor plus a clearance profile every swing foot must stay above.

    ``coefficients`` (polynomial in the swing phase s, lowest order first) [m] override ``height_m``;
    null means the default bump of ``height_m``. Both are checked: ``height_m`` in [0, MAX_HEIGHT_M],
    ``coefficients`` at least 3 finite numbers (order >= 2) whose profile peaks at most MAX_HEIGHT_M.
    The profile is a virtual obstacle in each swing (the paper's z(phi)); no geometry is added to the plant.
    """

    def __init__(
        self,
        name: str = "obstacle",
        friction: float = 1.0,
        height_m: float = 0.08,
        coefficients: Sequence[float] | None = None,
    ) -> None:
        super().__init__(name=name, friction=friction)
        height = number("scenario.height_m", height_m, 0.0, MAX_HEIGHT_M, unit="m")
        if coefficients is None:
            self.profile = ClearanceProfile(bump_coefficients(height))
            return
        self.profile = checked_profile(coefficients)

    def clearance_profile(self) -> ClearanceProfile | None:
        return self.profile


def checked_profile(coefficients: Sequence[float]) -> ClearanceProfile:
    """The virtual profile of ``scenario.coefficients``: at least 3 finite numbers (order >= 2) whose
    profile peaks at most MAX_HEIGHT_M over the swing (raises naming the field)."""
    coeffs = numbers("scenario.coefficients", coefficients, min_length=3, unit="m",
                     why="z(s) lowest order first, order >= 2 for the ECBF's curvature; null for the "
                         "default bump of height_m")  # fmt: skip
    profile = ClearanceProfile(coeffs)
    if profile.peak_m > MAX_HEIGHT_M:
        peak = f"the profile peaks at {profile.peak_m:.3g} m over the swing"
        raise fail("scenario.coefficients", coefficients, f"{peak}; must be <= {MAX_HEIGHT_M} m")
    return profile
