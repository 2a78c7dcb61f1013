"""Estimators without a model: the oracle (reads the true friction) and a fixed constant."""

from __future__ import annotations

from taslel_bench.interfaces import MAX_FRICTION, FrictionEstimate, GroundTruth, Proprioception, number


class OracleEstimator:
    """Returns the true ground friction under the robot every tick (upper bound of any estimator): the one
    estimator that reads the simulator's ground truth."""

    name = "oracle"
    reads_ground_truth = True

    def reset(self) -> None:
        """Nothing to forget."""

    def step(self, obs: Proprioception, truth: GroundTruth) -> FrictionEstimate:
        """``mu`` = the friction under the trunk [-], ``sigma`` = 0, always ready; the friction under each foot
        when the truth carries it."""
        return FrictionEstimate(mu=float(truth.friction_under_trunk), sigma=0.0, ready=True,
                                mu_per_foot=truth.friction_per_foot)


SAFE_FLOOR_MU = 0.2  # [-] lowest floor friction the deployment must handle (the filtered trot falls below it)


class FixedEstimator:
    """Always returns the same friction coefficient ``mu`` [-] (the filter without terrain awareness); by
    default the safe floor :data:`SAFE_FLOOR_MU`, which never over-estimates a floor the deployment handles."""

    name = "fixed"

    def __init__(self, mu: float = SAFE_FLOOR_MU) -> None:
        self.mu = number("estimator.mu", mu, 0.0, MAX_FRICTION, lo_open=True,
                         why="a positive friction coefficient")

    def reset(self) -> None:
        """Nothing to forget."""

    def step(self, obs: Proprioception) -> FrictionEstimate:
        """The configured constant, ``sigma`` = 0, always ready."""
        return FrictionEstimate(mu=self.mu, sigma=0.0, ready=True)
