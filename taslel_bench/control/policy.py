"""A learned policy as the nominal controller (``controller=policy policy=<name>``): an ONNX file run with
onnxruntime under its contract (:mod:`taslel_bench.control.policy_contract`).

Every ``control rate / policy rate`` control ticks the policy reads its observations (built from the joint
encoders, the trunk's velocity and attitude, its last output and the command) and outputs joint targets; on every
control tick in between the joint PD of its contract tracks them (``joint_position``) or its torques are held
(``joint_torque``). The policy runs from the first tick with a zero command, so it holds its own stand, and gets
``command`` once ``stand_duration_s`` has passed. Its contact plan has no gait clock: it is estimated from joint
torques, kinematics and the IMU (:class:`taslel_bench.control.contact_plan_estimate.ContactPlanEstimate`).

At load, the ONNX file's SHA-256 is checked against the contract's (a changed file is refused, so a result is never
reused for another policy) and its input and output sizes against the contract's observation and action sizes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from taslel_bench.control.contact_plan_estimate import ContactPlanEstimate, PlanEstimateSettings
from taslel_bench.control.plan import ContactPlan
from taslel_bench.control.policy_contract import (
    ObservationBuilder,
    PolicyContract,
    PolicyState,
    action_to_targets,
    file_sha256,
    joint_torques,
    projected_gravity,
)
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import RobotDescription
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.util.fields import ConfigError

REPO = Path(__file__).resolve().parents[2]


def resolve_onnx(contract: PolicyContract, where: str) -> Path:
    """The contract's ONNX file: an absolute path, or relative to the working directory or to the repository."""
    path = Path(contract.onnx).expanduser()
    candidates = [path] if path.is_absolute() else [Path.cwd() / path, REPO / path]
    for c in candidates:
        if c.is_file():
            return c
    raise ConfigError(f"{where}: onnx={contract.onnx!r}: no such file (looked in "
                      f"{', '.join(str(c) for c in candidates)})")


class OnnxPolicy:
    """One ONNX policy session: (obs_size,) float32 -> (12,) actions."""

    def __init__(self, contract: PolicyContract, where: str) -> None:
        import onnxruntime as ort

        path = resolve_onnx(contract, where)
        if contract.onnx_sha256 and file_sha256(path) != contract.onnx_sha256:
            raise ConfigError(f"{where}: {path} has SHA-256 {file_sha256(path)}, the contract says "
                              f"{contract.onnx_sha256}: the file changed since the contract was written")
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1 or len(outputs) < 1:
            raise ConfigError(f"{where}: {path} has {len(inputs)} inputs and {len(outputs)} outputs; a policy has one "
                              "input (the observations) and its first output is the action")
        n_in, n_out = inputs[0].shape[-1], outputs[0].shape[-1]
        if n_in != contract.obs_size:
            terms = ", ".join(f"{t.term} {t.size}" for t in contract.observations)
            raise ConfigError(f"{where}: {path} input {inputs[0].name!r} has {n_in} values; the contract's "
                              f"observations have {contract.obs_size} ({terms})")
        if n_out != quad.N_JOINTS:
            raise ConfigError(f"{where}: {path} output {outputs[0].name!r} has {n_out} values; the action needs "
                              f"{quad.N_JOINTS} (one per joint)")
        self._input, self._output = inputs[0].name, outputs[0].name
        self.path = path
        self._contract, self._where = contract, where

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        out = self.session.run([self._output], {self._input: obs.reshape(1, -1).astype(np.float32)})[0]
        return np.asarray(out)[0]

    def __getstate__(self) -> dict:  # an onnxruntime session does not pickle: rebuilt from the contract on load
        return {"contract": self._contract, "where": self._where}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["contract"], state["where"])


