"""Train one friction estimator variant (``python -m estimators.train estimator=linformer [key=value ...]``).

Overrides are OmegaConf dot-list entries on :data:`DEFAULTS` (merged with the variant's entry in
:data:`VARIANT_DEFAULTS`), e.g. ``model.d_model=64 trainer.max_minutes=10 data_dir=/work/data/estimators``.
The run folder (Lightning checkpoints, CSV log) is ``<runs_dir>/<estimator>``; the best model (lowest
validation MAE) is exported to ``estimators/checkpoints/<estimator>.pt/.json`` with the training record
(wall-clock training time, epochs, steps, best validation MAE, threads, versions).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint, TQDMProgressBar
from lightning.pytorch.loggers import CSVLogger
from omegaconf import DictConfig, OmegaConf

from estimators.checkpoint import CHECKPOINT_DIR, save_checkpoint
from estimators.data import WindowDataModule
from estimators.features import N_FEATURES
from estimators.models import (
    VARIANTS,
    FrictionModel,
    ModelConfig,
    build_model,
    calibrate_variance,
    parameter_count,
)

LOSSES = ("mae+nll", "nll", "mae")
SCHEDULES = ("plateau", "cosine_time")

DEFAULTS: dict[str, object] = {
    "estimator": "linformer",
    "data_dir": "/work/data/estimators",
    "runs_dir": "/work/data/runs",
    "export": True,  # write the best model to <export_dir>/<name>.pt/.json
    "export_dir": None,  # default: estimators/checkpoints (the shipped ones)
    "name": None,  # default: the estimator name
    "seed": 0,
    "threads": 2,
    "batch_size": 128,
    "lr": 1e-3,
    "weight_decay": 1e-4,
    "loss": "mae+nll",
    # learning-rate schedule: "plateau" (halve when val_mae stalls) or "cosine_time" (cosine decay to
    # lr_min_factor x lr over the wall-clock budget trainer.max_minutes, updated every step)
    "schedule": "plateau",
    "lr_min_factor": 0.02,
    "quantile_weight": 1.0,  # weight of the pinball loss of the lower-quantile head (model.lower_quantile > 0)
    # training-time augmentation: per-window torque scale ~ log-uniform(range) (payload / motor strength
    # change the torque readings), and Gaussian noise of noise_std x the feature's std on every feature
    "augment": {"tau_scale": [1.0, 1.0], "noise_std": 0.0},
    "model": {},
    "trainer": {"max_epochs": 60, "max_minutes": 13.0, "patience": 8, "fast_dev_run": False},
}
VARIANT_DEFAULTS: dict[str, dict[str, object]] = {
    "mlp": {"model": {"variant": "mlp", "mlp_hidden": [256, 128], "dropout": 0.1}, "lr": 1e-3},
    "attention": {"model": {"variant": "attention", "tokens": "joint", "d_model": 32, "n_layers": 2,
                            "n_heads": 2}},
    "linformer": {"model": {"variant": "linformer", "tokens": "joint", "d_model": 32, "n_layers": 2,
                            "n_heads": 2, "linformer_k": 32}},
}


def pinball(pred: torch.Tensor, y: torch.Tensor, q: float) -> torch.Tensor:
    """Mean pinball (quantile) loss at level q: minimised by the q-quantile of y; for q < 0.5 an
    over-estimate costs (1 - q) / q times more than an under-estimate of the same size."""
    e = y - pred
    return torch.maximum(q * e, (q - 1.0) * e).mean()


def gaussian_nll(mean: torch.Tensor, log_var: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Mean Gaussian negative log-likelihood (constant dropped)."""
    return 0.5 * (log_var + (y - mean) ** 2 * torch.exp(-log_var)).mean()


