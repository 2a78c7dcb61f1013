"""``episode.mcap``: the episode's trace as JSON-schema channels (opens in Foxglove; reads back with the
``mcap`` reader). Log time = simulated time [ns].

Written *while* the episode runs: :class:`McapStream` is the episode's chunk sink; every chunk of ticks
(:attr:`taslel_bench.sim.episode.Episode.chunk_ticks`, 1 s of simulated time by default) becomes messages of the
same columns as ``steps.parquet`` and is flushed to ``episode.partial.mcap`` as one MCAP chunk. A killed run
leaves that partial file, readable up to its last chunk (:func:`read_messages`); :meth:`McapStream.close`
adds the channels computed after the episode (``/residual``: the controller model's residuals), the events
and the summary, writes the MCAP summary section and renames the file ``episode.mcap``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from taslel_bench.record.trace import TICK_PARTS, EpisodeTrace
from taslel_bench.robot import a1

FINAL_NAME = "episode.mcap"
PARTIAL_NAME = "episode.partial.mcap"

_NUM = {"type": "number"}
_ARR = {"type": "array", "items": {"type": ["number", "null"]}}
_BOOLS = {"type": "array", "items": {"type": "boolean"}}
_NAMES = {"type": "array", "items": {"type": "string"}}
_SHORT = [j.removesuffix("_joint") for j in a1.JOINT_NAMES]
_LEGS = list(a1.LEGS)


def _legs(pattern: str, axes: str = "") -> list[str]:
    """steps.parquet column names of a per-leg quantity, legs in LEGS order (then axes)."""
    return [pattern.format(leg=leg, ax=ax) for leg in _LEGS for ax in (axes or [""])]


# topic -> {field: (JSON schema, steps.parquet columns)}; fields with columns=None are constant
CHANNELS: dict[str, dict[str, tuple[dict, list[str] | None]]] = {
    "/base_state": {
        "position_w_m": (_ARR, ["base_x_w_m", "base_y_w_m", "base_z_w_m"]),
        "quat_wxyz": (_ARR, ["base_quat_w", "base_quat_x", "base_quat_y", "base_quat_z"]),
        "rpy_rad": (_ARR, ["base_roll_rad", "base_pitch_rad", "base_yaw_rad"]),
        "linvel_w_mps": (_ARR, ["base_vx_w_mps", "base_vy_w_mps", "base_vz_w_mps"]),
        "angvel_b_radps": (_ARR, ["base_wx_b_radps", "base_wy_b_radps", "base_wz_b_radps"]),
    },
    "/joint_state": {
        "name": (_NAMES, None),
        "position_rad": (_ARR, [f"q_{j}_rad" for j in _SHORT]),
        "velocity_radps": (_ARR, [f"qd_{j}_radps" for j in _SHORT]),
    },
    "/torques": {"u_nom_nm": (_ARR, [f"u_nom_{j}_nm" for j in _SHORT]), "u_nm": (_ARR, [f"u_{j}_nm" for j in _SHORT])},
    "/contact_force": {
        "foot": (_NAMES, None),
        "filter_w_n": (_ARR, _legs("{leg}_grf_filter_{ax}_w_n", "xyz")),
        "plant_w_n": (_ARR, _legs("{leg}_grf_plant_{ax}_w_n", "xyz")),
        "stance": (_BOOLS, _legs("{leg}_stance")),
        "contact": (_BOOLS, _legs("{leg}_contact")),
        "mu_foot": (_ARR, _legs("{leg}_mu_foot")),
        "contact_point_speed_mps": (_ARR, _legs("{leg}_contact_point_speed_mps")),
    },
    "/qp": {"status": (_NUM, ["qp_status"]), "fallback": ({"type": "boolean"}, ["qp_fallback"]),
            "solve_us": (_NUM, ["qp_solve_us"]), "build_us": (_NUM, ["qp_build_us"]),
            "iterations": (_NUM, ["qp_iterations"])},
    "/tick": {"tick_us": (_NUM, ["tick_us"]), **{f"{p}_us": (_NUM, [f"tick_{p}_us"]) for p in TICK_PARTS}},
    "/barrier": {  # + {name}_h_m, {name}_h_e_mps of every barrier family (barrier_channel)
        "foot": (_NAMES, None),
        "h_m": (_ARR, _legs("{leg}_barrier_h_m")),
        "clearance_m": (_ARR, _legs("{leg}_clearance_m")),
        "obstacle_clearance_m": (_ARR, _legs("{leg}_obstacle_clearance_m")),
        "obstacle_contact": (_BOOLS, _legs("{leg}_obstacle_contact")),
    },
    "/friction": {"mu_hat": (_NUM, ["mu_hat"]), "mu_true": (_NUM, ["mu_true"])},
}
# computed after the episode (taslel_bench.metrics.residuals): written for every tick when the file is closed
AFTER_EPISODE: dict[str, dict[str, tuple[dict, list[str] | None]]] = {
    "/residual": {
        "foot": (_NAMES, None),
        "trunk_force_n": (_NUM, ["residual_trunk_force_n"]),
        "trunk_torque_nm": (_NUM, ["residual_trunk_torque_nm"]),
        "joint_max_nm": (_NUM, ["residual_joint_nm_max"]),
        "foot_acc_error_mps2": (_ARR, _legs("{leg}_foot_acc_error_mps2")),
        "barrier_psi_planned_mps2": (_ARR, _legs("{leg}_barrier_psi_planned_mps2")),
        "barrier_psi_realized_mps2": (_ARR, _legs("{leg}_barrier_psi_realized_mps2")),
    },
}
CONSTANTS = {"name": _SHORT, "foot": _LEGS}


def channels(barrier_names: Sequence[str] = ()) -> dict[str, dict[str, tuple[dict, list[str] | None]]]:
    """:data:`CHANNELS` with the ``/barrier`` channel's fields of each barrier family: ``<name>_h_m`` and
    ``<name>_h_e_mps`` per foot (``h_m``: the smallest h over the families)."""
    out = {topic: dict(fields) for topic, fields in CHANNELS.items()}
    for name in barrier_names:
        out["/barrier"][f"{name}_h_m"] = (_ARR, _legs("{leg}_barrier_" + name + "_h_m"))
        out["/barrier"][f"{name}_h_e_mps"] = (_ARR, _legs("{leg}_barrier_" + name + "_he_mps"))
    return out
EVENTS = {"/events": {"t_s": _NUM, "kind": {"type": "string"}, "message": {"type": "string"}},
          "/summary": {"summary": {"type": "object"}}}  # fmt: skip


def _schema(title: str, props: dict[str, dict]) -> bytes:
    return json.dumps({"title": title, "type": "object", "properties": props}).encode()


def _values(frame: pd.DataFrame, cols: list[str]) -> list:
    """Per row, the columns' values as JSON-ready Python (NaN -> null; one column -> a scalar)."""
    a = frame[cols].to_numpy()
    if a.dtype.kind == "f" and np.isnan(a).any():
        a = np.where(np.isnan(a), None, a.astype(object))
    rows = a.tolist()
    return [r[0] for r in rows] if len(cols) == 1 else rows


