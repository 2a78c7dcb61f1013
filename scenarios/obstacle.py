"""Swing-foot obstacle profile z(s) for the ground-clearance ECBF (paper, "Ground Clearance")."""

from __future__ import annotations

from collections.abc import Sequence

from scenarios.flat import FlatGround
from taslel_bench.interfaces import ClearanceProfile


def bump_coefficients(height_m: float) -> tuple[float, ...]:
    """4th-order bump 16 H s² (1 - s)²: zero with zero slope at lift-off and touch-down, peak H at s = 0.5."""
    return (0.0, 0.0, 16.0 * height_m, -32.0 * height_m, 16.0 * height_m)


class ObstacleProfile(FlatGround):
    """Flat floor plus a clearance profile every swing foot must stay above.

    ``coefficients`` (polynomial in the swing phase s, lowest order first) [m] override ``height_m``.
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
        coeffs = tuple(float(c) for c in coefficients) if coefficients else bump_coefficients(height_m)
        if len(coeffs) < 3:
            raise ValueError(
                f"scenario.coefficients must give a polynomial of order >= 2 (twice differentiable "
                f"profile with curvature), got {coeffs}"
            )
        self.profile = ClearanceProfile(coeffs)

    def clearance_profile(self) -> ClearanceProfile | None:
        return self.profile
