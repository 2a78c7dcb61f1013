"""Where the safety filter's stance set comes from: one part of the episode (``filter.stance_source``).

Each tick the episode asks its stance source for the stance set (bool (4,), core leg order) and the swing
phase (the ECBF's, [-] (4,)) the filter uses, given the controller's contact plan of the tick and the feet's
contact reader (:class:`taslel_bench.plant.contacts.FootContactReader`, MuJoCo's contact forces on each foot
sphere, world axes [N]):

* :class:`PlannedStance` (``schedule``): the controller's own plan, as the paper's filter uses it;
* :class:`MeasuredStance` (``contact``): the feet in contact at the end of the previous tick's physics;
* :class:`EstimatedStance` (``estimate``): the plan fused with the feet's contact forces
  (:class:`taslel_bench.control.contact_estimate.ContactEstimate`).

``reads_feet_before_tick``: the episode reads the feet's contacts at the start of every tick for it;
``reads_feet_after_step``: at the end of every tick's physics (the next tick's stance set).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from taslel_bench.control.contact_estimate import ContactEstimate
from taslel_bench.control.plan import ContactPlan
from taslel_bench.plant.contacts import FootContactReader


class StanceSource(Protocol):
    """The filter's stance set and swing phase of a tick (module doc)."""

    name: str
    reads_feet_before_tick: bool
    reads_feet_after_step: bool

    def reset(self) -> None: ...

    def stance(self, plan: ContactPlan, contacts: FootContactReader) -> np.ndarray: ...

    def swing_phase(self, plan: ContactPlan) -> np.ndarray: ...


class PlannedStance:
    """The controller's planned stance set and swing phase (the paper's filter)."""

    name = "schedule"
    reads_feet_before_tick = False
    reads_feet_after_step = False

    def reset(self) -> None:
        pass

    def stance(self, plan: ContactPlan, contacts: FootContactReader) -> np.ndarray:
        return plan.in_stance

    def swing_phase(self, plan: ContactPlan) -> np.ndarray:
        return plan.swing_phase


class MeasuredStance(PlannedStance):
    """The feet that touched the terrain in the last physics step of the previous tick (MuJoCo contacts); the
    swing phase is the plan's."""

    name = "contact"
    reads_feet_after_step = True

    def stance(self, plan: ContactPlan, contacts: FootContactReader) -> np.ndarray:
        return contacts.in_contact.copy()


class EstimatedStance:
    """The plan fused with the feet's contact forces of this tick (``estimate``: early and late touchdowns)."""

    name = "estimate"
    reads_feet_before_tick = True
    reads_feet_after_step = False

    def __init__(self, estimate: ContactEstimate) -> None:
        self.estimate = estimate

    def reset(self) -> None:
        self.estimate.reset()

    def stance(self, plan: ContactPlan, contacts: FootContactReader) -> np.ndarray:
        return self.estimate.update(plan.in_stance, plan.swing_phase, contacts.forces_in_world)

    def swing_phase(self, plan: ContactPlan) -> np.ndarray:
        return self.estimate.swing_phase(plan.swing_phase)
