"""Train a walking policy with PPO (``rsl-rl-lib``) on the harness's own plant and ship it.

    python -m taslel_bench.learn.train --robot a1 --name a1_walk --seed 0      # at most --minutes of wall time

Writes ``results/policies/<name>/`` (policy.onnx, training.yaml, learning_curve.csv and .png, README.md with
the machine, versions, commit, wall time and env-steps/s) and the policy's contract ``conf/policy/<name>.yaml``
(the ONNX file's path and SHA-256, the observation terms, the action, the gait's stance and swing durations
measured on flat ground at the end). Progress: one line per iteration (mean episode return, fall rate,
env-steps/s). Environments: :class:`taslel_bench.learn.env.WalkingEnv`; settings:
:class:`taslel_bench.learn.config.TrainingConfig` (``--set key=value`` for any of them).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch
import yaml

from taslel_bench.control.policy_contract import contract_to_mapping, file_sha256
from taslel_bench.learn.config import TrainingConfig
from taslel_bench.learn.env import WalkingEnv
from taslel_bench.learn.export import export_onnx
from taslel_bench.util.machine import machine_info

REPO = Path(__file__).resolve().parents[2]


def rsl_rl_config(cfg: TrainingConfig) -> dict:
    """``rsl_rl``'s OnPolicyRunner configuration from ``cfg.ppo``."""
    p = cfg.ppo
    model = {"class_name": "MLPModel", "hidden_dims": list(p.hidden_dims), "activation": p.activation,
             "obs_normalization": p.obs_normalization}
    return {
        "num_steps_per_env": p.num_steps_per_env, "save_interval": 10**9, "obs_groups": {"actor": ["policy"],
                                                                                        "critic": ["policy"]},
        "actor": {**model, "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": p.init_noise_std}},
        "critic": dict(model),
        "algorithm": {"class_name": "PPO", "learning_rate": p.learning_rate, "num_learning_epochs":
                      p.num_learning_epochs, "num_mini_batches": p.num_mini_batches, "clip_param": p.clip_param,
                      "gamma": p.gamma, "lam": p.lam, "entropy_coef": p.entropy_coef, "desired_kl": p.desired_kl,
                      "max_grad_norm": p.max_grad_norm, "schedule": "adaptive"},
        "check_for_nan": True,
    }  # fmt: skip


class EpisodeStats:
    """Returns and lengths of the episodes that ended, per iteration (wraps the environment's step)."""

    def __init__(self, env: WalkingEnv) -> None:
        self.env = env
        self.ret = np.zeros(env.num_envs)
        self.length = np.zeros(env.num_envs, int)
        self.returns: list[float] = []
        self.lengths: list[int] = []
        self.falls = 0
        self.ended = 0
        self._step = env.step
        env.step = self.step  # type: ignore[method-assign]

    def step(self, actions):
        obs, rew, done, extras = self._step(actions)
        self.ret += rew.numpy()
        self.length += 1
        ids = np.flatnonzero(done.numpy())
        if ids.size:
            self.returns += self.ret[ids].tolist()
            self.lengths += self.length[ids].tolist()
            self.falls += int((~extras["time_outs"].numpy()[ids]).sum())
            self.ended += ids.size
            self.ret[ids] = 0.0
            self.length[ids] = 0
        return obs, rew, done, extras

    def take(self) -> dict[str, float]:
        out = {"episodes": self.ended, "mean_return": float(np.mean(self.returns)) if self.returns else float("nan"),
               "mean_length_s": float(np.mean(self.lengths)) * self.env.dt if self.lengths else float("nan"),
               "fall_share": self.falls / self.ended if self.ended else float("nan")}
        self.returns, self.lengths, self.falls, self.ended = [], [], 0, 0
        return out


