"""Datasets written by :mod:`estimators.collect` and the Lightning datamodule around them."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, TensorDataset

from estimators.features import with_filter_channels

SPLITS = ("train", "val", "test", "shifted")


def load_split(data_dir: Path | str, split: str, filter_mu: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X (N, 40, 36) float32, y (N,) friction [-], episode (N,) int) of ``<data_dir>/<split>.npz``.
    ``filter_mu``: X gets the 2 filter features per step (N, 40, 38), from the per-episode ``filter_mu`` the
    collection saved (:func:`estimators.features.with_filter_channels`; collections without filter
    records count as unfiltered)."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)}")
    path = Path(data_dir) / f"{split}.npz"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found; run `python -m estimators.collect --out {data_dir}`")
    with np.load(path) as f:
        X, y, ep = f["X"].astype(np.float32), f["y"].astype(np.float32), f["episode"].astype(np.int64)
        if not filter_mu:
            return X, y, ep
        if "filter_mu" in f.files:
            mu_w = np.where(f["window_filtered"], f["filter_mu"][ep], np.nan)
        else:
            mu_w = np.full(len(y), np.nan)
    return with_filter_channels(X, mu_w), y, ep


class WindowDataModule(L.LightningDataModule):
    """Train / val / test windows as in-memory tensors (the splits are already by episode)."""

    def __init__(
        self,
        data_dir: Path | str | None = None,
        batch_size: int = 128,
        arrays: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
        filter_mu: bool = False,
    ) -> None:
        """Either ``data_dir`` (npz files) or ``arrays`` = {split: (X, y)} (tests, tiny generated data);
        ``filter_mu``: load the windows with the 2 filter features (:func:`load_split`)."""
        super().__init__()
        if (data_dir is None) == (arrays is None):
            raise ValueError("give exactly one of data_dir or arrays")
        self.data_dir, self.batch_size, self._arrays, self.filter_mu = data_dir, batch_size, arrays, filter_mu
        self.tensors: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}

    def setup(self, stage: str | None = None) -> None:
        if self.tensors:
            return
        for split in ("train", "val", "test"):
            if self._arrays is not None:
                X, y = self._arrays[split]
            else:
                X, y, _ = load_split(self.data_dir, split, self.filter_mu)  # type: ignore[arg-type]
            self.tensors[split] = (torch.from_numpy(np.asarray(X, np.float32)), torch.from_numpy(np.asarray(y, np.float32)))

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        return DataLoader(TensorDataset(*self.tensors[split]), batch_size=self.batch_size, shuffle=shuffle)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", False)
