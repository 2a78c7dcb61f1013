"""A learned policy's contract: what it reads, in which order and scale, and what its output means.

One contract serves the policy's training (:mod:`taslel_bench.learn.env`, many environments at once) and its
deployment in a run (:class:`taslel_bench.control.policy.PolicyController`, one robot): both build observations
with :class:`ObservationBuilder` from a :class:`PolicyState`, so a policy sees in the harness exactly what it saw
in training. A contract is written in a policy's YAML (``conf/policy/<name>.yaml``, keys in
``docs/guides/learned-policy.md``) and read by :func:`contract_from_mapping`.

**Observation vocabulary** (:data:`TERMS`), each term a row block of the observation vector, in the contract's
order; each has a scale (a number or one per component), a clip (applied after the scale) and a history length
(the last ``history`` values, oldest first):

* ``base_lin_vel``: trunk linear velocity [m/s], trunk axes. **Privileged**: a real robot has no sensor for it
  (it needs a state estimator fusing leg kinematics and the IMU);
* ``base_ang_vel``: trunk angular velocity [rad/s], trunk axes (the IMU's gyro);
* ``projected_gravity``: the unit gravity direction in trunk axes [-] (the IMU's attitude);
* ``joint_pos``: joint angles minus the default pose [rad], the policy's joint order (encoders);
* ``joint_vel``: joint velocities [rad/s], the policy's joint order (encoders);
* ``last_action``: the policy's previous output [-] (what it asked for);
* ``velocity_command``: the command (forward [m/s], lateral [m/s], yaw rate [rad/s]), trunk heading frame.

**Action** (``action.kind``): ``joint_position`` -- target = default pose + scale x action [rad], then joint PD
``kp (target - q) - kd qd`` [N·m] at the control rate, clipped to the robot's torque limits; ``joint_torque`` --
torque = scale x action [N·m], clipped likewise. The policy runs at ``rate_hz``; the PD (and a safety filter)
run at the control rate between its steps.

Arrays: batched over environments on axis 0; joint vectors in the core order
(:data:`taslel_bench.robot.quadruped.JOINT_NAMES`) unless named "policy order".
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from taslel_bench.robot import quadruped as quad
from taslel_bench.util.fields import ConfigError


@dataclass(frozen=True)
class TermSpec:
    size: int  # components per history entry
    privileged: bool  # True: a real robot cannot measure it
    meaning: str


TERMS: dict[str, TermSpec] = {
    "base_lin_vel": TermSpec(3, True, "trunk linear velocity, trunk axes [m/s] (needs a state estimator)"),
    "base_ang_vel": TermSpec(3, False, "trunk angular velocity, trunk axes [rad/s] (gyro)"),
    "projected_gravity": TermSpec(3, False, "unit gravity direction, trunk axes [-] (IMU attitude)"),
    "joint_pos": TermSpec(12, False, "joint angles minus the default pose [rad] (encoders)"),
    "joint_vel": TermSpec(12, False, "joint velocities [rad/s] (encoders)"),
    "last_action": TermSpec(12, False, "the policy's previous output [-]"),
    "velocity_command": TermSpec(3, False, "forward [m/s], lateral [m/s], yaw rate [rad/s]"),
}
ACTION_KINDS = ("joint_position", "joint_torque")


@dataclass(frozen=True)
class ObservationTerm:
    term: str  # one of TERMS
    scale: tuple[float, ...]  # one per component (a single value is broadcast)
    clip: float  # |scaled value| is clipped to this
    history: int  # entries kept, oldest first

    @property
    def size(self) -> int:
        return TERMS[self.term].size * self.history


@dataclass(frozen=True)
class ActionSpec:
    kind: str  # one of ACTION_KINDS
    scale: float  # [rad] or [N·m] per unit of action
    clip: float  # |action| is clipped to this before scaling
    kp: float  # [N·m/rad] joint PD stiffness (joint_position)
    kd: float  # [N·m·s/rad] joint PD damping (joint_position)


@dataclass(frozen=True)
class PolicyContract:
    name: str
    robot: str  # the robot it was trained for (conf/robot/<name>)
    onnx: str  # the ONNX file's path
    onnx_sha256: str  # its SHA-256 ("" : not checked)
    rate_hz: float  # [Hz] policy steps per second
    observations: tuple[ObservationTerm, ...]
    action: ActionSpec
    joint_order: tuple[str, ...]  # policy joint i = core joint named joint_order[i]
    default_pose: tuple[float, ...]  # [rad] (12,) policy order
    stance_s: float  # [s] typical stance duration of its gait on flat ground (the contact plan's expectation)
    swing_s: float  # [s] typical swing duration

    @property
    def obs_size(self) -> int:
        return sum(t.size for t in self.observations)

    @property
    def core_from_policy(self) -> np.ndarray:
        """Index array: core joint vector = policy vector[core_from_policy]."""
        policy_index = {name: i for i, name in enumerate(self.joint_order)}
        return np.array([policy_index[name] for name in quad.JOINT_NAMES])

    @property
    def policy_from_core(self) -> np.ndarray:
        """Index array: policy joint vector = core vector[policy_from_core]."""
        return np.array([quad.JOINT_NAMES.index(name) for name in self.joint_order])

    @property
    def privileged_terms(self) -> list[str]:
        return [t.term for t in self.observations if TERMS[t.term].privileged]

    def layout(self) -> list[tuple[str, slice]]:
        """(term, its columns of the observation vector), in order."""
        out, start = [], 0
        for t in self.observations:
            out.append((t.term, slice(start, start + t.size)))
            start += t.size
        return out


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def contract_from_mapping(node: dict, where: str) -> PolicyContract:
    """A contract from a policy YAML's keys (``where``: the file or config key, named in errors). Every error
    names the key, the value and what is valid."""
    def need(key: str):
        if key not in node or node[key] is None:
            raise ConfigError(f"{where}: {key} is missing (a policy contract needs name, robot, onnx, rate_hz, "
                              "observations, action, default_pose)")
        return node[key]

    terms = []
    raw_terms = need("observations")
    if not isinstance(raw_terms, (list, tuple)) or not raw_terms:
        raise ConfigError(f"{where}: observations={raw_terms!r}: must be a non-empty list of terms")
    for i, entry in enumerate(raw_terms):
        terms.append(_term(dict(entry), f"{where}: observations[{i}]"))
    action = _action(dict(need("action")), f"{where}: action")
    order = tuple(str(n) for n in (node.get("joint_order") or quad.JOINT_NAMES))
    if sorted(order) != sorted(quad.JOINT_NAMES):
        raise ConfigError(f"{where}: joint_order={list(order)!r}: must name each of the core joints once: "
                          f"{list(quad.JOINT_NAMES)}")
    pose = tuple(float(x) for x in need("default_pose"))
    if len(pose) != quad.N_JOINTS:
        raise ConfigError(f"{where}: default_pose has {len(pose)} values; needs {quad.N_JOINTS} [rad], policy order")
    rate = float(need("rate_hz"))
    if not 0.0 < rate <= 1000.0:
        raise ConfigError(f"{where}: rate_hz={rate!r}: must be in (0, 1000] [Hz]")
    gait = dict(node.get("gait") or {})
    stance_s, swing_s = float(gait.get("stance_s", 0.2)), float(gait.get("swing_s", 0.2))
    for key, value in (("gait.stance_s", stance_s), ("gait.swing_s", swing_s)):
        if not 0.0 < value <= 2.0:
            raise ConfigError(f"{where}: {key}={value!r}: must be in (0, 2] [s]")
    return PolicyContract(name=str(need("name")), robot=str(need("robot")), onnx=str(need("onnx")),
                          onnx_sha256=str(node.get("onnx_sha256") or ""), rate_hz=rate, observations=tuple(terms),
                          action=action, joint_order=order, default_pose=pose, stance_s=stance_s, swing_s=swing_s)


def _term(entry: dict, where: str) -> ObservationTerm:
    name = entry.get("term")
    if name not in TERMS:
        raise ConfigError(f"{where}: term={name!r}: unknown; valid terms: {', '.join(TERMS)}")
    size = TERMS[name].size
    scale = entry.get("scale", 1.0)
    scale_t = tuple(float(s) for s in (scale if isinstance(scale, (list, tuple)) else [scale] * size))
    if len(scale_t) != size:
        raise ConfigError(f"{where} ({name}): scale has {len(scale_t)} values; needs 1 or {size}")
    clip = float(entry.get("clip", 100.0))
    history = int(entry.get("history", 1))
    if not clip > 0.0:
        raise ConfigError(f"{where} ({name}): clip={clip!r}: must be > 0")
    if not 1 <= history <= 100:
        raise ConfigError(f"{where} ({name}): history={history!r}: must be an integer in [1, 100]")
    return ObservationTerm(str(name), scale_t, clip, history)


def _action(entry: dict, where: str) -> ActionSpec:
    kind = entry.get("kind", "joint_position")
    if kind not in ACTION_KINDS:
        raise ConfigError(f"{where}: kind={kind!r}: unknown; valid: {', '.join(ACTION_KINDS)}")
    spec = ActionSpec(str(kind), float(entry.get("scale", 0.25)), float(entry.get("clip", 100.0)),
                      float(entry.get("kp", 0.0)), float(entry.get("kd", 0.0)))
    if not spec.scale > 0.0 or not spec.clip > 0.0:
        raise ConfigError(f"{where}: scale={spec.scale!r}, clip={spec.clip!r}: both must be > 0")
    if kind == "joint_position" and not (spec.kp > 0.0 and spec.kd >= 0.0):
        raise ConfigError(f"{where}: kp={spec.kp!r}, kd={spec.kd!r}: joint_position needs kp > 0 [N·m/rad] and "
                          "kd >= 0 [N·m·s/rad]")
    return spec


def contract_to_mapping(c: PolicyContract) -> dict:
    """The YAML keys of a contract (what :func:`contract_from_mapping` reads)."""
    return {
        "name": c.name, "robot": c.robot, "onnx": c.onnx, "onnx_sha256": c.onnx_sha256, "rate_hz": c.rate_hz,
        "observations": [{"term": t.term, "scale": list(t.scale) if len(set(t.scale)) > 1 else t.scale[0],
                          "clip": t.clip, "history": t.history} for t in c.observations],
        "action": {"kind": c.action.kind, "scale": c.action.scale, "clip": c.action.clip, "kp": c.action.kp,
                   "kd": c.action.kd},
        "joint_order": list(c.joint_order), "default_pose": list(c.default_pose),
        "gait": {"stance_s": c.stance_s, "swing_s": c.swing_s},
    }  # fmt: skip


# ----------------------------------------------------------------------------------------------- state


@dataclass
class PolicyState:
    """What the observation terms are made of, for N robots (arrays (N, ...))."""

    base_lin_vel: np.ndarray  # [m/s] (N, 3) trunk axes
    base_ang_vel: np.ndarray  # [rad/s] (N, 3) trunk axes
    projected_gravity: np.ndarray  # [-] (N, 3) trunk axes
    q_joints: np.ndarray  # [rad] (N, 12) core order
    qd_joints: np.ndarray  # [rad/s] (N, 12) core order
    last_action: np.ndarray  # [-] (N, 12) policy order
    command: np.ndarray  # (N, 3) forward [m/s], lateral [m/s], yaw rate [rad/s]


def projected_gravity(quat_wxyz: np.ndarray) -> np.ndarray:
    """(N, 3) the world's -z axis in trunk axes for trunk quaternions (N, 4) (w, x, y, z; world <- trunk)."""
    w, x, y, z = (quat_wxyz[:, i] for i in range(4))
    # third row of R (world <- trunk), negated: R^T (0, 0, -1)
    return -np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)


