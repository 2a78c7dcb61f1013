"""A run's summary as typed sections, flattened into ``summary.json``'s keys only when written.

Sections, in the order ``summary.json`` lists them: ``identity`` (what was run: axes, settings, seed,
overrides, config and code versions), ``plant`` (the plant and the controller's model, their files and how
far they agree), ``outcome`` (status, fall, ticks), ``verdict`` (health and safety, their reasons as
values), ``locomotion``, ``filter`` (intervention, QP counts and timings), ``contacts`` (walking and stand
contacts in their own frames, clearance, trips and strikes), ``model`` (the controller model's residuals
against the plant's motion), ``estimator``, ``timing`` (wall time, the tick's parts, time spent off the
loop's clock) and ``machine`` (load and CPU share during the run). A key's meaning and unit:
``docs/reference/summary-keys.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from taslel_bench.metrics.verdict import Reason

SECTIONS = ("identity", "plant", "outcome", "verdict", "locomotion", "filter", "contacts", "model", "estimator",
            "timing", "machine")


@dataclass
class Verdict:
    """The run's health (``status``: ok, degraded or error, and why) and safety (``safe``, why not)."""

    status: str
    degraded_reasons: str  # "; "-joined, the guarantee limits crossed
    reasons: list[Reason]  # why the run is unsafe (empty: safe)
    model_error_reasons: str = ""  # "; "-joined, the model-error limits crossed (residual alarms)

    @property
    def safe(self) -> bool:
        return not self.reasons

    def keys(self) -> dict[str, object]:
        """``safe``, ``unsafe_reasons`` (the reasons' text), ``unsafe_reason_tags`` (what reports count) and
        ``degraded_reasons``, ``model_error_reasons``; ``status`` is the outcome's."""
        return {"degraded_reasons": self.degraded_reasons, "model_error_reasons": self.model_error_reasons,
                "safe": self.safe,
                "unsafe_reasons": "; ".join(r.text for r in self.reasons),
                "unsafe_reason_tags": ",".join(r.tag for r in self.reasons)}


@dataclass
class RunSummary:
    """One run's summary in :data:`SECTIONS` (the verdict typed, the others key -> value)."""

    outcome: dict[str, object]
    verdict: Verdict
    locomotion: dict[str, object] = field(default_factory=dict)
    filter: dict[str, object] = field(default_factory=dict)
    contacts: dict[str, object] = field(default_factory=dict)
    model: dict[str, object] = field(default_factory=dict)
    estimator: dict[str, object] = field(default_factory=dict)
    timing: dict[str, object] = field(default_factory=dict)
    identity: dict[str, object] = field(default_factory=dict)
    plant: dict[str, object] = field(default_factory=dict)
    machine: dict[str, object] = field(default_factory=dict)

    def section(self, name: str) -> dict[str, object]:
        """The section ``name`` (the verdict as its keys)."""
        if name not in SECTIONS:
            raise KeyError(f"no summary section {name!r}; sections: {', '.join(SECTIONS)}")
        if name == "verdict":
            return {"status": self.outcome.get("status"), **self.verdict.keys()}
        return getattr(self, name)

    def flat(self) -> dict[str, object]:
        """``summary.json``'s dict: every section's keys in :data:`SECTIONS` order (``status`` in the
        outcome, as judged). Refuses a key that two sections both hold."""
        out: dict[str, object] = {}
        for name in SECTIONS:
            part = self.verdict.keys() if name == "verdict" else getattr(self, name)
            clash = out.keys() & part.keys()
            if clash:
                raise ValueError(f"summary keys in two sections ({name} and an earlier one): {sorted(clash)}")
            out.update(part)
        return out
