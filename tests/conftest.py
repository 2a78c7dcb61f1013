"""Shared fixtures: Hydra compose API on the project's conf/ (no Hydra runtime needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

CONF_DIR = str(Path(__file__).resolve().parent.parent / "conf")


def compose_cfg(overrides: list[str] | None = None) -> DictConfig:
    from taslel_bench.config.schema import register

    register()  # the structured schema conf/config.yaml builds on
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides or []))


@pytest.fixture
def cfg_factory():
    return compose_cfg


class NeverSolves:
    """A QP backend that hits its iteration limit on every tick (as a mis-tuned solver does); tests put it
    in place of ``taslel_bench.sim.build.build_backend``'s answer to make a filter fail on purpose."""

    name = "never"

    def solve(self, problem):
        from taslel_bench.interfaces import QPSolution

        return QPSolution(None, "max_iter", 1e-6)

    def reset(self) -> None:
        pass

    def describe(self) -> dict:
        return {"name": self.name}
