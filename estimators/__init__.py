"""Terrain (friction) estimators: axis 3 of the sweep (docs/concepts.md).

Importable without torch: ``estimators.simple`` (oracle, fixed) and ``estimators.collect`` need only
numpy and MuJoCo; ``estimators.models``, ``train``, ``evaluate`` and ``learned`` need the ``learn`` extra
(torch, lightning) and are imported only when used.
"""

from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS
from estimators.simple import FixedEstimator, OracleEstimator

__all__ = ["N_FEATURES", "WINDOW_DT_S", "WINDOW_STEPS", "FixedEstimator", "OracleEstimator"]
