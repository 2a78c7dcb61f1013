"""The recorders of one run of the main job, as the episode's observers (:mod:`taslel_bench.sim.observers`):
the MCAP stream (``record.mcap``), steps.parquet, the summary's metrics stream and the QP test set
(``record.qps``). Made from the built parts before anything is simulated; files are opened when the episode
starts (the run folder is prepared by then)."""

from __future__ import annotations

import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from taslel_bench.config.settings import health_limits
from taslel_bench.metrics.summary import SummaryStream
from taslel_bench.record import qpset, run_files
from taslel_bench.record.result import EpisodeResult
from taslel_bench.record.steps_writer import StepsWriter
from taslel_bench.sim.observers import FilterQPs, MetricsFeed, StepsTable, StreamedChunks
from taslel_bench.util.fields import plain_dict

SWEEP_LEVEL_KEYS = ("tracker",)  # settings of the sweep, not of a run: not in a run's config.yaml or hash


def run_config_yaml(cfg: DictConfig) -> str:
    """The run's resolved config as written to its config.yaml (without :data:`SWEEP_LEVEL_KEYS`)."""
    plain = plain_dict(cfg, "config")
    for key in SWEEP_LEVEL_KEYS:
        plain.pop(key, None)
    return OmegaConf.to_yaml(OmegaConf.create(plain))


def chunk_ticks(cfg: DictConfig) -> int | None:
    """``record.chunk_ticks`` (null: the whole episode in memory)."""
    chunk = cfg.record.chunk_ticks
    return int(chunk) if chunk is not None else None


@dataclass
class RunRecorders:
    """The run's recorders; iterating gives the episode's observers in the order they see each chunk."""

    metrics: SummaryStream
    steps: StepsWriter
    mcap: StreamedChunks | None = None
    qps: qpset.QPRecorder | None = None

    def __iter__(self) -> Iterator[object]:
        if self.mcap is not None:
            yield self.mcap
        yield StepsTable(self.steps.append)
        yield MetricsFeed(self.metrics)
        if self.qps is not None:
            yield FilterQPs(self.qps)

    def save_qps(self, out_dir: Path, summary: dict) -> None:
        """qps.npz (``record.qps``); a failure is noted in the summary, never loses the run."""
        if self.qps is None:
            return
        try:
            self.qps.save(out_dir / qpset.FILENAME, {"source": "taslel_bench.sim.run"})
            summary["qps_recorded"] = len(self.qps)
        except Exception:  # recording must not lose the run
            summary["qps_error"] = traceback.format_exc().strip().splitlines()[-1]

    def close_mcap(self, res: EpisodeResult, events: list[dict], summary: dict) -> None:
        """Finish episode.mcap (the last ticks, events, summary); a failure is noted in the summary."""
        sink = self.mcap
        if sink is None or sink.stream is None:
            return
        if not sink.error:
            try:
                sink.stream.close(res.trace, events, summary)
            except Exception:  # recording must not lose the run: note it and keep the other files
                sink.error = traceback.format_exc().strip().splitlines()[-1]
                sink.stream.abandon()
        if sink.error:
            summary["mcap_error"] = sink.error


def run_recorders(cfg: DictConfig, built, out_dir: Path, choices: dict[str, str]) -> RunRecorders:
    """The recorders of a run of ``built`` (:class:`taslel_bench.sim.build.Built`) into ``out_dir``;
    ``choices``: the option of each config group, as the run's summary names them."""
    dt = 1.0 / float(cfg.control_rate_hz)
    stance_s, _ = built.controller.stance_swing_s
    metrics = SummaryStream(dt, float(cfg.controller.stand_duration), stance_s, health_limits(cfg))
    return RunRecorders(metrics, StepsWriter(out_dir / run_files.STEPS), _mcap(cfg, built, out_dir),
                        _qp_recorder(cfg, built, choices))


def _mcap(cfg: DictConfig, built, out_dir: Path) -> StreamedChunks | None:
    """record.mcap: an :class:`taslel_bench.record.mcap.McapStream`, fed after every ``record.chunk_ticks``
    ticks one MCAP chunk per second of simulated time (a killed run leaves a readable partial file)."""
    if not cfg.record.mcap:
        return None
    from taslel_bench.record import mcap

    # the per-leg families (the MCAP draws them at the feet)
    names = [b.name for b in built.filter.barriers if b.per_leg] if built.filter is not None else []
    metadata = {"config": {"config.yaml": run_config_yaml(cfg)}, "versions": mcap.versions()}
    every = mcap.stride(cfg.control_rate_hz, cfg.record.mcap_rate_hz)  # record.mcap_rate_hz (null: every tick)

    def open_stream() -> mcap.McapStream:
        plant = mcap.Plant3D(built.mj_model, built.scenario.terrain)
        return mcap.McapStream(out_dir, names, every=every, plant=plant, metadata=metadata)

    return StreamedChunks(open_stream, max(1, round(float(cfg.control_rate_hz))))


def _qp_recorder(cfg: DictConfig, built, choices: dict[str, str]) -> qpset.QPRecorder | None:
    """A :class:`taslel_bench.record.qpset.QPRecorder` when ``record.qps`` is on (and a filter runs)."""
    if not cfg.record.qps or built.filter is None:
        return None
    info = {
        "scenario": choices.get("scenario", built.scenario.name), "solver": choices.get("solver", ""),
        "estimator": choices.get("estimator", getattr(built.estimator, "name", "")), "seed": int(cfg.seed),
        "control_rate_hz": float(cfg.control_rate_hz), "backend": str(built.backend.describe()),
    }  # fmt: skip
    return qpset.QPRecorder(info, every=int(cfg.record.qps_every))
