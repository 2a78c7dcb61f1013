"""Where the project's Hydra config tree lives, and composing it outside a Hydra app (tests, tools, axes)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from omegaconf import DictConfig

CONF_DIR = Path(__file__).resolve().parents[2] / "conf"  # the repository's conf/ (config.yaml + one group per part)


def compose(overrides: Sequence[str] = (), config_name: str = "config") -> DictConfig:
    """``conf/<config_name>.yaml`` with Hydra overrides, composed without a Hydra runtime."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from taslel_bench.config import schema

    schema.register()  # the structured configs conf/ builds on

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return hydra_compose(config_name=config_name, overrides=list(overrides))
