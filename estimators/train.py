"""Train one friction estimator variant (``python -m estimators.train estimator=linformer [key=value ...]``).

Overrides are OmegaConf dot-list entries on :data:`DEFAULTS` (merged with the variant's entry in
:data:`VARIANT_DEFAULTS`), e.g. ``model.d_model=64 trainer.max_minutes=10 data_dir=/work/data/estimators``.
The run folder (Lightning checkpoints, CSV log) is ``<runs_dir>/<estimator>``; the best model (lowest
validation MAE) is exported to ``estimators/checkpoints/<estimator>.pt/.json`` with the training record
(wall-clock training time, epochs, steps, best validation MAE, threads, versions).

With ``ensemble=n`` (n >= 2) the command trains n members side by side, each in its own process with
``threads // n`` threads and training seed ``seed + i`` (the same data, config and ``trainer.max_minutes``),
so the variant's wall-clock training time stays that budget; member 0 prints its progress, the others log
to ``<runs_dir>/<name>/member<i>.log``. The members are exported to ``<runs_dir>/<name>/members/``; the
ensemble (:class:`estimators.models.EnsembleModel`, its variance calibrated on the validation split) is
exported as one checkpoint with the members' training records and the wall time of the whole.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint, TQDMProgressBar
from lightning.pytorch.loggers import CSVLogger
from omegaconf import DictConfig, OmegaConf

from estimators.checkpoint import CHECKPOINT_DIR, load_checkpoint, save_checkpoint
from estimators.data import WindowDataModule, load_split
from estimators.features import N_FEATURES, WINDOW_STEPS
from estimators.models import (
    VARIANTS,
    EnsembleModel,
    FrictionModel,
    ModelConfig,
    build_model,
    calibrate_variance,
    parameter_count,
)
from taslel_bench.interfaces import overestimates

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
    "ensemble": 1,  # >= 2: that many members trained side by side (seeds seed..seed+n-1), exported as one
    "member_of": None,  # set by the ensemble parent for its members: always export (fast_dev_run included)
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
            self.log(f"{stage}_lower_over", overestimates(lower, y).float().mean(), on_epoch=True, on_step=False)
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
    steps = int(cfg.model.get("window_steps", WINDOW_STEPS))  # < 40: a short-window model on the last samples
    per_foot = bool(cfg.model.get("per_foot", False)) or cfg.model.get("tokens") == "foot"
    dm = datamodule or WindowDataModule(cfg.data_dir, batch_size=int(cfg.batch_size), filter_mu=filter_mu,
                                        crop_steps=steps if steps != WINDOW_STEPS else None, per_foot=per_foot)
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
    if cfg.member_of is not None or (bool(cfg.export) and not bool(tcfg.fast_dev_run)):
        task.model.eval()
        export_dir = Path(cfg.export_dir) if cfg.export_dir else CHECKPOINT_DIR
        out = save_checkpoint(task.model, export_dir / str(cfg.name or cfg.estimator), {"training": record})
        print(f"exported {out}")
    return task, record


def member_overrides(cfg: DictConfig, i: int, members_dir: Path) -> list[str]:
    """Dot-list of ensemble member ``i``: the parent's config with one member, seed ``seed + i``, its share
    of the threads, exported to ``members_dir`` as ``<name>_m<i>``."""
    name = str(cfg.name or cfg.estimator)
    flat = OmegaConf.to_container(cfg)
    assert isinstance(flat, dict)
    flat.update(ensemble=1, seed=int(cfg.seed) + i, threads=max(1, int(cfg.threads) // int(cfg.ensemble)),
                name=f"{name}_m{i}", export_dir=str(members_dir), member_of=name, runs_dir=str(members_dir.parent))
    return [f"{k}={json.dumps(v) if not isinstance(v, str) else v}" for k, v in _dotted(flat)]


def _dotted(d: dict[str, object], prefix: str = "") -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for k, v in d.items():
        if isinstance(v, dict) and v:
            out += _dotted(v, f"{prefix}{k}.")
        elif not (isinstance(v, dict) or v is None):
            out.append((f"{prefix}{k}", v))
    return out


def train_ensemble(cfg: DictConfig) -> tuple[EnsembleModel, dict[str, object]]:
    """Train ``cfg.ensemble`` members side by side (one process each), combine, calibrate on the validation
    split, export (if ``cfg.export``); returns (ensemble, record). A failed member raises, naming its log."""
    n = int(cfg.ensemble)
    name = str(cfg.name or cfg.estimator)
    run_dir = Path(cfg.runs_dir) / name
    members_dir = run_dir / "members"
    members_dir.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    procs, logs, files = [], [], []
    t0 = time.perf_counter()
    for i in range(n):
        cmd = [sys.executable, "-m", "estimators.train", *member_overrides(cfg, i, members_dir)]
        log = run_dir / f"member{i}.log"
        logs.append(log)
        out = None if i == 0 else log.open("w")
        if out is not None:
            files.append(out)
        procs.append(subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT if out else None, env=env))
        print(f"ensemble member {i}: seed {int(cfg.seed) + i}" + ("" if i == 0 else f", log {log}"))
    codes = [p.wait() for p in procs]
    wall = time.perf_counter() - t0
    for f in files:
        f.close()
    bad = [i for i, c in enumerate(codes) if c != 0]
    if bad:
        raise RuntimeError(f"ensemble members {bad} failed (exit codes {[codes[i] for i in bad]}); "
                           f"logs: {[str(logs[i]) for i in bad if i > 0] or 'above'}")
    loaded = [load_checkpoint(members_dir / f"{name}_m{i}") for i in range(n)]
    ens = EnsembleModel([m for m, _ in loaded]).eval()  # type: ignore[misc]
    fast = bool(cfg.trainer.fast_dev_run)
    var_scale = 1.0
    if not fast:
        x_val, y_val, _ = load_split(cfg.data_dir, "val", bool(cfg.model.get("filter_mu_input", False)))
        x_val = x_val[:, -int(cfg.model.get("window_steps", WINDOW_STEPS)) :]
        torch.set_num_threads(int(cfg.threads))
        var_scale = calibrate_variance(ens, torch.from_numpy(x_val), torch.from_numpy(y_val))
    recs = [meta["training"] for _, meta in loaded]
    record: dict[str, object] = {
        "train_wall_time_s": round(wall, 2),  # all members, side by side, from the first start to the last end
        "train_cpu_time_s": round(sum(float(r["train_cpu_time_s"]) for r in recs), 2),
        "members": n,
        "epochs": [r["epochs"] for r in recs],
        "best_val_mae": [r["best_val_mae"] for r in recs],
        "train_windows": recs[0]["train_windows"],
        "variance_scale_fitted_on_val": var_scale,
        "parameters": parameter_count(ens),
        "torch_threads": int(cfg.threads),
        "member_records": recs,
        "versions": {"torch": torch.__version__, "lightning": L.__version__},
        "train_config": OmegaConf.to_container(cfg),
    }
    if bool(cfg.export) and not fast:
        export_dir = Path(cfg.export_dir) if cfg.export_dir else CHECKPOINT_DIR
        print(f"exported {save_checkpoint(ens, export_dir / name, {'training': record})}")
    return ens, record


def main(argv: list[str] | None = None) -> None:
    cfg = make_config(sys.argv[1:] if argv is None else argv)
    print(OmegaConf.to_yaml(cfg))
    if int(cfg.ensemble) < 1:
        raise ValueError(f"ensemble must be >= 1 (members), got {cfg.ensemble!r}")
    _, record = train_ensemble(cfg) if int(cfg.ensemble) > 1 else train(cfg)
    print(json.dumps({k: v for k, v in record.items() if k != "train_config"}, indent=2))


if __name__ == "__main__":
    main()
