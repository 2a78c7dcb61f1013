"""Collect friction-labelled proprioception windows from MuJoCo episodes (``python -m estimators.collect``).

Each episode: the A1 stands ``stand_duration_s`` then trots under the nominal controller (trot, IK, joint
PD at 1 kHz) on a flat floor whose friction and plant parameters are drawn by
:mod:`estimators.randomisation`. Every ``WINDOW_DT_S`` the 36 features (q, qdot, commanded tau; core
joint order; tau is the torque commanded on the previous tick, exactly what the core episode runner passes
as ``Proprioception.tau_joints``) are sampled; windows of ``WINDOW_STEPS`` samples, starting every ``stride`` samples from
``first_window_s`` on, are labelled with the floor friction. Splits are by episode (train / val / test
from the training ranges, ``shifted`` from :data:`SHIFTED_RANGES`). A fall (trunk below 0.15 m or tilted
more than ~53 deg) ends the episode; windows ending later than ``fall_margin_s`` before the fall are
dropped. Episodes run in parallel processes; the throughput is printed in env-steps/s (physics steps).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np

from estimators.features import N_FEATURES, WINDOW_DT_S, WINDOW_STEPS, sample_vector
from estimators.randomisation import (
    SHIFTED_RANGES,
    TRAIN_RANGES,
    EpisodeParams,
    PlantRandomiser,
    draw,
    ranges_dict,
)
from taslel_bench import bridge, controller, gait, plant, robot

PAPER_STEPS_PER_S = 100_000  # Isaac Gym, 4096 A1s, RTX 3080 (paper, "Data Collection")


@dataclass(frozen=True)
class EpisodeConfig:
    duration_s: float = 5.0  # [s] episode length including the stand
    timestep_s: float = 0.001  # [s] physics and control period
    stand_duration_s: float = 0.5  # [s] standing before the trot starts
    first_window_s: float = 0.3  # [s] earliest window start
    stride: int = 4  # [samples] between window starts
    fall_height_m: float = 0.15  # [m] trunk origin height below which the robot has fallen
    fall_upz: float = 0.6  # [-] trunk z axis . world z below which the robot has fallen
    fall_margin_s: float = 0.3  # [s] windows must end this long before a fall


@dataclass
class EpisodeResult:
    windows: np.ndarray  # (n, WINDOW_STEPS, N_FEATURES) float32
    fell: bool
    fall_time_s: float  # [s] nan if it did not fall
    steps: int  # physics steps simulated
    params: EpisodeParams


_WORKER: dict[str, object] = {}


def _worker_model() -> tuple[mujoco.MjModel, bridge.StateBridge, PlantRandomiser]:
    if "model" not in _WORKER:
        m = plant.build_plant(plant.PlantOptions())
        _WORKER.update(model=m, bridge=bridge.StateBridge(m), rand=PlantRandomiser(m))
    return _WORKER["model"], _WORKER["bridge"], _WORKER["rand"]  # type: ignore[return-value]


def run_episode(p: EpisodeParams, cfg: EpisodeConfig = EpisodeConfig()) -> EpisodeResult:
    """Simulate one episode and cut its windows (see the module docstring)."""
    m, br, rand = _worker_model()
    rand.apply(p)
    m.opt.timestep = cfg.timestep_s
    gp = gait.GaitParams(period_s=p.period_s, swing_height_m=p.swing_height_m, speed_mps=p.speed_mps)
    gains = controller.PDGains(kp=100.0 * p.kp_scale, kd=3.0 * p.kd_scale)
    ctl = controller.NominalController(
        gp, gains, stand_duration_s=cfg.stand_duration_s, fd_dt_s=cfg.timestep_s
    )
    d = mujoco.MjData(m)
    a = br.free_qadr
    d.qpos[a : a + 3] = [0.0, 0.0, gp.stand_height_m + robot.FOOT_RADIUS_M]
    d.qpos[a + 3 : a + 7] = [1.0, 0.0, 0.0, 0.0]
    d.qpos[br.joint_qadr] = ctl.stand_configuration()
    mujoco.mj_forward(m, d)

    n_steps = int(round(cfg.duration_s / cfg.timestep_s))
    every = int(round(WINDOW_DT_S / cfg.timestep_s))
    samples: list[np.ndarray] = []
    fall_t = float("nan")
    tau_prev = np.zeros(robot.N_JOINTS)  # [N·m] torque commanded on the previous tick (0 at t = 0)
    k = 0
    for k in range(n_steps):
        t = k * cfg.timestep_s
        qj, qd = d.qpos[br.joint_qadr], d.qvel[br.joint_dadr]
        if k % every == 0:  # sampled before this tick's control, as the episode runner feeds estimators
            samples.append(sample_vector(qj, qd, tau_prev))
            qx, qy = d.qpos[a + 4], d.qpos[a + 5]
            upz = 1.0 - 2.0 * (qx * qx + qy * qy)
            if d.qpos[a + 2] < cfg.fall_height_m or upz < cfg.fall_upz or not np.isfinite(d.qpos).all():
                fall_t = t
                break
        u = ctl.compute(t, qj, qd)
        br.ctrl_mj(u, d.ctrl)
        tau_prev = u
        mujoco.mj_step(m, d)

    s = np.stack(samples)
    first = int(np.ceil(cfg.first_window_s / WINDOW_DT_S))
    last_end = len(s) if np.isnan(fall_t) else int((fall_t - cfg.fall_margin_s) / WINDOW_DT_S)
    starts = list(range(first, last_end - WINDOW_STEPS + 1, cfg.stride))
    w = (
        np.stack([s[i : i + WINDOW_STEPS] for i in starts])
        if starts
        else np.zeros((0, WINDOW_STEPS, N_FEATURES), np.float32)
    )
    return EpisodeResult(w, not np.isnan(fall_t), fall_t, k + 1, p)


def _run(args: tuple[EpisodeParams, EpisodeConfig]) -> EpisodeResult:
    return run_episode(*args)


def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {"python": platform.python_version(), "platform": platform.platform(), "cpus": str(os.cpu_count())}
    for pkg in ("mujoco", "numpy", "pin", "taslel_bench"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "n/a"
    return out


def collect(
    out_dir: Path,
    counts: dict[str, int],
    seed: int = 0,
    workers: int = 2,
    cfg: EpisodeConfig = EpisodeConfig(),
) -> dict[str, object]:
    """Run all splits, write ``<split>.npz`` (X, y, episode, params) and ``manifest.json`` into ``out_dir``."""
    valid = {"train", "val", "test", "shifted"}
    if bad := set(counts) - valid:
        raise ValueError(f"unknown split(s) {sorted(bad)}; valid splits: {sorted(valid)}")
    out_dir.mkdir(parents=True, exist_ok=True)
    root = np.random.SeedSequence(seed)
    jobs: list[tuple[str, EpisodeParams]] = []
    for split_ss, split in zip(root.spawn(len(valid)), ("train", "val", "test", "shifted")):
        n = counts.get(split, 0)
        for ep_ss in split_ss.spawn(n):
            rng = np.random.default_rng(ep_ss)
            ep_seed = int(ep_ss.generate_state(1)[0])
            shifted = split == "shifted"
            p = draw(rng, SHIFTED_RANGES if shifted else TRAIN_RANGES, ep_seed, symmetric_com=not shifted)
            jobs.append((split, p))

    t0 = time.perf_counter()
    ctx = mp.get_context("fork")
    with ctx.Pool(workers) as pool:
        results = pool.map(_run, [(p, cfg) for _, p in jobs], chunksize=4)
    wall = time.perf_counter() - t0
    total_steps = sum(r.steps for r in results)

    manifest: dict[str, object] = {
        "seed": seed,
        "workers": workers,
        "episode_config": asdict(cfg),
        "window": {"steps": WINDOW_STEPS, "dt_s": WINDOW_DT_S, "features": N_FEATURES,
                   "layout": "q[12] rad, qdot[12] rad/s, tau_cmd[12] N·m; legs FL,FR,RL,RR x hip,thigh,calf"},
        "train_ranges": ranges_dict(TRAIN_RANGES),
        "shifted_ranges": ranges_dict(SHIFTED_RANGES),
        "shifted_note": "com_shift_xy_m is a magnitude range with random sign in the shifted set",
        "versions": _versions(),
        "wall_time_s": wall,
        "env_steps": total_steps,
        "env_steps_per_s": total_steps / wall,
        "paper_env_steps_per_s": PAPER_STEPS_PER_S,
        "splits": {},
    }
    for split in ("train", "val", "test", "shifted"):
        rs = [r for (s, _), r in zip(jobs, results) if s == split]
        if not rs:
            continue
        X = np.concatenate([r.windows for r in rs]).astype(np.float32)
        y = np.concatenate([np.full(len(r.windows), r.params.friction, np.float32) for r in rs])
        ep = np.concatenate([np.full(len(r.windows), i, np.int32) for i, r in enumerate(rs)])
        params = np.array([r.params.as_row() for r in rs], np.float64)
        np.savez_compressed(
            out_dir / f"{split}.npz", X=X, y=y, episode=ep, params=params,
            param_columns=np.array(EpisodeParams.columns()), fell=np.array([r.fell for r in rs]),
        )
        fell = [r for r in rs if r.fell]
        manifest["splits"][split] = {  # type: ignore[index]
            "episodes": len(rs),
            "windows": len(X),
            "episodes_fallen": len(fell),
            "episodes_fallen_without_windows": sum(1 for r in fell if len(r.windows) == 0),
            "fallen_friction": sorted(round(r.params.friction, 3) for r in fell),
            "env_steps": sum(r.steps for r in rs),
        }
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return manifest


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("/work/data/estimators"), help="output folder")
    ap.add_argument("--train", type=int, default=700, help="training episodes")
    ap.add_argument("--val", type=int, default=100, help="validation episodes")
    ap.add_argument("--test", type=int, default=150, help="in-distribution test episodes")
    ap.add_argument("--shifted", type=int, default=150, help="shifted test episodes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--duration", type=float, default=EpisodeConfig.duration_s, help="episode length [s]")
    ap.add_argument("--stride", type=int, default=EpisodeConfig.stride, help="window stride [samples]")
    a = ap.parse_args(argv)
    cfg = EpisodeConfig(duration_s=a.duration, stride=a.stride)
    counts = {"train": a.train, "val": a.val, "test": a.test, "shifted": a.shifted}
    man = collect(a.out, counts, seed=a.seed, workers=a.workers, cfg=cfg)
    rate = man["env_steps_per_s"]
    print(f"collected {man['env_steps']:,} env steps in {man['wall_time_s']:.1f} s with {a.workers} workers")
    print(f"throughput {rate:,.0f} env-steps/s  vs paper {PAPER_STEPS_PER_S:,} (RTX 3080, 4096 robots): "
          f"{rate / PAPER_STEPS_PER_S:.2f}x")
    for split, info in man["splits"].items():  # type: ignore[union-attr]
        print(f"  {split:8s} {info['episodes']:5d} episodes {info['windows']:7d} windows "
              f"fallen {info['episodes_fallen']}")
    print(f"wrote {a.out}/{{train,val,test,shifted}}.npz and manifest.json")


if __name__ == "__main__":
    main()