class McapStream:
    """The episode's chunk sink: ``stream(trace, k0, k1)`` writes ticks k0..k1 as one flushed MCAP chunk to
    ``<run>/episode.partial.mcap``; :meth:`close` finishes the file and renames it ``episode.mcap``."""

    def __init__(self, run_dir: Path, barrier_names: Sequence[str] = ()) -> None:
        self.partial = Path(run_dir) / PARTIAL_NAME
        self.final = Path(run_dir) / FINAL_NAME
        self._file = open(self.partial, "wb")  # noqa: SIM115 - kept open for the episode, closed in close()
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="taslel_bench")
        self._channels: dict[str, int] = {}
        self.channels = channels(barrier_names)
        for topic, fields in {**self.channels, **AFTER_EPISODE}.items():
            self._register(topic, {name: schema for name, (schema, _) in fields.items()})
        for topic, props in EVENTS.items():
            self._register(topic, props)
        self.ticks_written = 0

    def _register(self, topic: str, props: dict[str, dict]) -> None:
        sid = self._writer.register_schema(name=topic.strip("/"), encoding="jsonschema", data=_schema(topic, props))
        self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)

    def _put(self, topic: str, t_s: float, msg: dict) -> None:
        ns = round(t_s * 1e9)
        self._writer.add_message(self._channels[topic], log_time=ns, publish_time=ns, data=json.dumps(msg).encode())

    def __call__(self, trace: EpisodeTrace, k0: int, k1: int) -> None:
        """Write ticks ``k0:k1`` (the rows steps.parquet will hold) and flush them to disk."""
        if k1 <= k0:
            return
        self._write(trace.frame(k0, k1), self.channels)
        self.ticks_written = k1

    def _write(self, frame: pd.DataFrame, channels: dict) -> None:
        times = frame["t_s"].tolist()
        for topic, fields in channels.items():
            columns = {name: (_values(frame, cols) if cols is not None else None) for name, (_, cols) in fields.items()}
            for i, t in enumerate(times):
                msg = {name: (vals[i] if vals is not None else CONSTANTS[name]) for name, vals in columns.items()}
                self._put(topic, t, msg)
        self._writer.flush()

    def close(self, trace: EpisodeTrace, events: list[dict], summary: dict, steps: pd.DataFrame | None = None) -> Path:
        """Write the ticks not streamed yet, the channels computed after the episode (from ``steps``, the
        whole episode's frame, when the caller has it), the events and the summary; finish; rename to
        episode.mcap."""
        self(trace, self.ticks_written, trace.n)
        if trace.n:
            self._write(steps if steps is not None else trace.frame(0, trace.n), AFTER_EPISODE)
        t_end = float(trace.t_s[trace.n - 1]) if trace.n else 0.0
        for e in [*events, {"t_s": t_end, "kind": "end", "message": str(summary.get("status", ""))}]:
            t = float(e.get("t_s") if e.get("t_s") is not None else t_end)
            self._put("/events", t, {"t_s": t, "kind": str(e["kind"]), "message": str(e["message"])})
        safe = {k: (v if not (isinstance(v, float) and not np.isfinite(v)) else None) for k, v in summary.items()}
        self._put("/summary", t_end, {"summary": safe})
        self._writer.finish()
        self._file.close()
        os.replace(self.partial, self.final)
        return self.final

    def abandon(self) -> None:
        """Close the file without finishing it (the partial file stays, readable up to its last chunk)."""
        if not self._file.closed:
            self._file.close()


def read_messages(path: Path) -> Iterator[tuple[str, int, dict]]:
    """(topic, log time [ns], decoded JSON) of every message of a finished or partial MCAP file; a partial
    file (a killed run) is read record by record up to its last complete chunk."""
    channels: dict[int, str] = {}
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:  # chunks are expanded into their records
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    yield channels[record.channel_id], record.log_time, json.loads(record.data)
        except (McapError, EOFError, ValueError):
            return  # a partial file ends inside its last record
