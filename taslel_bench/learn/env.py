"""Many walking environments of one robot on flat ground, stepped together through ``mujoco.batch``, as an
``rsl_rl`` vectorised environment.

The plant is the benchmark's own (:func:`taslel_bench.sim.build.build_plant_model` of ``robot=<name>
scenario=flat``), with the physics step of the training (``physics_dt_s``); per environment the ground friction
and the trunk's mass are drawn at every reset (``mujoco.batch``'s per-simulation model fields). Each policy step
holds the policy's joint targets for ``physics steps per policy step`` physics steps, the joint PD recomputed
before each (as the benchmark's control loop does at its control rate). Observations come from the policy's
contract (:class:`taslel_bench.control.policy_contract.ObservationBuilder`, the one the benchmark's policy
controller uses), with uniform noise added here only.

A fall is the benchmark's: the trunk origin below the robot's ``fall_height_m`` or tilted beyond
``fall_tilt_deg``. Frames: MuJoCo's free joint gives the trunk's linear velocity in world axes and its angular
velocity in trunk axes; observations and rewards use trunk axes for both.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import torch
from hydra.utils import instantiate
from mujoco import batch as mj_batch
from tensordict import TensorDict

from taslel_bench.config.compose import compose
from taslel_bench.config.settings import build_controller, plant_options, robot_description
from taslel_bench.control.policy_contract import (
    TERMS,
    ActionSpec,
    ObservationBuilder,
    ObservationTerm,
    PolicyContract,
    PolicyState,
    action_to_targets,
    joint_torques,
    projected_gravity,
)
from taslel_bench.learn.config import TrainingConfig
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.build import compile_plant
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.build import build_plant_spec

# the observation terms of the policies trained here, in order: (term, scale) (legged_gym's scales)
TRAINED_TERMS: tuple[tuple[str, float | tuple[float, ...]], ...] = (
    ("base_lin_vel", 2.0), ("base_ang_vel", 0.25), ("projected_gravity", 1.0), ("velocity_command", (2.0, 2.0, 0.25)),
    ("joint_pos", 1.0), ("joint_vel", 0.05), ("last_action", 1.0))  # fmt: skip


def training_contract(cfg: TrainingConfig, default_pose_core: np.ndarray, onnx: str = "") -> PolicyContract:
    """The contract of a policy trained with ``cfg`` (joint order: the core's)."""
    terms = tuple(ObservationTerm(name, scale if isinstance(scale, tuple) else (float(scale),) * TERMS[name].size,
                                  100.0, 1) for name, scale in TRAINED_TERMS)  # fmt: skip
    return PolicyContract(name=cfg.name, robot=cfg.robot, onnx=onnx, onnx_sha256="", rate_hz=cfg.policy_rate_hz,
                          observations=terms, action=ActionSpec("joint_position", cfg.action_scale, 100.0, cfg.kp,
                                                                cfg.kd),
                          joint_order=quad.JOINT_NAMES, default_pose=tuple(float(x) for x in default_pose_core),
                          stance_s=0.2, swing_s=0.2)


# bodies whose touching the ground is a collision (penalised; the trunk's ends the episode)
_COLLISION_BODIES = (quad.TRUNK_BODY,) + tuple(f"{leg}_{part}" for leg in quad.LEGS for part in ("hip", "thigh"))


def _training_plant(hcfg, robot, cfg: TrainingConfig) -> mujoco.MjModel:
    """The benchmark's plant of ``robot`` on flat ground at the training's physics step, with a contact sensor
    (number of contacts) on each of :data:`_COLLISION_BODIES`."""
    spec = build_plant_spec(instantiate(hcfg.scenario), plant_options(hcfg, robot), cfg.seed,
                            np.random.default_rng(cfg.seed), None, robot)
    for body in _COLLISION_BODIES:
        sensor = spec.add_sensor(name=f"{body}_touch", type=mujoco.mjtSensor.mjSENS_CONTACT,
                                 objtype=mujoco.mjtObj.mjOBJ_BODY, objname=body)
        sensor.intprm[:3] = (1, 0, 1)  # data: found (the number of contacts)
    m = compile_plant(spec)
    m.opt.timestep = cfg.physics_dt_s
    return m


class WalkingEnv:
    """``cfg.n_envs`` environments (module doc); implements rsl_rl's ``VecEnv`` (get_observations, step)."""

    def __init__(self, cfg: TrainingConfig, device: str = "cpu") -> None:
        self.cfg = cfg
        self.device = device
        hcfg = compose([f"robot={cfg.robot}", "scenario=flat"])
        self.robot = robot_description(hcfg)
        m = _training_plant(hcfg, self.robot, cfg)
        self.m = m
        self.bridge = StateBridge(m)
        stand = build_controller(hcfg, self.robot).stand_configuration()
        self.contract = training_contract(cfg, stand)
        self.num_envs = n = cfg.n_envs
        self.num_actions = quad.N_JOINTS
        self.decimation = round(1.0 / (cfg.policy_rate_hz * cfg.physics_dt_s))
        if abs(self.decimation * cfg.physics_dt_s * cfg.policy_rate_hz - 1.0) > 1e-9:
            raise ValueError(f"policy_rate_hz={cfg.policy_rate_hz} is not a whole number of physics steps of "
                             f"physics_dt_s={cfg.physics_dt_s}")
        self.dt = self.decimation * cfg.physics_dt_s  # [s] policy step
        self.max_episode_length = round(cfg.episode_s / self.dt)
        self._resample_steps = round(cfg.command_resample_s / self.dt)
        self.rng = np.random.default_rng(cfg.seed)
        self.batch = mj_batch.Batch(m, n, cfg.nthread, persistent=True)
        b = self.batch
        self.qpos, self.qvel, self.ctrl = b.bind("qpos"), b.bind("qvel"), b.bind("ctrl")
        self.sensordata, self.ncon = b.bind("sensordata"), b.bind("ncon")
        self._floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        self._trunk = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, quad.TRUNK_BODY)
        self.geom_friction = b.expand("geom_friction")
        self.body_mass = b.expand("body_mass")
        # the payload: one per environment for the whole training (mj_setConst of every simulation costs ~14 ms)
        self.body_mass[:, self._trunk] = m.body_mass[self._trunk] + self.rng.uniform(*cfg.added_mass_kg, cfg.n_envs)
        b.set_const()  # the derived masses and inertias follow
        a, d = self.bridge.free_qadr, self.bridge.free_dadr
        self._pos, self._quat = slice(a, a + 3), slice(a + 3, a + 7)
        self._lin, self._ang = slice(d, d + 3), slice(d + 3, d + 6)
        self._jq, self._jd, self._act = self.bridge.joint_qadr, self.bridge.joint_dadr, self.bridge.actuator_ids
        found = [m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, f"{f}_contact")]
                 for f in quad.FOOT_FRAMES]
        self._found_rows = np.array(found)
        self._body_rows = np.array([m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, f"{b}_touch")]
                                    for b in _COLLISION_BODIES])
        self._trunk_row = self._body_rows[0]
        self._limits = self.robot.torque_limits
        lo, hi = m.jnt_range[[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in quad.JOINT_NAMES]].T
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * cfg.rewards.soft_dof_limit
        self._soft_lo, self._soft_hi = mid - half, mid + half
        self._stand = np.asarray(stand, float)
        self.builder = ObservationBuilder(self.contract, n)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long)
        self.actions = np.zeros((n, 12))
        self.last_actions = np.zeros((n, 12))
        self.last_qd = np.zeros((n, 12))
        self.command = np.zeros((n, 3))
        self.air_time = np.zeros((n, 4))
        self.last_contact = np.zeros((n, 4), bool)
        self._sums: dict[str, np.ndarray] = {}
        self.env_steps = 0  # policy steps of all environments
        self.physics_steps = 0
        self._reset(np.arange(n))
        self._obs = self._observe()

    # --------------------------------------------------------------------------------------------- state
    def _trunk_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(linear velocity, angular velocity, projected gravity), each (N, 3), trunk axes."""
        quat = self.qpos[:, self._quat]
        g = projected_gravity(quat)
        w, x, y, z = (quat[:, i] for i in range(4))
        # R (world <- trunk) rows; v_trunk = R^T v_world
        r = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)
        v = np.einsum("nij,ni->nj", r, self.qvel[:, self._lin])
        return v, self.qvel[:, self._ang].copy(), g

    def _state(self) -> PolicyState:
        v, w, g = self._trunk_state()
        return PolicyState(v, w, g, self.qpos[:, self._jq], self.qvel[:, self._jd], self.actions, self.command)

    def _observe(self) -> np.ndarray:
        s = self._state()
        noise = self.cfg.noise
        if noise:
            for name in ("base_lin_vel", "base_ang_vel", "projected_gravity"):
                getattr(s, name)[:] += self.rng.uniform(-1, 1, (self.num_envs, 3)) * noise.get(name, 0.0)
            s.q_joints = s.q_joints + self.rng.uniform(-1, 1, s.q_joints.shape) * noise.get("joint_pos", 0.0)
            s.qd_joints = s.qd_joints + self.rng.uniform(-1, 1, s.qd_joints.shape) * noise.get("joint_vel", 0.0)
        return self.builder.build(s)

    def get_observations(self) -> TensorDict:
        obs = torch.from_numpy(self._obs)
        return TensorDict({"policy": obs}, batch_size=[self.num_envs])

    # ---------------------------------------------------------------------------------------------- step
    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        a = np.clip(actions.detach().cpu().numpy().astype(float), -100.0, 100.0)
        self.last_actions[:] = self.actions
        self.actions[:] = a
        targets = action_to_targets(self.contract, a)
        contact_any = np.zeros((self.num_envs, 4), bool)
        tau_sq = np.zeros(self.num_envs)
        collided = np.zeros(self.num_envs, bool)
        trunk_hit = np.zeros(self.num_envs, bool)
        for _ in range(self.decimation):
            q, qd = self.qpos[:, self._jq], self.qvel[:, self._jd]
            tau = joint_torques(self.contract, targets, q, qd, self._limits)
            self.ctrl[:, self._act] = tau
            self.batch.step(nstep=1)
            found = self.sensordata[:, self._found_rows] > 0
            contact_any |= found
            collided |= (self.sensordata[:, self._body_rows] > 0).any(1)  # trunk, a hip or a thigh
            trunk_hit |= self.sensordata[:, self._trunk_row] > 0
            tau_sq += (tau * tau).sum(1)
        self.physics_steps += self.decimation * self.num_envs
        self.env_steps += self.num_envs
        self.episode_length_buf += 1
        rew, terms = self._rewards(contact_any, collided, tau_sq / self.decimation)
        fell = self._fell() | trunk_hit
        time_out = self.episode_length_buf.numpy() >= self.max_episode_length
        rew += self.cfg.rewards.termination * fell * self.dt
        done = fell | time_out
        resample = (self.episode_length_buf.numpy() % self._resample_steps == 0) & ~done
        if resample.any():
            self._sample_commands(np.flatnonzero(resample))
        extras = {"time_outs": torch.from_numpy(time_out & ~fell), "log": self._log(terms, done, fell)}
        ids = np.flatnonzero(done)
        if ids.size:
            self._reset(ids)
        self.last_qd[:] = self.qvel[:, self._jd]
        self._obs = self._observe()
        return self.get_observations(), torch.from_numpy(rew.astype(np.float32)), torch.from_numpy(done), extras

    def _fell(self) -> np.ndarray:
        z = self.qpos[:, self._pos][:, 2]
        g = projected_gravity(self.qpos[:, self._quat])
        tilt_cos = -g[:, 2]
        return (z < self.robot.fall_height_m) | (tilt_cos < math.cos(math.radians(self.robot.fall_tilt_deg)))

    def _rewards(self, contact: np.ndarray, collided: np.ndarray, tau_sq: np.ndarray
                 ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        r, dt = self.cfg.rewards, self.dt
        v, w, g = self._trunk_state()
        q, qd = self.qpos[:, self._jq], self.qvel[:, self._jd]
        first_contact = contact & ~self.last_contact & (self.air_time > 0.0)
        self.air_time += dt
        moving = np.linalg.norm(self.command[:, :2], axis=1) > 0.1
        air = ((self.air_time - r.feet_air_time_target) * first_contact).sum(1) * moving
        self.air_time[contact] = 0.0
        self.last_contact = contact
        terms = {
            "tracking_lin_vel": np.exp(-((v[:, :2] - self.command[:, :2]) ** 2).sum(1) / r.tracking_sigma),
            "tracking_ang_vel": np.exp(-(w[:, 2] - self.command[:, 2]) ** 2 / r.tracking_sigma),
            "lin_vel_z": v[:, 2] ** 2,
            "ang_vel_xy": (w[:, :2] ** 2).sum(1),
            "orientation": (g[:, :2] ** 2).sum(1),
            "torques": tau_sq,
            "dof_acc": (((qd - self.last_qd) / dt) ** 2).sum(1),
            "action_rate": ((self.actions - self.last_actions) ** 2).sum(1),
            "feet_air_time": air,
            "collision": collided.astype(float),
            "dof_pos_limits": (np.clip(self._soft_lo - q, 0, None) + np.clip(q - self._soft_hi, 0, None)).sum(1),
        }
        total = np.zeros(self.num_envs)
        for name, value in terms.items():
            total += getattr(r, name) * value * dt
        return total, terms

    def _log(self, terms: dict[str, np.ndarray], done: np.ndarray, fell: np.ndarray) -> dict[str, float]:
        out = {f"Episode_Reward/{k}": float(np.mean(v)) for k, v in terms.items()}
        out["Metrics/fall_rate_per_s"] = float(fell.mean() / self.dt)
        v, _, _ = self._trunk_state()
        out["Metrics/forward_speed_error_mps"] = float(np.mean(np.abs(v[:, 0] - self.command[:, 0])))
        return out

    # --------------------------------------------------------------------------------------------- reset
    def _sample_commands(self, ids: np.ndarray) -> None:
        c, n = self.cfg, ids.size
        self.command[ids, 0] = self.rng.uniform(*c.command_vx, n)
        self.command[ids, 1] = self.rng.uniform(*c.command_vy, n)
        self.command[ids, 2] = self.rng.uniform(*c.command_yaw, n)
        self.command[ids[self.rng.random(n) < c.standing_share]] = 0.0

    def _reset(self, ids: np.ndarray) -> None:
        """New episodes for environments ``ids``: friction and payload drawn, the stand pose perturbed."""
        c, n = self.cfg, ids.size
        self.geom_friction[ids, self._floor, 0] = self.rng.uniform(*c.friction, n)
        self.batch.reset(ids, stage=mujoco.mjtStage.mjSTAGE_NONE)
        qpos = np.zeros((n, self.m.nq))
        qpos[:] = self.m.qpos0
        qpos[:, self._pos] = (0.0, 0.0, self.robot.stand_height_m + self.robot.foot_radius_m + 0.02)
        qpos[:, self._quat] = (1.0, 0.0, 0.0, 0.0)
        qpos[:, self._jq] = self._stand + self.rng.uniform(-1, 1, (n, 12)) * c.init_joint_noise_rad
        qvel = np.zeros((n, self.m.nv))
        qvel[:, self._lin] = self.rng.uniform(-1, 1, (n, 3)) * c.init_base_vel_mps * np.array([1.0, 1.0, 0.2])
        self.qpos[ids] = qpos
        self.qvel[ids] = qvel
        self.batch.forward(ids)
        self.episode_length_buf[torch.from_numpy(ids)] = 0
        self.actions[ids] = 0.0
        self.last_actions[ids] = 0.0
        self.last_qd[ids] = 0.0
        self.air_time[ids] = 0.0
        self.last_contact[ids] = False
        self._sample_commands(ids)
        self.builder.reset(ids)