def train(cfg: TrainingConfig, out: Path, conf_dir: Path) -> dict:
    """Train, export and measure one policy (module doc); returns the README's figures."""
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.torch_threads)
    from rsl_rl.runners import OnPolicyRunner

    t_start = time.perf_counter()
    code = _versions()  # the code the training runs (read before: the checkout may move while it trains)
    env = WalkingEnv(cfg)
    stats = EpisodeStats(env)
    runner = OnPolicyRunner(env, rsl_rl_config(cfg), log_dir=None, device="cpu")  # type: ignore[arg-type]
    rows = []
    for it in range(cfg.iterations):
        t0 = time.perf_counter()
        steps0 = env.env_steps
        runner.learn(1)
        dt = time.perf_counter() - t0
        row = {"iteration": it, "wall_s": time.perf_counter() - t_start, "env_steps": env.env_steps,
               "env_steps_per_s": (env.env_steps - steps0) / dt, **stats.take(),
               "action_std": float(runner.alg.get_policy().output_std.detach().mean())}
        rows.append(row)
        print(f"it {it:4d}  {row['wall_s'] / 60:6.1f} min  return {row['mean_return']:8.3f}  "
              f"falls {row['fall_share']:.2f}  length {row['mean_length_s']:5.1f} s  "
              f"{row['env_steps_per_s']:8.0f} env-steps/s  std {row['action_std']:.2f}", flush=True)
        if row["wall_s"] > cfg.max_minutes * 60.0:
            print(f"stopping at the wall-clock budget of {cfg.max_minutes} min", flush=True)
            break
    train_s = time.perf_counter() - t_start
    out.mkdir(parents=True, exist_ok=True)
    policy = runner.get_inference_policy()
    export_onnx(policy, out / "policy.onnx")
    torch.save(policy.state_dict(), out / "policy_torch.pt")
    gait = measure_gait(env, policy)
    return {"rows": rows, "train_s": train_s, "gait": gait, "env": env, "code": code}


