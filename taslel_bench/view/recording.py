"""A run folder read for the viewer: the plant's state row by row (``steps.parquet``), the forces to draw, the
events to mark on the timeline (``events.json``: falls, QP failures, alarms; trips recomputed from the contact
columns the way the summary counts them), and the summary.

Times: ``t_s`` is the start of each control tick [s of simulated time]; a row's state is the plant's state at the
end of its tick, ``t_s + dt_s`` (as in :mod:`taslel_bench.record.video`). Frames: ``_w`` world axes, ``_b`` trunk
axes; forces [N], positions [m].
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from taslel_bench.metrics.clearance import TripRule
from taslel_bench.record import run_files
from taslel_bench.record.video import FOOT_COLUMNS, FORCE_COLUMNS, STATE_COLUMNS
from taslel_bench.robot import quadruped as quad

CONFIG = "config.yaml"
REQUIRED = (CONFIG, run_files.STEPS)  # what makes a folder a run folder for the viewer
JOINTS = [j.removesuffix("_joint") for j in quad.JOINT_NAMES]
VELOCITY_COLUMNS = [*(f"base_v{ax}_w_mps" for ax in "xyz"), *(f"base_w{ax}_b_radps" for ax in "xyz"),
                    *(f"qd_{j}_radps" for j in JOINTS)]  # fmt: skip
TORQUE_COLUMNS = [f"u_{j}_nm" for j in JOINTS]
PLANNED_FORCE_COLUMNS = [f"{leg}_grf_filter_{ax}_w_n" for leg in quad.LEGS for ax in "xyz"]
TRIP_COLUMNS = [f"{leg}_{name}" for leg in quad.LEGS
                for name in ("foot_touching", "foot_flank_contact", "leg_link_obstacle_contact", "stance",
                             "scheduled_stance", "swing_phase")]  # fmt: skip


class NotARunFolder(ValueError):
    """The path is not a run folder (the message names the path and what is missing)."""


@dataclass(frozen=True)
class RunEvent:
    """One mark on the timeline: ``t_s`` [s] the tick it happened in, ``kind`` (``fall``, ``trip``,
    ``qp_failure``, ``alarm``, ``error``, ...), ``text`` one line."""

    t_s: float
    kind: str
    text: str


@dataclass(frozen=True)
class Recording:
    """A run's recorded plant states and what the viewer draws over them, one row per control tick."""

    run_dir: Path
    t_s: np.ndarray  # (n,) [s] start of each tick
    dt_s: float  # [s] control period (the rows' spacing)
    state: np.ndarray  # (n, 19) trunk position [m] and quaternion wxyz (world), then the 12 joints [rad]
    velocity: np.ndarray  # (n, 18) trunk linear velocity [m/s] (world), angular [rad/s] (trunk), joints [rad/s]
    torque_nm: np.ndarray  # (n, 12) [N·m] the torques applied in the tick, in quad.JOINT_NAMES order
    feet_w: np.ndarray  # (n, 4, 3) [m] foot centres at the start of the tick (its physics step's sensors)
    grf_plant_w: np.ndarray  # (n, 4, 3) [N] MuJoCo's contact force on each foot
    grf_planned_w: np.ndarray  # (n, 4, 3) [N] the filter's planned contact force (nan: no filter or swing)
    stand_s: float  # [s] the stand before walking
    summary: dict = field(default_factory=dict)
    events: tuple[RunEvent, ...] = ()

    @property
    def n(self) -> int:
        return len(self.t_s)

    def state_time(self, row: int) -> float:
        """[s] simulated time of row ``row``'s state (the end of its tick)."""
        return float(self.t_s[row]) + self.dt_s

    def row_at(self, t_state_s: float) -> int:
        """The row whose state time is nearest ``t_state_s`` [s], clipped to the recording."""
        return int(np.clip(np.rint((t_state_s - float(self.t_s[0])) / self.dt_s) - 1, 0, self.n - 1))

    def feet_shown_w(self, row: int) -> np.ndarray:
        """(4, 3) [m] foot centres of row ``row``'s state: the next row's sensors (read at the start of its tick,
        i.e. at this state), this row's own on the last row (one tick earlier)."""
        return self.feet_w[min(row + 1, self.n - 1)]

    def row_of_tick(self, t_tick_s: float) -> int:
        """The row of the tick that starts at ``t_tick_s`` [s] (an event's time), clipped to the recording."""
        return int(np.clip(np.rint((t_tick_s - float(self.t_s[0])) / self.dt_s), 0, self.n - 1))


def check_run_folder(path: Path) -> None:
    """Raise :class:`NotARunFolder` naming ``path`` and what it lacks (a sweep folder: naming some runs)."""
    if not path.exists():
        raise NotARunFolder(f"{path}: no such folder")
    if not path.is_dir():
        raise NotARunFolder(f"{path} is a file, not a run folder (give the folder that holds {' and '.join(REQUIRED)})")
    missing = [name for name in REQUIRED if not (path / name).is_file()]
    if not missing:
        return
    runs = sorted(p.name for p in path.iterdir() if p.is_dir() and all((p / n).is_file() for n in REQUIRED))
    made = "; a run folder is made by `python -m taslel_bench ...` (its path is printed as `run folder:`)"
    hint = f"; it holds run folders, e.g. {path / runs[0]} ({len(runs)} runs)" if runs else made
    raise NotARunFolder(f"{path} is not a run folder: no {', '.join(missing)}{hint}")


