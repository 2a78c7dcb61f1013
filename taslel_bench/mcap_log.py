"""``episode.mcap``: the episode's trace as JSON-schema channels (opens in Foxglove; reads back with the
``mcap`` reader). Log time = simulated time [ns]. Written after the episode from the in-memory trace, so a
run that ended in an error still leaves a finalised file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from taslel_bench import robot
from taslel_bench.recording import atomic_write
from taslel_bench.trace import TICK_PARTS, EpisodeTrace

_NUM = {"type": "number"}
_ARR = {"type": "array", "items": {"type": ["number", "null"]}}


def _schema(title: str, props: dict[str, dict]) -> bytes:
    return json.dumps({"title": title, "type": "object", "properties": props}).encode()


CHANNELS: dict[str, dict[str, dict]] = {
    "/base_state": {"t_s": _NUM, "position_w_m": _ARR, "rpy_rad": _ARR, "linvel_w_mps": _ARR},
    "/joint_state": {"name": {"type": "array"}, "position_rad": _ARR, "velocity_radps": _ARR},
    "/torques": {"u_nom_nm": _ARR, "u_nm": _ARR},
    "/contact_force": {
        "foot": {"type": "array"}, "filter_w_n": _ARR, "plant_w_n": _ARR, "stance": {"type": "array"},
        "contact": {"type": "array"},
    },
    "/qp": {"status": {"type": "integer"}, "fallback": {"type": "boolean"}, "solve_us": _NUM, "build_us": _NUM,
            "iterations": {"type": "integer"}},
    "/tick": {"tick_us": _NUM, **{f"{part}_us": _NUM for part in TICK_PARTS}},
    "/barrier": {"foot": {"type": "array"}, "h_m": _ARR, "h_e_mps": _ARR, "clearance_m": _ARR},
    "/friction": {"mu_hat": _NUM, "mu_true": _NUM},
    "/events": {"t_s": _NUM, "kind": {"type": "string"}, "message": {"type": "string"}},
    "/summary": {"summary": {"type": "object"}},
}


def _clean(a: np.ndarray) -> list:
    """JSON-safe list: NaN -> None."""
    return [None if not np.isfinite(x) else float(x) for x in np.asarray(a, float).ravel()]


def write_episode_mcap(path: Path, trace: EpisodeTrace, events: list[dict], summary: dict) -> None:
    atomic_write(Path(path), lambda tmp: _write(tmp, trace, events, summary))


def _write(path: Path, tr: EpisodeTrace, events: list[dict], summary: dict) -> None:
    with open(path, "wb") as stream:
        w = Writer(stream)
        w.start(profile="", library="taslel_bench")
        ch = {}
        for topic, props in CHANNELS.items():
            sid = w.register_schema(name=topic.strip("/"), encoding="jsonschema", data=_schema(topic, props))
            ch[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)

        def put(topic: str, t_s: float, msg: dict) -> None:
            ns = round(t_s * 1e9)
            w.add_message(ch[topic], log_time=ns, publish_time=ns, data=json.dumps(msg).encode())

        n = tr.n
        rpy = tr.base_rpy()
        names = [j.removesuffix("_joint") for j in robot.JOINT_NAMES]
        legs = list(robot.LEGS)
        for k in range(n):
            t = float(tr.t_s[k])
            put("/base_state", t, {"t_s": t, "position_w_m": _clean(tr.base_pos_w[k]), "rpy_rad": _clean(rpy[k]),
                                   "linvel_w_mps": _clean(tr.base_linvel_w[k])})
            put("/joint_state", t, {"name": names, "position_rad": _clean(tr.q[k]),
                                    "velocity_radps": _clean(tr.qd[k])})
            put("/torques", t, {"u_nom_nm": _clean(tr.u_nom[k]), "u_nm": _clean(tr.u[k])})
            put("/contact_force", t, {"foot": legs, "filter_w_n": _clean(tr.grf_filter_w[k]),
                                      "plant_w_n": _clean(tr.grf_plant_w[k]),
                                      "stance": tr.in_stance[k].tolist(), "contact": tr.in_contact[k].tolist()})
            put("/qp", t, {"status": int(tr.qp_status[k]), "fallback": bool(tr.qp_fallback[k]),
                           "solve_us": _clean([tr.qp_solve_us[k]])[0], "build_us": _clean([tr.qp_build_us[k]])[0],
                           "iterations": int(tr.qp_iterations[k])})
            put("/barrier", t, {"foot": legs, "h_m": _clean(tr.barrier_h_m[k]), "h_e_mps": _clean(tr.barrier_he_mps[k]),
                                "clearance_m": _clean(tr.clearance_m[k])})
            put("/friction", t, {"mu_hat": float(tr.mu_hat[k]), "mu_true": float(tr.mu_true[k])})
            put("/tick", t, {"tick_us": float(tr.tick_us[k]),
                             **{f"{part}_us": float(v) for part, v in zip(TICK_PARTS, tr.tick_parts_us[k])}})
        t_end = float(tr.t_s[n - 1]) if n else 0.0
        end = {"t_s": t_end, "kind": "end", "message": str(summary.get("status", ""))}
        for e in [*events, end]:
            put("/events", float(e.get("t_s") or t_end), {"t_s": float(e.get("t_s") or t_end),
                                                          "kind": str(e["kind"]), "message": str(e["message"])})
        safe = {k: (v if not (isinstance(v, float) and not np.isfinite(v)) else None) for k, v in summary.items()}
        put("/summary", t_end, {"summary": safe})
        w.finish()
