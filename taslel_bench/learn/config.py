"""The settings of one policy's training: the world it sees, the randomisation, the rewards and PPO's.

The policy sees flat ground only, with a friction drawn per episode from ``friction``, a payload per environment
from ``added_mass_kg``, its initial joint angles and trunk velocity perturbed and noise on its observations; nothing
else (no pushes, no low friction, no obstacles, no slopes): those are the benchmark's worlds it was never trained
on. Units are SI; rewards are per second of simulated time (each is multiplied by the policy step).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


@dataclass
class Rewards:
    """Weights of the reward terms (legged_gym's flat-ground set)."""

    tracking_lin_vel: float = 1.0  # exp(-|v_xy - cmd_xy|^2 / tracking_sigma)
    tracking_ang_vel: float = 0.5  # exp(-(w_z - cmd_yaw)^2 / tracking_sigma)
    lin_vel_z: float = -2.0  # v_z^2 [m²/s²]
    ang_vel_xy: float = -0.05  # |w_xy|^2 [rad²/s²]
    orientation: float = -0.5  # |projected gravity_xy|^2
    torques: float = -2e-4  # |tau|^2 [N²m²]
    dof_acc: float = -2.5e-7  # |qdd|^2 [rad²/s⁴]
    action_rate: float = -0.01  # |a - a_prev|^2
    feet_air_time: float = 1.0  # sum over touchdowns of (air time - feet_air_time_target) [s], when commanded
    collision: float = -1.0  # a non-foot part of the robot touches the ground
    dof_pos_limits: float = -10.0  # [rad] beyond soft_dof_limit of the joint range
    termination: float = -0.0  # a fall
    tracking_sigma: float = 0.25  # [m²/s²]
    feet_air_time_target: float = 0.3  # [s]
    soft_dof_limit: float = 0.9  # [-] share of the joint range that is free of penalty


@dataclass
class PPOSettings:
    num_steps_per_env: int = 24  # policy steps per environment per iteration
    hidden_dims: tuple[int, ...] = (256, 128, 64)
    activation: str = "elu"
    init_noise_std: float = 1.0
    learning_rate: float = 1e-3
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    clip_param: float = 0.2
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.01
    desired_kl: float = 0.01
    max_grad_norm: float = 1.0
    obs_normalization: bool = True


@dataclass
class TrainingConfig:
    name: str = "a1_walk"  # the policy's name (conf/policy/<name>.yaml)
    robot: str = "a1"  # conf/robot/<robot>.yaml
    seed: int = 0
    n_envs: int = 512
    nthread: int = 2  # mujoco.batch threads
    torch_threads: int = 1  # PPO's threads (measured: 2 threads on this 2-core machine made a linear layer 9x slower)
    iterations: int = 1500  # PPO iterations (stops earlier at max_minutes)
    max_minutes: float = 85.0  # [min] wall-clock budget of the whole training
    physics_dt_s: float = 0.005  # [s] training physics step (the benchmark runs the policy at its own rate)
    policy_rate_hz: float = 50.0  # [Hz]
    episode_s: float = 20.0  # [s]
    command_resample_s: float = 10.0  # [s]
    command_vx: tuple[float, float] = (-0.3, 1.0)  # [m/s]
    command_vy: tuple[float, float] = (-0.3, 0.3)  # [m/s]
    command_yaw: tuple[float, float] = (-0.5, 0.5)  # [rad/s]
    standing_share: float = 0.1  # [-] episodes whose command is zero
    friction: tuple[float, float] = (0.6, 1.25)  # [-] ground friction, one per episode
    added_mass_kg: tuple[float, float] = (-1.0, 1.0)  # [kg] on the trunk, one per environment
    init_joint_noise_rad: float = 0.1  # [rad] uniform half-width around the default pose
    init_base_vel_mps: float = 0.5  # [m/s] uniform half-width of the initial trunk velocity
    kp: float = 20.0  # [N·m/rad] joint PD of the action
    kd: float = 0.5  # [N·m·s/rad]
    action_scale: float = 0.25  # [rad] per unit of action
    # uniform observation noise half-widths, in the term's units before scaling
    noise: dict[str, float] = field(default_factory=lambda: {
        "base_lin_vel": 0.1, "base_ang_vel": 0.2, "projected_gravity": 0.05, "joint_pos": 0.01, "joint_vel": 1.5})
    rewards: Rewards = field(default_factory=Rewards)
    ppo: PPOSettings = field(default_factory=PPOSettings)

    def as_dict(self) -> dict:
        return asdict(self)
