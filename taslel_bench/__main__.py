"""``python -m taslel_bench [overrides]`` — one episode; ``-m`` sweeps (joblib launcher, one job per core).

Each run writes its folder (summary.json, steps.parquet, events.json, episode.mcap); at the end of a
multirun the :class:`taslel_bench.sweep.aggregate.SweepCallback` aggregates the sweep folder and writes the report.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from taslel_bench.config.compose import CONF_DIR
from taslel_bench.sim.console import print_summary
from taslel_bench.sim.run import record_job_error
from taslel_bench.sweep.launchers import LauncherNotInstalled, check_launcher_overrides


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def main(cfg: DictConfig) -> dict:
    from taslel_bench.sim.run import run

    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if "/" not in k and not k.startswith("hydra")}
    try:
        summary = run(cfg, out_dir, choices, list(hc.overrides.task))
    except Exception as exc:
        if hc.mode != RunMode.MULTIRUN:
            raise  # a single run: the error (e.g. a bad value, naming the field) is the output
        # in a sweep one bad job must not stop the others: leave an error summary the report lists
        summary = record_job_error(out_dir, choices, cfg, exc, list(hc.overrides.task))
    print_summary(summary, out_dir)
    if hc.mode == RunMode.MULTIRUN:
        from taslel_bench.sweep.aggregate import run_folders

        sweep_dir = Path(hc.sweep.dir)
        done = sum(1 for d in run_folders(sweep_dir) if (d / "summary.json").is_file())
        job = hc.job.override_dirname or f"#{hc.job.num}"
        print(f"sweep progress: job #{hc.job.num} ({job}) ended {summary.get('status')}; {done} runs complete "
              f"in {sweep_dir}", flush=True)
    return summary


if __name__ == "__main__":
    try:
        check_launcher_overrides(sys.argv[1:])
    except LauncherNotInstalled as exc:
        sys.exit(f"error: {exc}")
    main()
