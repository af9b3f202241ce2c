"""PyTorch datasets over a dataset store (paper Sec. IV, "Training and input configuration").

* :class:`TrainingSet`: every environment (case) of a split, ``configs_per_env``
  times per epoch, each time with a fresh random sensor configuration (the
  number of sensors drawn from {5, 10, ..., 300}, positions uniform over free
  cells, fresh Table I noise) and one of the six symmetry transforms.
* :class:`FixedSet`: the store's fixed validation or test configurations
  (30 per environment), no augmentation: every evaluation sees the same samples.

Seeding is worker-safe: sample ``idx`` of epoch ``e`` draws from
``default_rng([seed, e, idx])`` and nothing else, so the result does not depend
on which DataLoader worker makes it or in which order (call
:meth:`TrainingSet.set_epoch` at the start of every epoch for fresh draws).

Items are dicts of tensors on one canvas ``(S, S)`` shared by the whole set:
``inputs (5, S, S)``, ``wind (2, S, S)``, ``log_conc (S, S)``, ``valid (S, S)``
(bool), ``source_index`` (int64 flat canvas index) and ``n_obs``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from dgse.data.augment import random_symmetry, transform_sample
from dgse.data.rasterize import Sample, canvas_shape_for, make_sample
from dgse.data.store import DatasetStore
from dgse.errors import InputDataError
from dgse.sensing.noise import NoiseModel
from dgse.sensing.sensors import measure, random_observation_count, random_observations
from dgse.world.case import Case

CONFIGS_PER_ENV = 30


def load_cases(store: str | Path | DatasetStore, split: str) -> list[tuple[str, int, Case]]:
    """Every ``(layout_id, source_index, case)`` of ``split``, read into memory."""
    if isinstance(store, DatasetStore):
        return list(store.iter_cases(split))
    with DatasetStore(store, "r") as s:
        out = list(s.iter_cases(split))
    if not out:
        raise InputDataError(f"{store}: no cases in split {split!r}")
    return out


def common_canvas(cases: Sequence[Case], minimum: int = 100, stride: int = 16) -> tuple[int, int]:
    """The smallest canvas (as :func:`canvas_shape_for`) that holds every map."""
    H = max(c.occupancy.shape[0] for c in cases)
    W = max(c.occupancy.shape[1] for c in cases)
    return canvas_shape_for((H, W), minimum=minimum, stride=stride)


def sample_to_tensors(sample: Sample, n_obs: int) -> dict[str, torch.Tensor]:
    t = sample.targets
    return {
        "inputs": torch.from_numpy(np.ascontiguousarray(sample.inputs)),
        "wind": torch.from_numpy(np.ascontiguousarray(t.wind)),
        "log_conc": torch.from_numpy(np.ascontiguousarray(t.log_concentration)),
        "valid": torch.from_numpy(np.ascontiguousarray(t.valid)),
        "source_index": torch.tensor(t.source_index, dtype=torch.int64),
        "n_obs": torch.tensor(n_obs, dtype=torch.int64),
    }


class TrainingSet(Dataset):
    """Fresh random sensor configurations and symmetry transforms, every epoch.

    Args:
        cases: the environments (e.g. ``[c for _, _, c in load_cases(store, "train")]``).
        configs_per_env: samples per environment and epoch (paper: 30).
        seed: base seed of every draw.
        augment: apply a random one of the six symmetry transforms.
        noise: the sensor noise model (Table I ranges by default).
        canvas: the canvas shape (default: :func:`common_canvas` of ``cases``).
    """

    def __init__(
        self,
        cases: Sequence[Case],
        configs_per_env: int = CONFIGS_PER_ENV,
        seed: int = 0,
        augment: bool = True,
        noise: NoiseModel | None = None,
        canvas: tuple[int, int] | None = None,
    ) -> None:
        if not cases:
            raise InputDataError("a training set needs at least one case")
        if configs_per_env < 1:
            raise InputDataError(f"configs_per_env must be >= 1, got {configs_per_env}")
        self.cases = list(cases)
        self.configs_per_env = int(configs_per_env)
        self.seed = int(seed)
        self.augment = augment
        self.noise = noise or NoiseModel()
        self.canvas = canvas or common_canvas(self.cases)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Use the draws of ``epoch`` (call at the start of every epoch)."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.cases) * self.configs_per_env

    def __getitem__(self, idx: int) -> dict[str, torch.Tensor]:
        if not 0 <= idx < len(self):
            raise IndexError(idx)
        case = self.cases[idx // self.configs_per_env]
        rng = np.random.default_rng([self.seed, self.epoch, idx])
        n = min(random_observation_count(rng), int(case.free.sum()))
        obs = random_observations(case, n, rng, self.noise)
        sample = make_sample(case, obs, self.canvas)
        if self.augment:
            sample = transform_sample(sample, random_symmetry(rng))
        return sample_to_tensors(sample, n)


class FixedSet(Dataset):
    """The store's fixed sensor configurations of a split (validation or test).

    Args:
        store: path of the dataset store (configurations it does not hold yet
            are drawn deterministically from its seed, see
            :meth:`DatasetStore.fixed_configurations`).
        split: ``"val"`` or ``"test"``.
        configs_per_env: use the first this many configurations per environment.
        canvas: the canvas shape (default: :func:`common_canvas` of the split).
    """

    def __init__(
        self,
        store: str | Path,
        split: str = "val",
        configs_per_env: int = CONFIGS_PER_ENV,
        canvas: tuple[int, int] | None = None,
        noise: NoiseModel | None = None,
        cases: Sequence[tuple[str, int, Case]] | None = None,
    ) -> None:
        with DatasetStore(store, "r") as s:
            fixed = s.fixed_configurations(split)
            self.entries = list(cases) if cases is not None else list(s.iter_cases(split))
        if not self.entries:
            raise InputDataError(f"{store}: no cases in split {split!r}")
        self.items = []
        for e, (layout_id, k, _) in enumerate(self.entries):
            configs = fixed.for_env(layout_id, k)[:configs_per_env]
            self.items += [(e, cfg) for cfg in configs]
        self.noise = noise or NoiseModel()
        self.canvas = canvas or common_canvas([c for _, _, c in self.entries])

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, idx: int) -> dict[str, torch.Tensor]:
        e, cfg = self.items[idx]
        case = self.entries[e][2]
        rng = cfg.rng()
        params = self.noise.draw(rng, float(case.concentration[case.free].mean()))
        obs = measure(case, cfg.cells, params, rng)
        return sample_to_tensors(make_sample(case, obs, self.canvas), len(cfg.cells))


__all__ = [
    "CONFIGS_PER_ENV",
    "FixedSet",
    "TrainingSet",
    "common_canvas",
    "load_cases",
    "sample_to_tensors",
]