class ObservationBuilder:
    """The observation vectors (N, contract.obs_size) of a contract, with each term's history."""

    def __init__(self, contract: PolicyContract, n: int) -> None:
        self.c = contract
        self.n = n
        self._order = contract.policy_from_core
        self._pose = np.asarray(contract.default_pose)
        self._history = {i: np.zeros((n, t.history, TERMS[t.term].size)) for i, t in enumerate(contract.observations)
                         if t.history > 1}
        self._filled = np.zeros(n, bool)  # False: the next build fills the whole history with the current value

    def reset(self, ids: np.ndarray | None = None) -> None:
        """Forget the history of environments ``ids`` (all: None)."""
        self._filled[slice(None) if ids is None else ids] = False

    def raw(self, s: PolicyState, term: str) -> np.ndarray:
        """One term's current value (N, size), unscaled."""
        if term == "base_lin_vel":
            return s.base_lin_vel
        if term == "base_ang_vel":
            return s.base_ang_vel
        if term == "projected_gravity":
            return s.projected_gravity
        if term == "joint_pos":
            return s.q_joints[:, self._order] - self._pose
        if term == "joint_vel":
            return s.qd_joints[:, self._order]
        if term == "last_action":
            return s.last_action
        if term == "velocity_command":
            return s.command
        raise KeyError(term)

    def build(self, s: PolicyState) -> np.ndarray:
        """The observations (N, obs_size) of this policy step (histories advance by one entry)."""
        parts = []
        for i, t in enumerate(self.c.observations):
            value = np.clip(self.raw(s, t.term) * np.asarray(t.scale), -t.clip, t.clip)
            h = self._history.get(i)
            if h is not None:
                h[:, :-1] = h[:, 1:]
                h[:, -1] = value
                fresh = ~self._filled
                if fresh.any():
                    h[fresh] = value[fresh, None, :]
                value = h.reshape(self.n, -1)
            parts.append(value)
        self._filled[:] = True
        return np.concatenate(parts, axis=1).astype(np.float32)


def action_to_targets(contract: PolicyContract, action: np.ndarray) -> np.ndarray:
    """(N, 12) core order: joint position targets [rad] (``joint_position``) or torques [N·m] (``joint_torque``)
    from policy outputs (N, 12) policy order."""
    a = contract.action
    scaled = np.clip(action, -a.clip, a.clip) * a.scale
    if a.kind == "joint_position":
        scaled = scaled + np.asarray(contract.default_pose)
    return scaled[:, contract.core_from_policy]


def joint_torques(contract: PolicyContract, targets: np.ndarray, q: np.ndarray, qd: np.ndarray,
                  limits: np.ndarray) -> np.ndarray:  # fmt: skip
    """(N, 12) [N·m] core order: the PD law towards ``targets`` (joint_position) or the targets themselves
    (joint_torque), clipped to ``limits`` (12,) [N·m]."""
    a = contract.action
    tau = a.kp * (targets - q) - a.kd * qd if a.kind == "joint_position" else targets
    return np.clip(tau, -limits, limits)
