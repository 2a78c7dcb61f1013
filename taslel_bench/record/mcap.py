"""``episode.mcap``: the episode for Foxglove (reads back with the ``mcap`` reader, :func:`read_messages`).

Channels (every ``record.mcap_rate_hz``-th of a second, i.e. every :attr:`McapStream.every`-th control tick):

* the robot in the 3D panel, protobuf well-known schemas of ``foxglove-sdk``
  (:mod:`taslel_bench.record.scene`): ``/tf`` (``foxglove.FrameTransforms``: world -> trunk -> links),
  ``/scene/robot`` and ``/scene/terrain`` (``foxglove.SceneUpdate``: collision geometry and terrain, repeated
  once per streamed chunk so a seek or a partial file shows them), ``/scene/contact`` (force arrows of the
  plant and of the filter per foot, the swing feet's barrier state);
* the signals, JSON with named fields (:mod:`taslel_bench.record.signals`): ``/base_state``,
  ``/joint_state``, ``/torques``, ``/contact_force``, ``/qp``, ``/tick``, ``/barrier``, ``/friction``, ``/residual``
  (the model residuals, computed for each chunk before it is written);
* ``/events`` (JSON) and ``/log`` (``foxglove.Log``): QP failures, falls, errors, the end; ``/summary``.

Log time = the run's wall-clock start [ns since the Unix epoch] + simulated time; publish time = simulated
time [ns] (and ``t_s`` in every JSON message, ``t_s`` in every scene entity's metadata). MCAP metadata
records: ``run`` (start time, rates, frames), ``config`` (the resolved config.yaml), ``versions``
(packages, git commit) and, at close, ``summary``.

Written *while* the episode runs: :class:`McapStream` is the episode's chunk sink; every chunk of ticks
(``record.chunk_ticks``, 5 s of simulated time at 1 kHz by default) is flushed to ``episode.partial.mcap`` as
one zstd-compressed MCAP chunk. A killed run leaves that partial file, readable up to its last chunk;
:meth:`McapStream.close` adds the events, the summary and the MCAP summary section and renames the file.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from foxglove import messages as fm
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from taslel_bench.plant.contacts import foot_radius_m
from taslel_bench.record import scene, signals
from taslel_bench.record.trace import EpisodeTrace
from taslel_bench.robot import quadruped as quad
from taslel_bench.util.provenance import code_version

FINAL_NAME = "episode.mcap"
PARTIAL_NAME = "episode.partial.mcap"
PROTOBUF_CHANNELS = {"/tf": fm.FrameTransforms, "/scene/robot": fm.SceneUpdate, "/scene/terrain": fm.SceneUpdate,
                     "/scene/contact": fm.SceneUpdate, "/log": fm.Log}  # fmt: skip
EVENTS = {"/events": {"t_s": {"type": "number"}, "kind": {"type": "string"}, "message": {"type": "string"}},
          "/summary": {"summary": {"type": "object"}}}  # fmt: skip
VERSION_PACKAGES = ("mujoco", "pin", "numpy", "qpsolvers", "daqp", "osqp", "hydra-core", "foxglove-sdk", "mcap")
_LOG_LEVEL = {"qp_failure": fm.LogLevel.Warning, "residual_alarm": fm.LogLevel.Warning, "fall": fm.LogLevel.Error,
              "error": fm.LogLevel.Error, "end": fm.LogLevel.Info}  # fmt: skip


class Plant3D:
    """What the 3D channels need of a run: the plant model (bodies, collision geoms) and the terrain."""

    def __init__(self, mj_model, terrain) -> None:
        self.model, self.terrain = mj_model, terrain
        self.tree = scene.BodyTree(mj_model)


class McapStream:
    """The episode's chunk sink: ``stream(trace, k0, k1)`` writes ticks k0..k1 as one flushed MCAP chunk to
    ``<run>/episode.partial.mcap``; :meth:`close` finishes the file and renames it ``episode.mcap``.

    ``every``: write every ``every``-th control tick (1: all); ``plant``: the 3D channels (None: signals
    only); ``metadata``: MCAP metadata records written first (name -> {key: text}); ``start_ns``: wall-clock
    time [ns] of simulated time 0 (default: now)."""

    def __init__(self, run_dir: Path, barrier_names: Sequence[str] = (), *, every: int = 1,
                 plant: Plant3D | None = None, metadata: dict[str, dict[str, str]] | None = None,
                 start_ns: int | None = None) -> None:  # fmt: skip
        self.partial, self.final = Path(run_dir) / PARTIAL_NAME, Path(run_dir) / FINAL_NAME
        self.every, self.plant = max(1, int(every)), plant
        self.start_ns = time.time_ns() if start_ns is None else int(start_ns)
        self.barrier_names = list(barrier_names)
        self._file = open(self.partial, "wb")  # noqa: SIM115 - kept open for the episode, closed in close()
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="taslel_bench")
        self._channels: dict[str, int] = {}
        self.channels = signals.channels(barrier_names)
        for topic, spec in {**self.channels, **signals.AFTER_EPISODE}.items():
            self._register_json(topic, signals.json_schema(topic, spec))
        for topic, props in EVENTS.items():
            self._register_json(topic, {"title": topic, "type": "object", "properties": props})
        for topic, cls in PROTOBUF_CHANNELS.items():
            if plant is not None or topic == "/log":
                self._register_protobuf(topic, cls)
        for name, record in {"run": self._run_record(), **(metadata or {})}.items():
            self._writer.add_metadata(name, {k: str(v) for k, v in record.items()})
        self.ticks_written = 0

    def _run_record(self) -> dict[str, str]:
        return {"start_unix_ns": str(self.start_ns), "log_time": "start_unix_ns + simulated time [ns]",
                "publish_time": "simulated time [ns]", "record_every_ticks": str(self.every),
                "fixed_frame": scene.WORLD_FRAME, "follow_frame": quad.TRUNK_BODY,
                "force_arrow_m_per_n": str(scene.FORCE_SCALE_M_PER_N)}  # fmt: skip

    def _register_json(self, topic: str, schema: dict) -> None:
        sid = self._writer.register_schema(
            name=topic.strip("/"), encoding="jsonschema", data=json.dumps(schema).encode()
        )
        self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)

    def _register_protobuf(self, topic: str, cls) -> None:
        schema = cls.get_schema()
        sid = self._writer.register_schema(name=schema.name, encoding="protobuf", data=bytes(schema.data))
        self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="protobuf", schema_id=sid)

    def _put(self, topic: str, t_s: float, data: bytes) -> None:
        sim_ns = round(t_s * 1e9)
        self._writer.add_message(self._channels[topic], log_time=self.start_ns + sim_ns, publish_time=sim_ns, data=data)

    def _put_json(self, topic: str, t_s: float, msg: dict) -> None:
        self._put(topic, t_s, json.dumps(msg).encode())

    def log_ns(self, t_s: float) -> int:
        return self.start_ns + round(t_s * 1e9)

    def recorded(self, k0: int, k1: int) -> np.ndarray:
        """The ticks of ``k0:k1`` that are written (every ``every``-th tick of the episode)."""
        first = -(-k0 // self.every) * self.every
        return np.arange(first, k1, self.every)

    def __call__(self, trace: EpisodeTrace, k0: int, k1: int) -> None:
        """Write the recorded ticks of ``k0:k1`` (episode ticks the trace holds: the rows steps.parquet will
        hold, with their model residuals when computed) and flush them to disk."""
        if k1 <= k0:
            return
        ticks = self.recorded(k0, k1)
        if len(ticks):
            frame = trace.frame(k0, k1).iloc[ticks - k0].reset_index(drop=True)
            if self.plant is not None:
                self._write_3d(trace.qpos_mj[ticks - trace.offset], frame)
            self._write_signals(frame, self.channels)
            self._write_signals(frame, signals.AFTER_EPISODE)
        self._writer.flush()
        self.ticks_written = k1

    def _write_signals(self, frame: pd.DataFrame, channels: dict) -> None:
        times = frame["t_s"].tolist()
        for topic, spec in channels.items():
            for t, msg in zip(times, signals.messages(frame, spec), strict=True):
                self._put_json(topic, t, msg)

    def _write_3d(self, qpos_rows: np.ndarray, frame: pd.DataFrame) -> None:
        """/scene/robot and /scene/terrain once (the chunk's first tick), /tf and /scene/contact per tick."""
        p, times = self.plant, frame["t_s"].to_numpy()
        assert p is not None  # called only with a plant to draw
        t0 = float(times[0])
        self._put("/scene/robot", t0, scene.robot_scene(p.model, p.tree, self.log_ns(t0)).encode())
        self._put("/scene/terrain", t0, scene.terrain_scene(p.terrain, p.model, self.log_ns(t0)).encode())
        pos, quat = p.tree.relative_poses(qpos_rows)
        feet = _leg_array(frame, "{leg}_foot_{ax}_w_m")
        plant_f, filter_f = (
            _leg_array(frame, "{leg}_grf_plant_{ax}_w_n"),
            _leg_array(frame, "{leg}_grf_filter_{ax}_w_n"),
        )
        h = {name: frame[[f"{leg}_barrier_{name}_h_m" for leg in quad.LEGS]].to_numpy() for name in self.barrier_names}
        radius = foot_radius_m(p.model)  # [m]
        for i, t in enumerate(times):
            ns = self.log_ns(float(t))
            self._put("/tf", float(t), scene.body_transforms(p.tree, ns, pos[i], quat[i]).encode())
            update = scene.contact_scene(ns, float(t), feet[i], plant_f[i], filter_f[i],
                                         {n: v[i] for n, v in h.items()}, radius)
            self._put("/scene/contact", float(t), update.encode())

    def close(self, trace: EpisodeTrace, events: list[dict], summary: dict) -> Path:
        """Write the ticks not streamed yet, the events, the summary (a channel and a metadata record);
        finish; rename to episode.mcap."""
        self(trace, self.ticks_written, trace.n)
        t_end = float(trace.t_s[trace.n - 1 - trace.offset]) if trace.n else 0.0
        for e in [*events, {"t_s": t_end, "kind": "end", "message": str(summary.get("status", ""))}]:
            self._write_event(
                float(e.get("t_s") if e.get("t_s") is not None else t_end), str(e["kind"]), str(e["message"])
            )
        safe = {k: (v if not (isinstance(v, float) and not np.isfinite(v)) else None) for k, v in summary.items()}
        self._put_json("/summary", t_end, {"summary": safe})
        self._writer.add_metadata(
            "summary", {k: json.dumps(v) if not isinstance(v, str) else v for k, v in safe.items()}
        )
        self._writer.finish()
        self._file.close()
        os.replace(self.partial, self.final)
        return self.final

    def _write_event(self, t: float, kind: str, message: str) -> None:
        self._put_json("/events", t, {"t_s": t, "kind": kind, "message": message})
        log = fm.Log(timestamp=scene.timestamp(self.log_ns(t)), level=_LOG_LEVEL.get(kind, fm.LogLevel.Info),
                     message=f"t={t:.3f} s {kind}: {message}", name="taslel_bench", file="", line=0)  # fmt: skip
        self._put("/log", t, log.encode())

    def abandon(self) -> None:
        """Close the file without finishing it (the partial file stays, readable up to its last chunk)."""
        if not self._file.closed:
            self._file.close()


def _leg_array(frame: pd.DataFrame, pattern: str) -> np.ndarray:
    """(n, 4, 3) of the columns ``pattern`` per leg and axis (legs in LEGS order, world axes)."""
    cols = [pattern.format(leg=leg, ax=ax) for leg in quad.LEGS for ax in "xyz"]
    return frame[cols].to_numpy(float).reshape(len(frame), quad.N_LEGS, 3)


def stride(control_rate_hz: float, mcap_rate_hz: float | None) -> int:
    """Control ticks per MCAP sample for ``record.mcap_rate_hz`` (None: every tick)."""
    if mcap_rate_hz is None:
        return 1
    return max(1, round(float(control_rate_hz) / float(mcap_rate_hz)))


def versions() -> dict[str, str]:
    """The package versions and the code version of the run (the ``versions`` metadata record)."""
    out = {}
    for pkg in VERSION_PACKAGES:
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            continue
    return {**out, **{k: str(v) for k, v in code_version().items()}}


# ------------------------------------------------------------------------------------------------ reading
def _protobuf_decoder(schema: Schema):
    """bytes -> dict for a protobuf schema (the FileDescriptorSet the file carries; google.protobuf only)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory

    pool = descriptor_pool.DescriptorPool()
    pending = list(descriptor_pb2.FileDescriptorSet.FromString(schema.data).file)
    while pending:  # add each file after its dependencies
        added = [f for f in pending if all(_has_file(pool, dep) for dep in f.dependency)]
        if not added:
            raise McapError(f"schema {schema.name}: unresolved protobuf dependencies")
        for f in added:
            pool.Add(f)
            pending.remove(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return lambda data: json_format.MessageToDict(cls.FromString(data), preserving_proto_field_name=True)


def _has_file(pool, name: str) -> bool:
    try:
        pool.FindFileByName(name)
    except KeyError:
        return False
    return True


def read_messages(path: Path, with_publish_time: bool = False) -> Iterator[tuple]:
    """(topic, log time [ns], decoded message) of every message of a finished or partial MCAP file (JSON
    and protobuf channels, both as dicts; with ``with_publish_time`` a 4th item, the publish time = the
    simulated time [ns]); a partial file (a killed run) is read up to its last complete chunk."""
    topics: dict[int, str] = {}
    decoders: dict[int, Callable[[bytes], object]] = {}
    schemas: dict[int, Schema] = {}
    by_schema: dict[int, Callable[[bytes], object]] = {}  # protobuf decoders, built once per schema
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:  # chunks are expanded into their records
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    topics[record.id] = record.topic
                    if record.message_encoding != "protobuf":
                        decoders[record.id] = json.loads
                        continue
                    if record.schema_id not in by_schema:
                        by_schema[record.schema_id] = _protobuf_decoder(schemas[record.schema_id])
                    decoders[record.id] = by_schema[record.schema_id]
                elif isinstance(record, Message):
                    msg = decoders[record.channel_id](record.data)
                    head = (topics[record.channel_id], record.log_time, msg)
                    yield (*head, record.publish_time) if with_publish_time else head
        except (McapError, EOFError, ValueError):
            return  # a partial file ends inside its last record