class FrictionTask(L.LightningModule):
    """One task around any :class:`FrictionModel`.

    Losses: ``"mae"`` (mean only), ``"nll"`` (Gaussian NLL on mean and variance), ``"mae+nll"`` (MAE trains
    the mean; NLL with the mean detached trains only the variance, so the uncertainty never pulls the
    estimate). Friction values and errors are in [-]; the logged ``val_mae`` drives checkpointing.
    """

    def __init__(self, model_cfg: dict[str, object], lr: float = 1e-3, weight_decay: float = 1e-4,
                 loss: str = "mae+nll", tau_scale: tuple[float, float] = (1.0, 1.0),
                 noise_std: float = 0.0, schedule: str = "plateau", max_minutes: float = 13.0,
                 lr_min_factor: float = 0.02, quantile_weight: float = 1.0) -> None:
        super().__init__()
        if loss not in LOSSES:
            raise ValueError(f"unknown loss {loss!r}; valid choices: {', '.join(LOSSES)}")
        if schedule not in SCHEDULES:
            raise ValueError(f"unknown schedule {schedule!r}; valid choices: {', '.join(SCHEDULES)}")
        self.save_hyperparameters()
        self.model: FrictionModel = build_model(ModelConfig(**model_cfg))
        # [raw units] per-feature std of the training windows (set by train()); 0 for the filter features
        self.raw_x_std = torch.ones(self.model.cfg.n_raw)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.model(x)

    def augment(self, x: torch.Tensor) -> torch.Tensor:
        """Training-only augmentation of raw windows (B, T, n_raw): torque scale and feature noise (the
        filter features, what the controller itself asked for, are left exact)."""
        lo, hi = self.hparams.tau_scale
        if hi > lo:
            log_s = torch.empty(x.shape[0], 1, 1, device=x.device).uniform_(math.log(lo), math.log(hi))
            x = torch.cat([x[..., :24], x[..., 24:N_FEATURES] * torch.exp(log_s), x[..., N_FEATURES:]], dim=-1)
        if self.hparams.noise_std > 0:  # in raw units: noise_std x each raw feature's training std
            x = x + torch.randn_like(x) * self.hparams.noise_std * self.raw_x_std
        return x

    def _loss(self, batch: tuple[torch.Tensor, torch.Tensor], stage: str) -> torch.Tensor:
        x, y = batch
        if stage == "train":
            x = self.augment(x)
        mean, log_var, lower = self.model.predict(x)
        mae = (mean - y).abs().mean()
        if self.hparams.loss == "mae":
            loss = mae
        elif self.hparams.loss == "nll":
            loss = gaussian_nll(mean, log_var, y)
        else:
            loss = mae + 0.1 * gaussian_nll(mean.detach(), log_var, y)
        if lower is not None:
            q = float(self.model.cfg.lower_quantile)
            ql = pinball(lower, y, q)
            loss = loss + self.hparams.quantile_weight * ql
            self.log(f"{stage}_pinball", ql, on_epoch=True, on_step=False)
            self.log(f"{stage}_lower_over", ((lower - y) > 0.05).float().mean(), on_epoch=True, on_step=False)
        self.log(f"{stage}_loss", loss, prog_bar=stage == "train", on_epoch=True, on_step=False)
        self.log(f"{stage}_mae", mae, prog_bar=True, on_epoch=True, on_step=False)
        return loss

    def training_step(self, batch: tuple[torch.Tensor, torch.Tensor], batch_idx: int) -> torch.Tensor:
        return self._loss(batch, "train")

    def validation_step(self, batch: tuple[torch.Tensor, torch.Tensor], batch_idx: int) -> None:
        self._loss(batch, "val")

    def test_step(self, batch: tuple[torch.Tensor, torch.Tensor], batch_idx: int) -> None:
        self._loss(batch, "test")

    def configure_optimizers(self) -> dict[str, object]:
        opt = torch.optim.AdamW(self.parameters(), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay)
        if self.hparams.schedule == "cosine_time":
            budget = 60.0 * float(self.hparams.max_minutes)
            lo = float(self.hparams.lr_min_factor)
            t0 = time.perf_counter()

            def factor(_: int) -> float:
                frac = min(1.0, (time.perf_counter() - t0) / budget)
                return lo + (1.0 - lo) * 0.5 * (1.0 + math.cos(math.pi * frac))

            sched = torch.optim.lr_scheduler.LambdaLR(opt, factor)
            return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": "step"}}
        sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=3)
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "monitor": "val_mae"}}


def make_config(overrides: list[str] | None = None) -> DictConfig:
    """DEFAULTS <- VARIANT_DEFAULTS[estimator] <- overrides (dot-list)."""
    cli = OmegaConf.from_dotlist(list(overrides or []))
    variant = str(cli.get("estimator", DEFAULTS["estimator"]))
    if variant not in VARIANT_DEFAULTS:
        raise ValueError(f"unknown estimator {variant!r}; trainable estimators: {', '.join(VARIANTS)}")
    cfg = OmegaConf.merge(OmegaConf.create(DEFAULTS), OmegaConf.create(VARIANT_DEFAULTS[variant]), cli)
    return cfg  # type: ignore[return-value]


