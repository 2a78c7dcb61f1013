"""A trained actor as one self-contained ONNX file, and the torch actor rebuilt from a shipped policy's folder
(``policy_torch.pt`` + ``training.yaml``) to check the two agree."""

from __future__ import annotations

from pathlib import Path

import torch
import yaml
from tensordict import TensorDict

from taslel_bench.learn.config import PPOSettings


def export_onnx(actor, path: Path) -> None:
    """The deterministic ``actor`` (rsl_rl's MLPModel, its observation normaliser included) as one ONNX file:
    input ``obs`` (batch, obs_size) float32, output ``actions`` (batch, 12)."""
    model = actor.as_onnx(verbose=False).to("cpu").eval()
    torch.onnx.export(model, model.get_dummy_inputs(), str(path), opset_version=18, input_names=model.input_names,
                      output_names=model.output_names, dynamic_shapes=({0: torch.export.Dim("batch")},),
                      external_data=False, verbose=False)


def actor_model(ppo: PPOSettings, obs_size: int, n_actions: int = 12):
    """A fresh rsl_rl actor of the training's architecture (``ppo``) for ``obs_size`` observations."""
    from rsl_rl.models import MLPModel

    obs = TensorDict({"policy": torch.zeros(1, obs_size)}, batch_size=[1])
    return MLPModel(obs, {"actor": ["policy"]}, "actor", n_actions, hidden_dims=list(ppo.hidden_dims),
                    activation=ppo.activation, obs_normalization=ppo.obs_normalization,
                    distribution_cfg={"class_name": "GaussianDistribution", "init_std": ppo.init_noise_std})


def load_torch_actor(folder: Path, obs_size: int):
    """The actor saved in ``folder`` (``policy_torch.pt``, architecture from ``training.yaml``), in eval mode."""
    settings: dict = yaml.safe_load((folder / "training.yaml").read_text())["ppo"]
    ppo = PPOSettings(**settings)
    ppo.hidden_dims = tuple(ppo.hidden_dims)
    actor = actor_model(ppo, obs_size)
    actor.load_state_dict(torch.load(folder / "policy_torch.pt", weights_only=True))
    return actor.eval()


@torch.inference_mode()
def deterministic_actions(actor, obs: torch.Tensor) -> torch.Tensor:
    """The actor's deterministic output (the distribution's mean) for observations (batch, obs_size)."""
    return actor.as_onnx(verbose=False).eval()(obs)
