"""QP backends for the ID-CBF-QP safety filter (sweep axis 2).

Every backend implements :class:`taslel_bench.interfaces.QPBackend`: ``solve(problem) -> QPSolution``
(never raises for solver failures), ``reset()`` and ``describe()``. Two families:

* :class:`solvers.qpsolvers_backend.QpsolversBackend` -- any solver installed behind ``qpsolvers``, set up
  from scratch on every call;
* persistent native backends (``osqp_persistent``, ``piqp_persistent``, ``proxqp_persistent``,
  ``daqp_persistent``) that set the solver up once per QP layout, then update values and warm start.

Every returned solution is checked against the *original* problem (primal residual, dual residual and
duality gap, :mod:`solvers.checks`): a solver that claims success with a bad answer gets a non-solved status.
Build backends by name with :func:`solvers.registry.make_backend` or from Hydra (``conf/solver/*.yaml``).
"""

from solvers.base import BackendSolution
from solvers.checks import Tolerances
from solvers.registry import available_backends, make_backend

__all__ = ["BackendSolution", "Tolerances", "available_backends", "make_backend"]
