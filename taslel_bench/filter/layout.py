"""The ID-CBF-QP's decision variables and what every constraint family reads each tick.

Decision variables X = (vdot [18], u [12], lambda [12]):
  * vdot: generalised acceleration in Pinocchio's convention (trunk-frame linear/angular, joints);
  * u: joint torques [N·m], core joint order;
  * lambda: contact forces [N] of the four feet (LEGS order) **on the robot, in world axes**, applied at
    the foot-sphere centre. A swing foot's lambda is constrained to zero so the layout never changes.

The layout is fixed for an episode (42 variables, 30 equality rows, 20 friction rows + 4 rows per barrier
family), which lets persistent solvers keep one sparsity pattern for a whole episode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.model import RobotModel

NV, NU, NL = quad.NV, quad.N_JOINTS, 3 * quad.N_LEGS
VDOT, U, LAM = slice(0, NV), slice(NV, NV + NU), slice(NV + NU, NV + NU + NL)
N_VARS = NV + NU + NL
INACTIVE_RHS = 1e6  # right-hand side of an inactive inequality row (0 <= 1e6); finite for every solver


@dataclass
class TickInputs:
    """What the constraint families read each tick (model already updated at (q, v))."""

    model: RobotModel
    v: np.ndarray  # Pinocchio velocity (18)
    in_stance: np.ndarray  # bool (4,)
    mu: float  # [-] friction coefficient the filter assumes
    swing_phase: np.ndarray  # [-] (4,) progress of each swing in [0, 1]
    swing_phase_rate: float  # [1/s]
    mu_per_foot: np.ndarray | None = None  # [-] (4,) friction under each foot (None: ``mu`` for all four)

    def with_mu_scaled(self, factor: float) -> TickInputs:
        """A copy with ``mu`` and, where given, every foot's ``mu_per_foot`` multiplied by ``factor`` [-] (the
        friction margin: the per-foot cones shrink with the single value they replace); built field by field,
        ~1 µs instead of ~5 µs for ``dataclasses.replace`` (tests/test_terrain_kernels.py checks the fields)."""
        feet = None if self.mu_per_foot is None else self.mu_per_foot * factor
        return TickInputs(self.model, self.v, self.in_stance, self.mu * factor, self.swing_phase,
                          self.swing_phase_rate, feet)
