"""External pushes on the trunk: a force [N] in world axes held for a duration, at given times."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from scenarios.flat import FlatGround
from taslel_bench import robot


class Pushes(FlatGround):
    """Flat floor plus pushes. ``pushes``: list of ``{t_s, force_n: [fx, fy, fz], duration_s}``; the
    impulse of each is force x duration [N·s], applied at the trunk's centre of mass."""

    def __init__(self, name: str = "push", friction: float = 1.0,
                 pushes: Sequence[dict] = ({"t_s": 2.0, "force_n": (0.0, 60.0, 0.0), "duration_s": 0.1},)) -> None:
        super().__init__(name=name, friction=friction)
        self.pushes = []
        for i, p in enumerate(pushes):
            force = np.asarray(p.get("force_n", ()), float)
            t0, dur = float(p.get("t_s", -1.0)), float(p.get("duration_s", -1.0))
            if force.shape != (3,) or t0 < 0 or dur <= 0:
                raise ValueError(f"scenario.pushes[{i}]={dict(p)!r}: need t_s >= 0, duration_s > 0, force_n [fx, fy, fz]")
            self.pushes.append((t0, t0 + dur, force))
        self._trunk = -1

    def on_tick(self, model: mujoco.MjModel, data: mujoco.MjData, t_s: float) -> None:
        if self._trunk < 0:
            self._trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot.TRUNK_BODY)
        wrench = data.xfrc_applied[self._trunk]
        wrench[:] = 0.0
        for t0, t1, force in self.pushes:
            if t0 <= t_s < t1:
                wrench[:3] += force
