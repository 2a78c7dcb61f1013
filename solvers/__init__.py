"""QP backends for the ID-CBF-QP safety filter (sweep axis 2).

Every backend implements :class:`taslel_bench.interfaces.QPBackend`: ``solve(problem) -> QPSolution``
(never raises for solver failures), ``reset()`` and ``describe()``. Two routes:

* the solver as a controller deploys it (``solver=osqp``, ``clarabel``, ``piqp``, ``proxqp``, ``daqp``):
  persistent native backends that set the solver up once per QP layout, then update values each tick and
  warm start where the solver can (Clarabel, an interior point, keeps only its setup);
* :class:`solvers.qpsolvers_backend.QpsolversBackend` -- any solver installed behind ``qpsolvers``, set up
  from scratch on every call (``solver=qpsolvers solver.name=<name>``; ``solver=quadprog``).

Every returned solution is checked against the *original* problem (primal residual, dual residual and
duality gap, :mod:`solvers.checks`): a solver that claims success with a bad answer gets a non-solved status.
Build backends by name with :func:`solvers.registry.make_backend` or from Hydra (``conf/solver/*.yaml``).
"""

from solvers.base import BackendSolution
from solvers.checks import Tolerances
from solvers.registry import available_backends, make_backend

__all__ = ["BackendSolution", "Tolerances", "available_backends", "make_backend"]
