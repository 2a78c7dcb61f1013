"""The sim side of the viewer: a MuJoCo Studio sim plugin that plays the recorded states instead of simulating.

It takes the place of Studio's ``StepControl`` (stepping) and ``SimHistory`` (the history scrubber) and speaks their
messages, so Studio's own Run/Pause button, speed setting, single step and timeline scrubber drive the replay:

* the history it announces (``SimHistorySnapshot``) is the whole recording, one frame per control tick (index 0 =
  the last tick, ``1 - n`` = the first); a scrub request (the scrubber, the arrow keys, the run panel's timeline
  and event buttons) poses the plant at that tick and pauses;
* running plays the recording at the chosen speed (percent of real time) and pauses on its last tick;
* every frame sets the plant's ``qpos``, ``qvel`` (free joint: linear velocity in world axes, angular in trunk
  axes, as MuJoCo stores them), ``ctrl`` (the tick's applied torques [N·m]) and ``time`` (the end of the tick [s])
  from ``steps.parquet``; nothing is integrated. Studio's viewer then runs ``mj_forward`` on that state.
"""

from __future__ import annotations

import time

import mujoco
import numpy as np
from mujoco.studio import (
    messages,
    plugin,
    sim,  # pyright: ignore[reportAttributeAccessIssue] compiled, set up by mujoco.studio
)
from mujoco.studio.sim_history import SimHistorySnapshot

from taslel_bench.record.video import qpos_addresses
from taslel_bench.robot import quadruped as quad
from taslel_bench.view.recording import Recording

IDLE_SLEEP_S = 0.01  # [s] wall time yielded per sync loop iteration (Studio's own stepping yields 1 ms)


def has_the_robot(model) -> bool:
    """``model`` has a free joint and every joint of ``quad.JOINT_NAMES`` (the recorded state fits it)."""
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) for name in quad.JOINT_NAMES]
    return min(joints) >= 0 and bool((model.jnt_type == mujoco.mjtJoint.mjJNT_FREE).any())


def qvel_addresses(model) -> np.ndarray:
    """qvel indices of :data:`taslel_bench.view.recording.VELOCITY_COLUMNS`: the free joint's 6, then the 12 joints."""
    free = next(j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    joints = [model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)] for name in quad.JOINT_NAMES]
    return np.array([*range(model.jnt_dofadr[free], model.jnt_dofadr[free] + 6), *joints])


def ctrl_columns(model) -> np.ndarray:
    """For each actuator, the column of :attr:`Recording.torque_nm` of the joint it drives (-1: none)."""
    names = list(quad.JOINT_NAMES)
    cols = []
    for a in range(model.nu):
        joint = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, int(model.actuator_trnid[a, 0]))
        cols.append(names.index(joint) if joint in names else -1)
    return np.array(cols, dtype=int)


