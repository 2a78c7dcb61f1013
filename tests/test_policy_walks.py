"""Each shipped policy (conf/policy/*.yaml) walks 2 s at its 0.5 m/s command on flat ground in the benchmark's 1 kHz
plant; the paper's filter and the terrain filter run with it (both read the plan estimated without a gait clock;
whether they keep it on its feet is the policy study's question, results/policy/); its ONNX file agrees with its
torch weights."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest
import torch
import yaml

from taslel_bench.config.compose import CONF_DIR, compose
from taslel_bench.control.policy import resolve_onnx
from taslel_bench.control.policy_contract import contract_from_mapping
from taslel_bench.learn.export import deterministic_actions, load_torch_actor
from taslel_bench.sim.build import Built

SHIPPED = sorted(p.stem for p in (CONF_DIR / "policy").glob("*.yaml"))


def test_at_least_one_policy_ships():
    assert SHIPPED, "conf/policy/ holds no policy"


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_onnx_matches_its_torch_weights(name):
    path = CONF_DIR / "policy" / f"{name}.yaml"
    contract = contract_from_mapping(yaml.safe_load(path.read_text()), str(path))
    onnx = resolve_onnx(contract, str(path))
    folder = Path(onnx).parent
    actor = load_torch_actor(folder, contract.obs_size)
    obs = torch.randn(512, contract.obs_size, generator=torch.Generator().manual_seed(0)) * 2.0
    reference = deterministic_actions(actor, obs).numpy()
    actions = ort.InferenceSession(str(onnx)).run(None, {"obs": obs.numpy()})[0]
    assert np.abs(actions - reference).max() <= 1e-5


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_walks_two_seconds_on_flat_ground(name):
    built, result = _run(name, ["filter.enabled=false"])
    assert result.status == "ok" and not result.fell
    trace = result.traced()
    walk = trace.t_s[: trace.n] >= float(built.cfg.controller.stand_duration)
    x = trace.qpos_mj[: trace.n, built.episode.bridge.free_qadr][walk]
    speed = (x[-1] - x[0]) / 2.0
    assert speed > 0.3, f"{name}: {speed:.3f} m/s forward over 2 s at a 0.5 m/s command"
    assert built.controller.policy_steps == pytest.approx(2.5 * built.controller.contract.rate_hz, abs=1)


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("safety_filter", ["id_cbf_qp", "terrain"])
def test_both_filters_run_with_a_shipped_policy(name, safety_filter):
    built, result = _run(name, [f"filter={safety_filter}", "duration=0.5"])
    assert result.status == "ok"
    trace = result.traced()
    assert trace.n > 500 and (trace.qp_status[: trace.n] == 0).mean() > 0.9  # the filter solved its QPs
    # the stance set it used is the estimated plan's (a policy has no schedule): not every foot, every tick
    assert not trace.in_stance[: trace.n].all()


def _run(name: str, overrides: list[str]):
    contract = yaml.safe_load((CONF_DIR / "policy" / f"{name}.yaml").read_text())
    cfg = compose([f"robot={contract['robot']}", "controller=policy", f"policy={name}", "duration=2", *overrides,
                   "progress=false"])
    built = Built(cfg)
    return built, built.episode.run()
