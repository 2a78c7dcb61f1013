"""External pushes on the trunk: a force [N] in world axes held for a duration, at given times."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import mujoco
import numpy as np

from scenarios.flat import FlatGround
from taslel_bench.interfaces import fail, number, numbers, quad

MAX_FORCE_N = 1000.0  # [N] per axis (about 8 times the A1's weight)
MAX_TIME_S = 3600.0  # [s] push start and duration
PUSH_KEYS = ("t_s", "force_n", "duration_s")


class Pushes(FlatGround):
    """Flat floor plus pushes. ``pushes``: list of ``{t_s, force_n: [fx, fy, fz], duration_s}``; the
    impulse of each is force x duration [N·s], applied at the trunk's centre of mass."""

    def __init__(self, name: str = "push", friction: float = 1.0,
                 pushes: Sequence[dict] = ({"t_s": 3.0, "force_n": (0.0, 60.0, 0.0), "duration_s": 0.1},
                                           {"t_s": 6.0, "force_n": (40.0, 0.0, 0.0), "duration_s": 0.1})) -> None:
        super().__init__(name=name, friction=friction)
        if isinstance(pushes, (str, bytes)) or not isinstance(pushes, Sequence):  # ListConfig is a Sequence
            raise fail("scenario.pushes", pushes, "must be a list of {t_s, force_n: [fx, fy, fz],"
                                                  " duration_s}")
        self.pushes = [_push(f"scenario.pushes[{i}]", p) for i, p in enumerate(pushes)]
        self._trunk = -1

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        if self._trunk < 0:
            self._trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
        wrench = data.xfrc_applied[self._trunk]
        wrench[:] = 0.0
        for t0, t1, force in self.pushes:
            if t0 <= t_s < t1:
                wrench[:3] += force


def _push(path: str, push: object) -> tuple[float, float, np.ndarray]:
    """(start [s], end [s], force [N] in world axes) of one push entry, each key checked by name."""
    if not isinstance(push, Mapping) or set(push) != set(PUSH_KEYS):
        raise fail(path, push, f"must be a mapping with exactly the keys {', '.join(PUSH_KEYS)}")
    t0 = number(f"{path}.t_s", push["t_s"], 0.0, MAX_TIME_S, unit="s")
    duration = number(f"{path}.duration_s", push["duration_s"], 0.0, MAX_TIME_S, lo_open=True, unit="s")
    force = numbers(f"{path}.force_n", push["force_n"], -MAX_FORCE_N, MAX_FORCE_N, length=3, unit="N",
                    why="[fx, fy, fz] in world axes")
    return t0, t0 + duration, np.asarray(force)
