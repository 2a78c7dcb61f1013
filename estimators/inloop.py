"""Learned estimators in a closed loop with a friction change (``python -m estimators.inloop``).

Stand-alone check of the in-loop path (the harness's own sweep uses the core episode runner): the A1
trots under the nominal controller (no safety filter) on a floor whose friction switches from ``mu_a``
to ``mu_b`` at ``t_switch_s``; a :class:`LearnedEstimator` is stepped every 1 ms tick with the joint
state and the previous tick's commanded torques (as the core episode runner does). Reported per episode: MAE, bias and over-estimation rate (> truth + 0.05)
of the reported (conservative) estimate over the ticks where it is ready, and the settle time: the time
after the switch from which the model mean stays within ``settle_tol`` of the new friction.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import mujoco
import numpy as np

from estimators.checkpoint import checkpoint_paths
from estimators.collect import _worker_model
from estimators.learned import LearnedEstimator
from estimators.randomisation import EpisodeParams
from taslel_bench import api
from taslel_bench.interfaces import Proprioception
from taslel_bench.robot import a1

RESULTS_DIR = Path(__file__).resolve().parents[1] / "results" / "estimators"


def nominal_params(friction: float, trunk_mass_scale: float = 1.0) -> EpisodeParams:
    return EpisodeParams(seed=0, friction=friction, trunk_mass_scale=trunk_mass_scale, com_shift_x_m=0.0,
                         com_shift_y_m=0.0, joint_damping=0.05, joint_frictionloss=0.1, motor_strength=1.0,
                         kp_scale=1.0, kd_scale=1.0, speed_mps=0.3, period_s=0.4, swing_height_m=0.06)


def run(est: LearnedEstimator, mu_a: float, mu_b: float, t_switch_s: float, duration_s: float,
        trunk_mass_scale: float = 1.0, settle_tol: float = 0.1) -> dict[str, float]:
    """One episode; returns the metrics described in the module docstring (times in [s])."""
    m, br, rand = _worker_model()
    rand.apply(nominal_params(mu_a, trunk_mass_scale))
    p = nominal_params(mu_a)
    ctl = api.NominalController(api.GaitParams(period_s=p.period_s, speed_mps=p.speed_mps),
                                       api.PDGains())
    d = mujoco.MjData(m)
    a = br.free_qadr
    d.qpos[a : a + 3] = [0.0, 0.0, 0.27 + a1.FOOT_RADIUS_M]
    d.qpos[a + 3 : a + 7] = [1.0, 0.0, 0.0, 0.0]
    d.qpos[br.joint_qadr] = ctl.stand_configuration()
    est.reset()
    ts, truth, mus, means, ready = [], [], [], [], []
    fell = False
    tau_prev = np.zeros(a1.N_JOINTS)  # [N·m] torque commanded on the previous tick
    for k in range(round(duration_s / m.opt.timestep)):
        t = k * m.opt.timestep
        mu_true = mu_a if t < t_switch_s else mu_b
        m.geom_friction[rand.floor_id, 0] = mu_true
        qj, qd = d.qpos[br.joint_qadr].copy(), d.qvel[br.joint_dadr].copy()
        e = est.step(Proprioception(t, qj, qd, tau_prev.copy(), mu_true))  # as the episode runner does
        u = ctl.compute(t, qj, qd)
        tau_prev = u
        ts.append(t), truth.append(mu_true), mus.append(e.mu), means.append(est.mean), ready.append(e.ready)
        br.ctrl_mj(u, d.ctrl)
        mujoco.mj_step(m, d)
        if d.qpos[a + 2] < 0.15:
            fell = True
            break
    t_arr, y, mu, mean, r = map(np.asarray, (ts, truth, mus, means, ready))
    err = (mu - y)[r]
    after = t_arr >= t_switch_s
    bad = after & (np.abs(mean - mu_b) > settle_tol)
    settle = float(t_arr[bad].max() - t_switch_s + m.opt.timestep) if bad.any() else 0.0
    if bad.any() and t_arr[bad].max() >= t_arr[-1] - 1e-9:
        settle = float("inf")  # never settled
    return {"mu_a": mu_a, "mu_b": mu_b, "trunk_mass_scale": trunk_mass_scale, "fell": float(fell),
            "mae": float(np.abs(err).mean()), "bias": float(err.mean()),
            "overestimate_rate": float((err > 0.05).mean()), "settle_s": settle,
            "first_ready_s": float(t_arr[r][0]) if r.any() else float("nan")}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+", default=["mlp", "attention", "linformer", "attention_step"],
                    help="shipped checkpoint names or checkpoint paths")
    ap.add_argument("--k", type=float, default=1.0, help="conservative_k")
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--switch", type=float, default=4.0)
    ap.add_argument("--out", type=Path, default=RESULTS_DIR / "inloop.json")
    a = ap.parse_args(argv)
    cases = [(1.0, 0.3, 1.0), (0.3, 1.0, 1.0), (0.8, 0.2, 1.0), (1.0, 0.3, 1.7), (0.8, 0.2, 1.7)]
    rows = []
    for v in a.variants:
        variant = json.loads(checkpoint_paths(v)[1].read_text())["model"]["variant"]
        est = LearnedEstimator(variant, checkpoint=v, conservative_k=a.k)
        for mu_a, mu_b, mass in cases:
            row = {"variant": est.name, "conservative_k": a.k, **run(est, mu_a, mu_b, a.switch, a.duration, mass)}
            rows.append(row)
            print(json.dumps(row))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(rows, indent=2))
    cols = ["variant", "conservative_k", "mu_a", "mu_b", "trunk_mass_scale", "fell", "mae", "bias",
            "overestimate_rate", "settle_s", "first_ready_s"]
    lines = [f"# In-loop friction switch at t = {a.switch:g} s ({a.duration:g} s episodes)", "",
             ("Generated by `python -m estimators.inloop`. Nominal trot (no safety filter), 1 kHz ticks; errors of "
             "the reported (conservative) estimate over ready ticks; settle_s: time after the switch from which "
             "the model mean stays within 0.1 of the new friction (inf: never within the episode)."), "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{r[c]:.3f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    a.out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