def load_recording(run_dir: Path) -> Recording:
    """The run in ``run_dir`` (checked by :func:`check_run_folder`) as a :class:`Recording`."""
    run_dir = Path(run_dir)
    check_run_folder(run_dir)
    steps = _read_steps(run_dir / run_files.STEPS)
    t_s = steps["t_s"].to_numpy(float)
    dt_s = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 1e-3
    summary = _read_json(run_dir / run_files.SUMMARY, {})
    stand_s = _stand_duration_s(run_dir)
    events = [*_saved_events(run_dir), *trip_events(steps, stand_s, dt_s)]
    return Recording(
        run_dir=run_dir, t_s=t_s, dt_s=dt_s, state=steps[STATE_COLUMNS].to_numpy(float),
        velocity=steps[VELOCITY_COLUMNS].to_numpy(float), torque_nm=steps[TORQUE_COLUMNS].to_numpy(float),
        feet_w=_legs(steps, FOOT_COLUMNS), grf_plant_w=_legs(steps, FORCE_COLUMNS),
        grf_planned_w=_legs(steps, PLANNED_FORCE_COLUMNS), stand_s=stand_s, summary=summary,
        events=tuple(sorted(events, key=lambda e: (e.t_s, e.kind))),
    )  # fmt: skip


def _read_steps(path: Path) -> pd.DataFrame:
    import pyarrow.parquet as pq

    need = ["t_s", *STATE_COLUMNS, *VELOCITY_COLUMNS, *TORQUE_COLUMNS, *FOOT_COLUMNS, *FORCE_COLUMNS]
    have = set(pq.read_schema(path).names)
    missing = [c for c in need if c not in have]
    if missing:
        raise NotARunFolder(f"{path}: no column {', '.join(missing[:6])}{' ...' if len(missing) > 6 else ''} "
                            "(written by an older or another harness?)")  # fmt: skip
    optional = [c for c in (*PLANNED_FORCE_COLUMNS, *TRIP_COLUMNS, "nonfoot_obstacle_contact") if c in have]
    steps = pd.read_parquet(path, columns=[*need, *optional])
    for c in PLANNED_FORCE_COLUMNS:
        if c not in steps:
            steps[c] = np.nan
    if steps.empty:
        raise NotARunFolder(f"{path}: no rows (the run recorded no tick)")
    return steps


def _legs(steps: pd.DataFrame, columns: list[str]) -> np.ndarray:
    return steps[columns].to_numpy(float).reshape(-1, quad.N_LEGS, 3)


def _read_json(path: Path, default):
    return json.loads(path.read_text()) if path.is_file() else default


def _stand_duration_s(run_dir: Path) -> float:
    from omegaconf import OmegaConf

    cfg = OmegaConf.load(run_dir / CONFIG)
    return float(OmegaConf.select(cfg, "controller.stand_duration", default=0.0) or 0.0)


def _saved_events(run_dir: Path) -> list[RunEvent]:
    """The run's events.json (falls, QP failures, residual alarms, errors), ``[]`` without one."""
    out = []
    for e in _read_json(run_dir / run_files.EVENTS, []):
        if isinstance(e, dict) and isinstance(e.get("t_s"), int | float):
            out.append(RunEvent(float(e["t_s"]), str(e.get("kind", "event")), str(e.get("message", ""))))
    return out


def trip_events(steps: pd.DataFrame, stand_s: float, dt_s: float) -> list[RunEvent]:
    """The trips the summary's ``trips`` counts, one event per onset over the walking ticks, by the same rule
    (:class:`taslel_bench.metrics.clearance.TripRule`): a foot in the air by the plan and the filter's stance set
    striking a flank, or touching a walkable surface in the first half of its swing; a leg link's new obstacle
    contact. ``[]`` when the columns are missing (a run recorded before the rule)."""
    if any(c not in steps for c in TRIP_COLUMNS):
        return []
    t_s = steps["t_s"].to_numpy(float)
    walk = slice(int(np.searchsorted(t_s, stand_s - dt_s / 2)), len(t_s))

    def legs(name: str, dtype: type = bool) -> np.ndarray:
        return steps[[f"{leg}_{name}" for leg in quad.LEGS]].to_numpy(dtype)[walk]

    air = ~legs("stance") & ~legs("scheduled_stance")
    r = TripRule(dt_s)(legs("foot_touching"), legs("foot_flank_contact"), air, legs("swing_phase", float),
                       legs("leg_link_obstacle_contact"))  # fmt: skip
    out = []
    for mask, what in ((r["strike"], "foot struck a flank"), (r["lift"], "foot scuffed the ground lifting"),
                       (r["link"], "leg link hit an obstacle")):  # fmt: skip
        for k, i in zip(*np.nonzero(mask), strict=True):
            out.append(RunEvent(float(t_s[walk][k]), "trip", f"{quad.LEGS[i]} {what}"))
    return sorted(out, key=lambda e: e.t_s)
