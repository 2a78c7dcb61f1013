"""Learned estimators in a closed loop with a friction change (``python -m studies.estimator_friction_switch``).

The A1 trots in the core episode loop (:class:`taslel_bench.api.Episode`: the benchmark's loop and fall rule)
under the nominal controller (no safety filter) on a floor whose friction switches from ``mu_a`` to ``mu_b``
at ``t_switch_s`` (a world of this study: the floor's friction changes in time, not along the path); the
:class:`LearnedEstimator` is the loop's estimator. Reported per episode: MAE, bias and over-estimation rate (> truth +
0.05) of the reported (conservative) estimate over the ticks where it is ready, and the settle time: the time
after the switch from which the model mean stays within ``settle_tol`` of the new friction.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from estimators.checkpoint import checkpoint_paths
from estimators.learned import LearnedEstimator
from estimators.randomisation import EpisodeParams
from taslel_bench import api
from taslel_bench.interfaces import GROUND, OVERESTIMATE_MARGIN, Plane, Terrain

RESULTS_DIR = Path(__file__).resolve().parents[1] / "results" / "estimators"


def nominal_params(friction: float, trunk_mass_scale: float = 1.0) -> EpisodeParams:
    return EpisodeParams(seed=0, friction=friction, trunk_mass_scale=trunk_mass_scale, trunk_com_shift_x_m=0.0,
                         trunk_com_shift_y_m=0.0, joint_damping=0.05, joint_frictionloss=0.1,
                         motor_strength_scale=1.0, kp_scale=1.0, kd_scale=1.0, speed_mps=0.3, period_s=0.4,
                         swing_height_m=0.06)


class _SwitchingFloor:
    """The floor z = 0 whose friction is ``now`` [-] (set by :class:`_FrictionSwitch`): a terrain part."""

    role = GROUND

    def __init__(self, mu: float) -> None:
        self.now = mu

    def add_to(self, spec, body, name, rng) -> None:
        spec.geom("floor").friction[0] = self.now

    def top_z(self, x, y) -> float:
        return 0.0

    def normal(self, x, y) -> np.ndarray:
        return np.array([0.0, 0.0, 1.0])

    def friction_at(self, x, y) -> float:
        return self.now

    def sphere_distance(self, centres, radius):
        return Plane().sphere_distance(centres, radius)


class _FrictionSwitch(api.StaticWorld):
    """The floor's friction jumps from ``mu_a`` to ``mu_b`` at episode time ``t_switch_s`` [s]."""

    def __init__(self, mu_a: float, mu_b: float, t_switch_s: float, perturbation) -> None:
        self.floor = _SwitchingFloor(mu_a)
        super().__init__(Terrain((self.floor,)), perturbation=perturbation, name="friction_switch")
        self.mu_a, self.mu_b, self.t_switch_s = mu_a, mu_b, t_switch_s

    def on_tick(self, model, data, t_s: float) -> None:
        mu = self.mu_a if t_s < self.t_switch_s else self.mu_b
        if mu != self.floor.now:
            model.geom_friction[model.geom("floor").id, 0] = self.floor.now = mu


class _Watched:
    """The estimator, with its model mean kept every tick (the settle time reads it)."""

    def __init__(self, est: LearnedEstimator) -> None:
        self.est, self.name, self.means = est, est.name, []

    def reset(self) -> None:
        self.est.reset()
        self.means = []

    def step(self, obs):
        out = self.est.step(obs)
        self.means.append(self.est.mean)
        return out


def run(est: LearnedEstimator, mu_a: float, mu_b: float, t_switch_s: float, duration_s: float,
        trunk_mass_scale: float = 1.0, settle_tol: float = 0.1) -> dict[str, float]:
    """One episode; returns the metrics described in the module docstring (times in [s])."""
    p = nominal_params(mu_a, trunk_mass_scale)
    world = _FrictionSwitch(mu_a, mu_b, t_switch_s, p.perturbation())
    controller = api.NominalController(api.GaitParams(period_s=p.period_s, speed_mps=p.speed_mps), api.PDGains())
    settings = replace(api.episode_settings(api.compose()), duration_s=duration_s - controller.stand_duration_s,
                       init_joint_noise_rad=0.0, init_base_vel_noise_mps=0.0, analyse=False)
    watched = _Watched(est)
    episode = api.Episode(settings, world, api.build_plant(world), controller, None, watched, np.random.default_rng(0))
    res = episode.run()
    tr, n = res.trace, res.trace.n
    t_arr, y, mu, r = tr.t_s[:n], tr.mu_true[:n], tr.mu_hat[:n], tr.mu_hat_ready[:n]
    mean = np.asarray(watched.means[:n])
    err = (mu - y)[r]
    after = t_arr >= t_switch_s
    bad = after & (np.abs(mean - mu_b) > settle_tol)
    dt = settings.control_dt_s
    settle = float(t_arr[bad].max() - t_switch_s + dt) if bad.any() else 0.0
    if bad.any() and t_arr[bad].max() >= t_arr[-1] - 1e-9:
        settle = float("inf")  # never settled
    return {"mu_a": mu_a, "mu_b": mu_b, "trunk_mass_scale": trunk_mass_scale, "fell": float(res.fell),
            "mae": float(np.abs(err).mean()), "bias": float(err.mean()),
            "overestimate_rate": float((err > OVERESTIMATE_MARGIN).mean()), "settle_s": settle,
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
             ("Generated by `python -m studies.estimator_friction_switch`. Nominal trot (no safety filter), 1 kHz "
             "ticks; errors of the reported (conservative) estimate over ready ticks; settle_s: time after the switch "
             "from which the model mean stays within 0.1 of the new friction (inf: never within the episode)."), "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{r[c]:.3f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    a.out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
