"""Datasets written by :mod:`estimators.collect` and the Lightning datamodule around them."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, TensorDataset

from estimators.features import with_filter_channels

SPLITS = ("train", "val", "test", "shifted")


def window_filter_mu(f: np.lib.npyio.NpzFile) -> np.ndarray:
    """Friction the safety filter assumed per window [-] of an open collected ``.npz`` (NaN: no filter in
    the loop; all NaN for collections without filter records)."""
    if "filter_mu" not in f.files:
        return np.full(len(f["y"]), np.nan)
    return np.where(f["window_filtered"], f["filter_mu"][f["episode"]], np.nan)


def load_windows(path: Path | str, filter_mu: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(X (N, 40, 36) float32, y (N,) friction [-], episode (N,) int, window_filtered (N,) bool) of a
    collected ``.npz`` (any split). ``filter_mu``: X gets the 2 filter features per step (N, 40, 38)
    (:func:`estimators.features.with_filter_channels`, from :func:`window_filter_mu`)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"window set {path} not found (write one with `python -m estimators.collect`)")
    with np.load(path) as f:
        X, y = f["X"].astype(np.float32), f["y"].astype(np.float32)
        # window sets written by hand may have no episode ids: each window is then its own episode
        ep = f["episode"].astype(np.int64) if "episode" in f.files else np.arange(len(y))
        wf = f["window_filtered"].astype(bool) if "window_filtered" in f.files else np.zeros(len(y), bool)
        if filter_mu:
            X = with_filter_channels(X, window_filter_mu(f))
    return X, y, ep, wf


def load_foot_labels(path: Path | str) -> np.ndarray:
    """(N, 4) friction under each foot [-] (LEGS order) at the last sample of every window of a collected
    ``.npz``; collections made before the per-foot labels (uniform floors only) get ``y`` for every foot."""
    with np.load(path) as f:
        if "y_foot" in f.files:
            return f["y_foot"].astype(np.float32)
        if "patch" in f.files and np.isfinite(f["patch"]).any():  # pragma: no cover - every writer adds y_foot
            raise ValueError(f"{path}: patch episodes without per-foot labels")
        return np.repeat(f["y"].astype(np.float32)[:, None], 4, axis=1)


def load_split(data_dir: Path | str, split: str, filter_mu: bool = False,
               per_foot: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X (N, 40, 36) float32, y (N,) friction [-], episode (N,) int) of ``<data_dir>/<split>.npz``;
    ``filter_mu``: with the 2 filter features, (N, 40, 38) (:func:`load_windows`); ``per_foot``: y is the
    friction under each foot (N, 4) (:func:`load_foot_labels`)."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)}")
    path = Path(data_dir) / f"{split}.npz"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found; run `python -m estimators.collect --out {data_dir}`")
    X, y, ep = load_windows(path, filter_mu)[:3]
    return X, (load_foot_labels(path) if per_foot else y), ep


class WindowDataModule(L.LightningDataModule):
    """Train / val / test windows as in-memory tensors (the splits are already by episode)."""

    def __init__(
        self,
        data_dir: Path | str | None = None,
        batch_size: int = 128,
        arrays: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
        filter_mu: bool = False,
        crop_steps: int | None = None,
        per_foot: bool = False,
    ) -> None:
        """Either ``data_dir`` (npz files) or ``arrays`` = {split: (X, y)} (tests, tiny generated data);
        ``filter_mu``: load the windows with the 2 filter features (:func:`load_split`); ``crop_steps``: keep
        only the last that many samples of every window (short-window models, e.g. the drop detector of
        :class:`estimators.learned.LearnedEstimator`); ``per_foot``: labels under each foot (N, 4)."""
        super().__init__()
        if (data_dir is None) == (arrays is None):
            raise ValueError("give exactly one of data_dir or arrays")
        if crop_steps is not None and crop_steps < 1:
            raise ValueError(f"crop_steps must be >= 1, got {crop_steps!r}")
        self.data_dir, self.batch_size, self._arrays, self.filter_mu = data_dir, batch_size, arrays, filter_mu
        self.crop_steps, self.per_foot = crop_steps, per_foot
        self.tensors: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}

    def setup(self, stage: str | None = None) -> None:
        if self.tensors:
            return
        for split in ("train", "val", "test"):
            if self._arrays is not None:
                X, y = self._arrays[split]
            else:
                X, y, _ = load_split(self.data_dir, split, self.filter_mu, self.per_foot)  # type: ignore[arg-type]
            if self.crop_steps is not None:
                if self.crop_steps > X.shape[1]:
                    raise ValueError(f"crop_steps={self.crop_steps} exceeds the {X.shape[1]}-sample windows")
                X = X[:, -self.crop_steps :]
            self.tensors[split] = (
                torch.from_numpy(np.asarray(X, np.float32)),
                torch.from_numpy(np.asarray(y, np.float32)),
            )

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        return DataLoader(TensorDataset(*self.tensors[split]), batch_size=self.batch_size, shuffle=shuffle)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", False)
