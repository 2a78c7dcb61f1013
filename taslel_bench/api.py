"""The core's services for axis packages (``scenarios/``, ``solvers/``, ``estimators/``).

Axis packages import :mod:`taslel_bench.interfaces` for types and this module for the few core services
they need beyond them (e.g. data collection with the safety filter in the loop). Everything here is built
from the project's Hydra config, so a solver or filter setting means the same thing in a data-collection
run as in a benchmark run.

    cfg = api.compose(["solver=daqp_persistent"])
    safety_filter = api.build_safety_filter(cfg)          # SafetyFilter with cfg.solver's backend
    controller = api.build_controller(cfg)                # NominalController (trot, IK, joint PD)
    controller = api.NominalController(api.GaitParams(speed_mps=0.3), api.PDGains())  # or set by hand
    bridge, model = api.StateBridge(mj_model), api.A1Model()  # plant state -> the controller's model
"""

from __future__ import annotations

from hydra.utils import instantiate
from omegaconf import DictConfig

from taslel_bench.config.compose import compose
from taslel_bench.config.settings import build_barriers, build_controller, filter_settings
from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.filter.layout import TickInputs
from taslel_bench.filter.safety_filter import FilterResult, SafetyFilter
from taslel_bench.interfaces import ClearanceProfile, Terrain
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.robot.model import A1Model

__all__ = [
    "A1Model",
    "FilterResult",
    "GaitParams",
    "NominalController",
    "PDGains",
    "SafetyFilter",
    "StateBridge",
    "TickInputs",
    "build_controller",
    "build_safety_filter",
    "compose",
]


def build_safety_filter(cfg: DictConfig, terrain: Terrain | None = None,
                        profile: ClearanceProfile | None = None) -> SafetyFilter:
    """The ID-CBF-QP filter configured by ``cfg.filter``/``cfg.robot`` with the backend ``cfg.solver`` and the
    barrier families of ``cfg.filter.barriers`` that apply to ``terrain`` (default: the flat floor) and the
    virtual ``profile`` (None: no phase-profile rows). Per tick:
    ``safety_filter.filter(TickInputs(model, v, in_stance, mu, swing_phase, swing_phase_rate), u_nom)``
    with ``model`` an :class:`A1Model` updated at the plant state (see :mod:`taslel_bench.sim.episode`)."""
    fs = filter_settings(cfg)
    if not fs.enabled:
        raise ValueError("build_safety_filter: cfg.filter.enabled is false")
    barriers = build_barriers(cfg, terrain if terrain is not None else Terrain(), profile)
    return SafetyFilter(fs, instantiate(cfg.solver), barriers)