class RecordingPlayback(plugin.SimPlugin):
    """Poses the plant from a :class:`Recording`, frame by frame, under Studio's step controls."""

    def __init__(self, recording: Recording, start_row: int = 0, play: bool = False) -> None:
        self.rec = recording
        self.row = int(np.clip(start_row, 0, recording.n - 1))
        self.step_control = sim.StepControl()
        self.step_control.set_pause_state(sim.PauseState.UNPAUSED if play else sim.PauseState.NORMAL_PAUSED)
        self._clock_s = recording.state_time(self.row)  # [s] playback time (simulated)
        self._wall = time.monotonic()
        self._posed: tuple[int, int] | None = None  # (id of the MjData, row) last written
        self._announced = (-1, -1.0)  # (row, speed) last sent to the viewer
        self._active = False  # the current model is the run's plant (set on each model)

    # ------------------------------------------------------------------ model and state
    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_post_model(self, event: messages.PostModelEvent) -> None:
        """A model arrives (the run's plant; or a file dropped on the page: not posed, Studio shows it as it is)."""
        self._active = has_the_robot(event.model)
        if self._active:
            self._qadr, self._vadr = qpos_addresses(event.model), qvel_addresses(event.model)
            self._ctrl = ctrl_columns(event.model)
        self._posed, self._announced = None, (-1, -1.0)

    def pose(self, model, data) -> None:
        """Write row :attr:`row` into ``data`` (positions, velocities, torques, time) and run ``mj_forward``."""
        if not self._active or self._posed == (id(data), self.row):
            return
        r = self.row
        data.qpos[self._qadr] = self.rec.state[r]
        data.qvel[:] = 0.0
        data.qvel[self._vadr] = self.rec.velocity[r]
        driven = self._ctrl >= 0
        data.ctrl[:] = 0.0
        data.ctrl[driven] = self.rec.torque_nm[r, self._ctrl[driven]]
        data.time = self.rec.state_time(r)
        mujoco.mj_forward(model, data)
        self._posed = (id(data), r)

    # ------------------------------------------------------------------ stepping (in place of StepControl)
    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_step(self, event: messages.StepEvent) -> None:
        now = time.monotonic()
        wall_s, self._wall = now - self._wall, now
        if self.step_control.get_pause_state() == sim.PauseState.UNPAUSED:
            self._clock_s += wall_s * self.step_control.get_speed() / 100.0
            self.row = self.rec.row_at(self._clock_s)
            if self.row == self.rec.n - 1:
                self._set_paused(True)
        self.pose(event.model, event.data)
        self._announce()
        time.sleep(IDLE_SLEEP_S)  # sync() never sleeps: without this the loop spins a core

    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_step_control(self, event: messages.StepControlSnapshot) -> bool:
        was_paused = self.step_control.get_pause_state() != sim.PauseState.UNPAUSED
        self.step_control.set_speed(event.speed)
        if was_paused and event.pause_state == sim.PauseState.UNPAUSED and self.row == self.rec.n - 1:
            self.seek(0)  # Run at the end plays again from the start
        self._set_paused(event.pause_state != sim.PauseState.UNPAUSED)
        return True

    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_pause(self, event: messages.RequestPauseEvent) -> bool:
        self._set_paused(event.pause_state != sim.PauseState.UNPAUSED)
        return True

    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_single_step(self, _: messages.SingleStepEvent) -> bool:
        self.seek(min(self.row + 1, self.rec.n - 1))
        return True

    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_reset(self, _: messages.ResetEvent) -> None:
        self._posed = None  # Studio reset the data: pose it again even on the same row
        self.seek(0)

    # ------------------------------------------------------------------ history (in place of SimHistory)
    @messages.handler(priority=messages.Priority.INTERNAL)
    def _on_scrub(self, snapshot: SimHistorySnapshot) -> bool:
        """A scrub request: ``index`` 0 is the last tick, ``1 - n`` the first; the replay pauses there."""
        self.seek(self.rec.n - 1 + int(snapshot.index))
        self._set_paused(True)
        return True

    def seek(self, row: int) -> None:
        """Show row ``row`` next (clipped to the recording); the playback clock continues from there."""
        self.row = int(np.clip(row, 0, self.rec.n - 1))
        self._clock_s = self.rec.state_time(self.row)

    def _set_paused(self, paused: bool) -> None:
        state = sim.PauseState.NORMAL_PAUSED if paused else sim.PauseState.UNPAUSED
        if self.step_control.get_pause_state() != state:
            self.step_control.set_pause_state(state)
            self._announced = (self._announced[0], -1.0)  # send the step controls again

    def _announce(self) -> None:
        """Tell the viewer the history (size, current index, times) and the step controls when they changed."""
        key = (self.row, self.step_control.get_speed() * (1 if self._paused() else -1))
        if key == self._announced:
            return
        if key[1] != self._announced[1]:
            speed = self.step_control.get_speed()  # the replay keeps the set speed (to a tick)
            self.handle.send_to_viewer(messages.StepControlSnapshot.from_step_control(self.step_control, speed))
        self._announced = key
        self.handle.send_to_viewer(SimHistorySnapshot(
            size=self.rec.n, index=self.row - (self.rec.n - 1), head_time=self.rec.state_time(self.rec.n - 1),
            tail_time=self.rec.state_time(0)))  # fmt: skip

    def _paused(self) -> bool:
        return self.step_control.get_pause_state() != sim.PauseState.UNPAUSED