class PolicyController:
    """The nominal controller of a learned policy (module doc); implements
    :class:`taslel_bench.control.plan.NominalControl`."""

    def __init__(self, contract: PolicyContract, robot: RobotDescription, control_dt_s: float, *,
                 command: tuple[float, float, float], stand_duration_s: float, plan: PlanEstimateSettings,
                 where: str = "policy") -> None:  # fmt: skip
        if contract.robot != robot.name:
            raise ConfigError(f"{where}: the policy {contract.name!r} was trained for robot {contract.robot!r}; this "
                              f"run's robot is {robot.name!r} (set robot={contract.robot})")
        self.contract = contract
        self.robot = robot
        self.policy = OnnxPolicy(contract, where)
        self.control_dt_s = float(control_dt_s)
        ticks = 1.0 / (contract.rate_hz * self.control_dt_s)
        self.ticks_per_step = round(ticks)
        if self.ticks_per_step < 1 or abs(ticks - self.ticks_per_step) > 1e-9:
            raise ConfigError(f"{where}: rate_hz={contract.rate_hz} is not a whole division of the control rate "
                              f"{1.0 / self.control_dt_s:g} Hz")
        self.command = np.asarray(command, float)
        self.stand_duration_s = float(stand_duration_s)
        self._builder = ObservationBuilder(contract, 1)
        self._default_core = np.asarray(contract.default_pose)[contract.core_from_policy]
        self._limits = robot.torque_limits
        self._targets = self._default_core[None, :].copy()  # (1, 12) core order: PD targets or torques
        self._last_action = np.zeros((1, quad.N_JOINTS))
        self._tick = 0
        self.estimate = ContactPlanEstimate(robot, contract.swing_s, control_dt_s, plan)
        kin = LegKinematics(robot)
        feet = [kin.leg_fk(i, self._default_core[3 * i: 3 * i + 3]) for i in range(quad.N_LEGS)]
        self._stand_height = float(-np.mean([f[2] for f in feet]))
        self.policy_steps = 0

    @property
    def stand_height_m(self) -> float:
        """[m] hip joint -> foot centre in the policy's default pose."""
        return self._stand_height

    @property
    def commanded_speed_mps(self) -> float:
        return float(self.command[0])

    @property
    def stance_swing_s(self) -> tuple[float, float]:
        """[s] the stance and swing durations of the policy's gait on flat ground (measured at training)."""
        return self.contract.stance_s, self.contract.swing_s

    def stand_configuration(self) -> np.ndarray:
        """[rad] (12,) core order: the policy's default pose."""
        return self._default_core.copy()

    def reset(self) -> None:
        self._targets[:] = self._default_core
        self._last_action[:] = 0.0
        self._tick = 0
        self._builder.reset()
        self.estimate.reset()
        self.policy_steps = 0

    def compute(self, t: float, q_joints: np.ndarray, qd_joints: np.ndarray, base_pose: np.ndarray | None = None,
                base_velocity: np.ndarray | None = None, tau_applied: np.ndarray | None = None) -> np.ndarray:
        """Torques [N·m] (12,) core order at episode time ``t`` [s] from the joint state [rad, rad/s], the trunk's
        pose (position [m], quaternion xyzw) and velocity (Pinocchio's: linear [m/s] and angular [rad/s], trunk
        axes), and the torques applied on the previous tick [N·m] (the contact plan's estimate)."""
        if base_pose is None or base_velocity is None:
            raise ValueError("PolicyController.compute needs the trunk's pose and velocity")
        quat_xyzw = base_pose[3:7]
        self.estimate.update(q_joints, tau_applied if tau_applied is not None else np.zeros(quad.N_JOINTS),
                             quat_xyzw)
        if self._tick % self.ticks_per_step == 0:
            self._policy_step(t, q_joints, qd_joints, quat_xyzw, base_velocity)
        self._tick += 1
        return joint_torques(self.contract, self._targets, q_joints[None, :], qd_joints[None, :], self._limits)[0]

    def _policy_step(self, t: float, q_joints: np.ndarray, qd_joints: np.ndarray, quat_xyzw: np.ndarray,
                     base_velocity: np.ndarray) -> None:  # fmt: skip
        x, y, z, w = quat_xyzw
        gravity = projected_gravity(np.array([[w, x, y, z]]))
        command = self.command if t >= self.stand_duration_s else np.zeros(3)
        state = PolicyState(base_velocity[None, :3], base_velocity[None, 3:6], gravity, q_joints[None, :],
                            qd_joints[None, :], self._last_action, command[None, :])
        action = self.policy(self._builder.build(state)).astype(float)
        self._last_action[0] = action
        self._targets = action_to_targets(self.contract, action[None, :])
        self.policy_steps += 1

    def contact_plan(self, t: float) -> ContactPlan:
        """The plan estimated on this tick's :meth:`compute` (all feet in stance before the first)."""
        return self.estimate.plan


def policy_controller(robot: RobotDescription, control_dt_s: float, terrain=None, *, contract: dict,
                      command: list[float], stand_duration: float, plan: dict) -> PolicyController:
    """``controller=policy``'s builder (its keys: the schema's PolicyControllerConfig; ``contract``: the
    ``policy`` group's node)."""
    from taslel_bench.control.policy_contract import contract_from_mapping

    where = f"policy={contract.get('name', '?')}"
    c = contract_from_mapping(dict(contract), where)
    return PolicyController(c, robot, control_dt_s, command=(float(command[0]), float(command[1]), float(command[2])),
                            stand_duration_s=float(stand_duration),
                            plan=PlanEstimateSettings(**{k: float(v) for k, v in plan.items()}), where=where)
