"""``python -m taslel_bench [overrides]`` — one episode; ``-m`` sweeps (joblib launcher, one job per core).

Each run writes its folder (summary.json, steps.parquet, events.json, episode.mcap); at the end of a
multirun the :class:`taslel_bench.sweep.SweepCallback` aggregates the sweep folder and writes the report.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from taslel_bench.console import print_summary

CONF_DIR = str(Path(__file__).resolve().parent.parent / "conf")


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def main(cfg: DictConfig) -> dict:
    from taslel_bench.run import run

    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if "/" not in k and not k.startswith("hydra")}
    summary = run(cfg, out_dir, choices)
    print_summary(summary, out_dir)
    return summary


if __name__ == "__main__":
    main()
