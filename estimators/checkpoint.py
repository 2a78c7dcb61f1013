"""Shipped checkpoints: ``<name>.pt`` (a plain ``state_dict`` of tensors, loaded with
``torch.load(weights_only=True)`` — no arbitrary pickle) beside ``<name>.json`` (model config,
normalisation statistics, training record and recorded metrics). An ensemble
(:class:`estimators.models.EnsembleModel`) is one such pair too: its state dict holds every member
(``members.<i>.*``), its JSON the shared config, ``"ensemble": {"members": n}`` and each member's
normalisation and training record."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from estimators.models import EnsembleModel, FrictionModel, ModelConfig, build_model

CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"


def checkpoint_paths(name_or_path: str | Path) -> tuple[Path, Path]:
    """(weights .pt, metadata .json) for a shipped name (``"linformer"``) or a path with or without suffix."""
    p = Path(name_or_path)
    if p.suffix in (".pt", ".json"):
        p = p.with_suffix("")
    elif p.parent == Path(".") and not p.exists():
        p = CHECKPOINT_DIR / p.name
    return p.with_suffix(".pt"), p.with_suffix(".json")


def _normalisation(model: FrictionModel) -> dict[str, object]:
    n = model.norm
    return {"x_mean": n.x_mean.tolist(), "x_std": n.x_std.tolist(), "y_mean": float(n.y_mean),
            "y_std": float(n.y_std), "log_var_offset": float(n.log_var_offset)}


def save_checkpoint(model: FrictionModel | EnsembleModel, path: str | Path,
                    meta: dict[str, object] | None = None) -> Path:
    """Write weights and a new metadata JSON (``meta`` merged in); returns the .pt path."""
    pt, js = checkpoint_paths(path)
    pt.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    torch.save(state, pt)
    info: dict[str, object] = {"model": model.cfg.to_dict()}
    if isinstance(model, EnsembleModel):
        info["ensemble"] = {"members": len(model.members), "log_var_offset": float(model.log_var_offset)}
        info["normalisation"] = [_normalisation(m) for m in model.members]  # type: ignore[arg-type]
    else:
        info["normalisation"] = _normalisation(model)
    info.update(meta or {})  # a fresh JSON: metrics recorded for earlier weights do not carry over
    js.write_text(json.dumps(info, indent=2))
    return pt


class CheckpointError(ValueError):
    """A checkpoint file exists but cannot be read (truncated, not JSON / not a torch file, mismatched)."""


def load_checkpoint(name_or_path: str | Path) -> tuple[FrictionModel | EnsembleModel, dict[str, object]]:
    """Model (or ensemble) in eval mode and its metadata. Raises FileNotFoundError naming the shipped
    checkpoints, :class:`CheckpointError` naming the file that cannot be read."""
    pt, js = checkpoint_paths(name_or_path)
    if not (pt.is_file() and js.is_file()):
        shipped = sorted(p.stem for p in CHECKPOINT_DIR.glob("*.pt"))
        raise FileNotFoundError(f"checkpoint {pt} / {js} not found; shipped checkpoints: {shipped}")
    try:
        meta = json.loads(js.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"checkpoint metadata {js} cannot be read: {type(exc).__name__}: {exc}") \
            from exc
    try:
        state = torch.load(pt, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises RuntimeError, OSError, UnpicklingError ... on a damaged file
        raise CheckpointError(f"checkpoint weights {pt} cannot be read (truncated or not a torch state "
                              f"dict?): {type(exc).__name__}: {exc}") from exc
    check_finite_weights(pt, state)
    try:
        return _build(meta, state)
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:  # RuntimeError: state dict mismatch
        raise CheckpointError(f"checkpoint {pt} with metadata {js} cannot be loaded into a model: "
                              f"{type(exc).__name__}: {exc}") from exc


def check_finite_weights(pt: Path, state: object) -> None:
    """Refuse weights holding NaN or infinity (a diverged training run): such a model answers NaN, which the
    estimator would floor to ``mu_min`` without a word."""
    if not isinstance(state, dict):
        raise CheckpointError(f"checkpoint weights {pt} hold a {type(state).__name__}, not a state dict of tensors")
    for key, value in state.items():
        if isinstance(value, torch.Tensor) and value.is_floating_point() and not bool(torch.isfinite(value).all()):
            bad = int((~torch.isfinite(value)).sum())
            raise CheckpointError(f"checkpoint weights {pt}: tensor {key!r} holds {bad} non-finite value(s) "
                                  f"(NaN or infinity) of {value.numel()}; retrain or use another checkpoint")


def _build(meta: dict, state: dict) -> tuple[FrictionModel | EnsembleModel, dict[str, object]]:
    """The model (or ensemble) described by ``meta`` with the weights ``state``, in eval mode."""
    if "ensemble" in meta:
        cfg = ModelConfig(**meta["model"])
        ens = EnsembleModel([build_model(cfg) for _ in range(int(meta["ensemble"]["members"]))])
        ens.load_state_dict(state)
        return ens.eval(), meta
    model = build_model(ModelConfig(**meta["model"]))
    state.setdefault("norm.log_var_offset", torch.tensor(0.0))  # checkpoints from before calibration
    model.load_state_dict(state)
    return model.eval(), meta