def train(cfg: DictConfig, datamodule: WindowDataModule | None = None) -> tuple[FrictionTask, dict[str, object]]:
    """Fit, export the best model (if ``cfg.export``) and return (task with best weights, training record)."""
    torch.set_num_threads(int(cfg.threads))
    L.seed_everything(int(cfg.seed), workers=True)
    filter_mu = bool(cfg.model.get("filter_mu_input", False))
    dm = datamodule or WindowDataModule(cfg.data_dir, batch_size=int(cfg.batch_size), filter_mu=filter_mu)
    dm.setup("fit")
    task = FrictionTask(
        OmegaConf.to_container(cfg.model), cfg.lr, cfg.weight_decay, cfg.loss,  # type: ignore[arg-type]
        tuple(cfg.augment.tau_scale), float(cfg.augment.noise_std), str(cfg.schedule),
        float(cfg.trainer.max_minutes), float(cfg.lr_min_factor), float(cfg.quantile_weight),
    )
    task.model.fit_normaliser(*dm.tensors["train"])
    x_train = dm.tensors["train"][0]
    task.raw_x_std = x_train.reshape(-1, x_train.shape[-1]).std(0).clamp_min(1e-6)
    task.raw_x_std[N_FEATURES:] = 0.0  # filter features: no noise
    run_dir = Path(cfg.runs_dir) / str(cfg.name or cfg.estimator)
    tcfg = cfg.trainer
    ckpt = ModelCheckpoint(dirpath=run_dir / "checkpoints", monitor="val_mae", mode="min", save_top_k=1)
    trainer = L.Trainer(
        max_epochs=int(tcfg.max_epochs),
        max_time={"minutes": float(tcfg.max_minutes)},
        accelerator="cpu",
        devices=1,
        deterministic=False,
        fast_dev_run=bool(tcfg.fast_dev_run),
        logger=CSVLogger(str(run_dir), name="csv"),
        callbacks=[ckpt, EarlyStopping("val_mae", patience=int(tcfg.patience), mode="min"),
                   TQDMProgressBar(refresh_rate=20)],
        enable_model_summary=False,
    )
    t0, c0 = time.perf_counter(), time.process_time()
    trainer.fit(task, datamodule=dm)
    train_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    if ckpt.best_model_path:
        state = torch.load(ckpt.best_model_path, map_location="cpu", weights_only=True)["state_dict"]
        task.load_state_dict(state)
    var_scale = calibrate_variance(task.model, *dm.tensors["val"]) if not bool(tcfg.fast_dev_run) else 1.0
    record: dict[str, object] = {
        "train_wall_time_s": round(train_s, 2),
        "train_cpu_time_s": round(cpu_s, 2),  # this process, all threads (the CPU is shared)
        "epochs": int(trainer.current_epoch),
        "global_steps": int(trainer.global_step),
        "best_val_mae": float(ckpt.best_model_score) if ckpt.best_model_score is not None else None,
        "train_windows": len(dm.tensors["train"][1]),
        "variance_scale_fitted_on_val": var_scale,
        "parameters": parameter_count(task.model),
        "torch_threads": int(cfg.threads),
        "versions": {"torch": torch.__version__, "lightning": L.__version__},
        "train_config": OmegaConf.to_container(cfg),
    }
    if bool(cfg.export) and not bool(tcfg.fast_dev_run):
        task.model.eval()
        export_dir = Path(cfg.export_dir) if cfg.export_dir else CHECKPOINT_DIR
        out = save_checkpoint(task.model, export_dir / str(cfg.name or cfg.estimator), {"training": record})
        print(f"exported {out}")
    return task, record


def main(argv: list[str] | None = None) -> None:
    cfg = make_config(sys.argv[1:] if argv is None else argv)
    print(OmegaConf.to_yaml(cfg))
    _, record = train(cfg)
    print(json.dumps({k: v for k, v in record.items() if k != "train_config"}, indent=2))


if __name__ == "__main__":
    main()