@torch.inference_mode()
def measure_gait(env: WalkingEnv, policy, seconds: float = 6.0) -> dict[str, float]:
    """Mean stance and swing durations [s] and forward speed [m/s] of the deterministic policy at a 0.5 m/s
    forward command on flat ground (the last ``seconds`` of a fresh start), in the training environments."""
    env._reset(np.arange(env.num_envs))
    env.command[:] = (0.5, 0.0, 0.0)
    env._obs = env._observe()
    n_steps = round(seconds / env.dt)
    contact_log, speed = [], []
    env.cfg.episode_s = 1e9  # no time-outs while measuring
    env.max_episode_length = 10**9
    for _ in range(n_steps):
        obs = env.get_observations()
        action = policy(obs)
        env.step(action)
        env.command[:] = (0.5, 0.0, 0.0)
        contact_log.append(env.last_contact.copy())
        speed.append(env._trunk_state()[0][:, 0].copy())
    c = np.array(contact_log)[n_steps // 3:]  # (T, N, 4) after the start
    stance, swing = _run_lengths(c, True), _run_lengths(c, False)
    return {"stance_s": float(np.median(stance)) * env.dt if stance.size else float("nan"),
            "swing_s": float(np.median(swing)) * env.dt if swing.size else float("nan"),
            "forward_speed_mps": float(np.mean(np.array(speed)[n_steps // 3:]))}


def _run_lengths(c: np.ndarray, value: bool) -> np.ndarray:
    """Lengths (in steps) of the complete runs of ``value`` along axis 0 of ``c`` (T, ...)."""
    flat = c.reshape(c.shape[0], -1)
    out = []
    for col in flat.T:
        edges = np.flatnonzero(np.diff(col.astype(int)) != 0) + 1
        runs = np.split(col, edges)[1:-1]  # drop the partial first and last runs
        out += [len(r) for r in runs if r[0] == value]
    return np.array(out)


def ship(cfg: TrainingConfig, out: Path, conf_dir: Path, result: dict, argv: list[str]) -> None:
    """The contract, training config, learning curve and README of a trained policy."""
    env, gait, rows = result["env"], result["gait"], result["rows"]
    onnx = out / "policy.onnx"
    try:
        onnx_ref = str(onnx.resolve().relative_to(REPO))
    except ValueError:
        onnx_ref = str(onnx.resolve())
    contract = dataclasses.replace(env.contract, onnx=onnx_ref, onnx_sha256=file_sha256(onnx),
                                   stance_s=round(gait["stance_s"], 3), swing_s=round(gait["swing_s"], 3))
    conf_dir.mkdir(parents=True, exist_ok=True)
    header = (f"# Policy contract of {cfg.name}: PPO on {cfg.robot}, flat ground, friction {cfg.friction[0]}-"
              f"{cfg.friction[1]}; written by python -m taslel_bench.learn.train "
              "(keys: docs/guides/learned-policy.md)\n")
    (conf_dir / f"{cfg.name}.yaml").write_text(header + yaml.safe_dump(contract_to_mapping(contract),
                                                                       sort_keys=False))
    (out / "training.yaml").write_text(yaml.safe_dump(_plain(cfg.as_dict()), sort_keys=False))
    import pandas as pd

    frame = pd.DataFrame(rows)
    frame.to_csv(out / "learning_curve.csv", index=False)
    _plot(frame, out / "learning_curve.png", cfg)
    last = frame.tail(20)
    info = machine_info()
    machine = (f"{info.get('cpu', '?')}, {info.get('cores', '?')} cores, {info.get('os', '?')}, "
               f"Python {info.get('python', '?')}")
    steps_per_s = frame["env_steps"].iloc[-1] / frame["wall_s"].iloc[-1]
    text = [f"# Policy `{cfg.name}` ({cfg.robot})", "",
            "Generated by:", "", "```", "python -m taslel_bench.learn.train " + " ".join(argv), "```", "",
            f"- wall time: {result['train_s'] / 60:.1f} min for {len(frame)} iterations, "
            f"{int(frame['env_steps'].iloc[-1]):,} env-steps ({steps_per_s:,.0f} env-steps/s overall, policy steps "
            f"of {1 / cfg.policy_rate_hz * 1e3:g} ms; physics at {cfg.physics_dt_s * 1e3:g} ms)",
            f"- last 20 iterations: mean episode return {last['mean_return'].mean():.2f}, share of episodes ending in "
            f"a fall {last['fall_share'].mean():.3f}",
            f"- gait at a 0.5 m/s command (training plant): stance {gait['stance_s']:.3f} s, swing "
            f"{gait['swing_s']:.3f} s, forward speed {gait['forward_speed_mps']:.3f} m/s",
            f"- machine: {machine}",
            f"- code at the start of training: {result['code']}", "",
            "Files: `policy.onnx` (the deterministic actor, observation normaliser included), `policy_torch.pt` (its "
            "torch weights), `training.yaml`, `learning_curve.csv`/`.png`; the contract: "
            f"`conf/policy/{cfg.name}.yaml`."]
    (out / "README.md").write_text("\n".join(text) + "\n")


def _versions() -> str:
    import subprocess
    from importlib.metadata import version

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
                            ).stdout.strip() or "unknown"
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO, capture_output=True,
                           text=True).stdout.strip()
    pkgs = ", ".join(f"{p} {version(p)}" for p in ("mujoco", "torch", "rsl-rl-lib", "onnx", "numpy"))
    return f"commit {commit}{' (with uncommitted changes)' if dirty else ''}; {pkgs}"


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def _plot(frame, path: Path, cfg: TrainingConfig) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.2))
    minutes = frame["wall_s"] / 60.0
    for ax, key, label in zip(axes, ("mean_return", "fall_share", "mean_length_s"),
                              ("mean episode return", "share of episodes ending in a fall", "mean episode length [s]"),
                              strict=True):
        ax.plot(minutes, frame[key].rolling(10, min_periods=1).mean())
        ax.set_xlabel("wall time [min]")
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle(f"PPO, {cfg.name} ({cfg.robot}), {cfg.n_envs} environments, seed {cfg.seed}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _set(cfg: TrainingConfig, assignment: str) -> None:
    key, _, raw = assignment.partition("=")
    target, parts = cfg, key.split(".")
    for p in parts[:-1]:
        target = getattr(target, p)
    if not hasattr(target, parts[-1]):
        sys.exit(f"--set {assignment}: unknown key {key!r}; valid: {[f.name for f in dataclasses.fields(target)]}")
    old = getattr(target, parts[-1])
    value = yaml.safe_load(raw)
    setattr(target, parts[-1], tuple(value) if isinstance(old, tuple) else type(old)(value))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(prog="python -m taslel_bench.learn.train",
                                 description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--robot", default="a1", help="conf/robot/<robot>.yaml")
    ap.add_argument("--name", default=None, help="policy name (default: <robot>_walk)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--minutes", type=float, default=85.0, help="wall-clock budget [min]")
    ap.add_argument("--iterations", type=int, default=1500, help="PPO iterations at most")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default results/policies/<name>)")
    ap.add_argument("--conf-dir", type=Path, default=REPO / "conf" / "policy", help="where the contract goes")
    ap.add_argument("--set", action="append", default=[], help="TrainingConfig key=value (dotted for nested)")
    a = ap.parse_args(argv)
    cfg = TrainingConfig(robot=a.robot, name=a.name or f"{a.robot}_walk", seed=a.seed, max_minutes=a.minutes,
                         iterations=a.iterations)
    for s in a.set:
        _set(cfg, s)
    out = a.out or REPO / "results" / "policies" / cfg.name
    os.environ.setdefault("OMP_NUM_THREADS", str(cfg.nthread))
    result = train(cfg, out, a.conf_dir)
    ship(cfg, out, a.conf_dir, result, argv)
    print(f"wrote {out} and {a.conf_dir / (cfg.name + '.yaml')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
