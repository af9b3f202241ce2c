"""The data of a training run: a LightningDataModule over a dataset store.

* Training: :class:`~dgse.data.torch_dataset.TrainingSet` over the store's
  ``train`` split: ``configs_per_env`` fresh random sensor configurations per
  environment and epoch, with the six symmetry augmentations (paper Sec. IV).
* Validation: :class:`~dgse.data.torch_dataset.FixedSet` over the ``val``
  split, the first ``val_configs_per_env`` of the store's fixed
  configurations per environment (the paper uses 30; fewer keep validation
  cheap), never augmented: every validation sees the same samples.

The cases of both splits are read into memory once (:meth:`DGSEDataModule.load`)
and shared by the two sets, on one canvas that holds every map of both.

Epochs, workers and determinism
-------------------------------
A :class:`TrainingSet` item is a pure function of ``(seed, epoch, index)``;
the epoch is an attribute of the dataset object.  The DataLoaders use
``persistent_workers=False``: every epoch creates new worker processes that
receive a copy of the dataset object as it is *when the epoch's iterator is
created*, so setting the epoch on the main process' copy before that is
enough (no state has to reach running workers).  :class:`EpochSetup` does it
in ``on_train_epoch_start``, which Lightning runs before it creates the
iterator of every epoch after the first; the first epoch's iterator is created
earlier (in ``FitLoop.setup_data``), so the module is built with the epoch it
starts at (``start_epoch``, non-zero when a run is resumed).  Trading
persistent workers for this costs one worker start per epoch (a fork, cheap on
Linux; with the ``spawn``/``forkserver`` start methods every worker unpickles
the cases, which costs seconds per epoch for a paper-size dataset).

The sample order is a random permutation that depends only on ``(seed,
epoch)`` (:class:`EpochShuffleSampler`; with several processes, a
``DistributedSampler`` with the same seed), and :class:`EpochSetup` reseeds
PyTorch's global RNG (the DGSE-S reparameterization noise) from ``(seed,
epoch, rank)`` at every epoch start, so an epoch runs the same whether or not
the run was interrupted and resumed before it.  Workers ignore SIGINT
(:func:`ignore_sigint`): a Ctrl-C stops training through the main process
(:class:`~dgse.training.train.StopControl`) instead of killing the workers.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, DistributedSampler, Sampler

from dgse.data.torch_dataset import FixedSet, TrainingSet, common_canvas, load_cases
from dgse.errors import InputDataError
from dgse.world.case import Case

__all__ = ["DGSEDataModule", "EpochSetup", "EpochShuffleSampler", "derive_seed", "ignore_sigint"]


def ignore_sigint(worker_id: int) -> None:
    """DataLoader ``worker_init_fn``: workers ignore Ctrl-C, so the main process can stop cleanly."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def derive_seed(*parts: int) -> int:
    """A 63-bit seed that depends on all ``parts`` (non-negative ints), via NumPy's SeedSequence."""
    state = np.random.SeedSequence([int(p) for p in parts]).generate_state(1, dtype=np.uint64)[0]
    return int(state >> np.uint64(1))


class EpochShuffleSampler(Sampler[int]):
    """A random permutation of ``range(n)`` that depends only on ``(seed, epoch)``.

    Lightning calls :meth:`set_epoch` before every epoch.
    """

    def __init__(self, n: int, seed: int = 0, epoch: int = 0) -> None:
        self.n = int(n)
        self.seed = int(seed)
        self.epoch = int(epoch)

    def set_epoch(self, epoch: int) -> None:
        """Use the permutation of ``epoch``."""
        self.epoch = int(epoch)

    def __iter__(self) -> Iterator[int]:
        g = torch.Generator().manual_seed(derive_seed(self.seed, self.epoch, 0x5A3))
        return iter(torch.randperm(self.n, generator=g).tolist())

    def __len__(self) -> int:
        return self.n


class DGSEDataModule(L.LightningDataModule):
    """Training and validation data of one dataset store (see the module docstring).

    Args:
        store: path of the dataset store (``.h5``).
        batch_size: samples per batch and device (training and validation).
        configs_per_env: fresh training configurations per environment and epoch.
        val_configs_per_env: fixed validation configurations per environment
            (0: no validation data).
        num_workers: DataLoader worker processes (0: load in the main process).
        seed: base seed of the training draws and of the shuffling.
        augment: random symmetry transform of every training sample.
        start_epoch: the first epoch this run trains (non-zero on resume).
    """

    def __init__(
        self,
        store: str | Path,
        batch_size: int,
        configs_per_env: int = 30,
        val_configs_per_env: int = 30,
        num_workers: int = 0,
        seed: int = 0,
        augment: bool = True,
        start_epoch: int = 0,
    ) -> None:
        super().__init__()
        self.store = Path(store)
        self.batch_size = int(batch_size)
        self.configs_per_env = int(configs_per_env)
        self.val_configs_per_env = int(val_configs_per_env)
        self.num_workers = int(num_workers)
        self.seed = int(seed)
        self.augment = bool(augment)
        self.epoch = int(start_epoch)
        self.train_cases: list[Case] | None = None
        self.val_entries: list[tuple[str, int, Case]] = []
        self.canvas: tuple[int, int] | None = None
        self.resolution: float | None = None
        self.train_set: TrainingSet | None = None
        self.val_set: FixedSet | None = None
        self._train_sampler: EpochShuffleSampler | DistributedSampler | None = None

    # -- data ----------------------------------------------------------------------------
    def load(self) -> None:
        """Read the cases of both splits into memory and build the datasets (once)."""
        if self.train_set is not None:
            return
        if not self.store.is_file():
            raise InputDataError(f"dataset store {self.store} not found")
        self.train_cases = [c for _, _, c in load_cases(self.store, "train")]
        if self.val_configs_per_env > 0:
            try:
                self.val_entries = load_cases(self.store, "val")
            except InputDataError as e:
                raise InputDataError(
                    f"{e} (set val_configs_per_env: 0 to train without validation)"
                ) from None
        every = self.train_cases + [c for _, _, c in self.val_entries]
        resolutions = sorted({float(c.grid.resolution) for c in every})
        if len(resolutions) != 1:
            raise InputDataError(f"{self.store}: cases of different cell sizes {resolutions} m")
        self.resolution = resolutions[0]
        self.canvas = common_canvas(every)
        self.train_set = TrainingSet(
            self.train_cases,
            configs_per_env=self.configs_per_env,
            seed=self.seed,
            augment=self.augment,
            canvas=self.canvas,
        )
        self.train_set.set_epoch(self.epoch)
        if self.val_entries:
            self.val_set = FixedSet(
                self.store,
                "val",
                configs_per_env=self.val_configs_per_env,
                canvas=self.canvas,
                cases=self.val_entries,
            )

    def setup(self, stage: str | None = None) -> None:
        """Lightning hook: :meth:`load` (a no-op when already loaded)."""
        self.load()

    def set_epoch(self, epoch: int) -> None:
        """Use the training draws and the sample order of ``epoch``."""
        self.epoch = int(epoch)
        if self.train_set is not None:
            self.train_set.set_epoch(self.epoch)
        if self._train_sampler is not None:
            self._train_sampler.set_epoch(self.epoch)

    @property
    def n_train(self) -> int:
        """Training samples per epoch (all devices together)."""
        self.load()
        assert self.train_set is not None
        return len(self.train_set)

    @property
    def n_val(self) -> int:
        """Validation samples (all devices together)."""
        self.load()
        return 0 if self.val_set is None else len(self.val_set)

    # -- loaders -------------------------------------------------------------------------
    def _loader_kwargs(self) -> dict[str, Any]:
        trainer = self.trainer
        pin = trainer is not None and trainer.strategy.root_device.type == "cuda"
        return {
            "batch_size": self.batch_size,
            "num_workers": self.num_workers,
            "persistent_workers": False,
            "pin_memory": pin,
            "worker_init_fn": ignore_sigint if self.num_workers > 0 else None,
        }

    def train_dataloader(self) -> DataLoader:
        """Shuffled training batches of the current epoch (see the module docstring)."""
        self.load()
        assert self.train_set is not None
        trainer = self.trainer
        sampler: EpochShuffleSampler | DistributedSampler
        if trainer is not None and trainer.world_size > 1:
            # Lightning leaves a DistributedSampler alone; it calls set_epoch every epoch
            sampler = DistributedSampler(
                self.train_set,
                num_replicas=trainer.world_size,
                rank=trainer.global_rank,
                shuffle=True,
                seed=self.seed,
            )
        else:
            sampler = EpochShuffleSampler(len(self.train_set), self.seed)
        sampler.set_epoch(self.epoch)
        self._train_sampler = sampler
        return DataLoader(self.train_set, sampler=sampler, **self._loader_kwargs())

    def val_dataloader(self) -> DataLoader | Sequence[Any]:
        """The fixed validation batches, in order (an empty list without validation data)."""
        self.load()
        if self.val_set is None:
            return []
        return DataLoader(self.val_set, shuffle=False, **self._loader_kwargs())


class EpochSetup(L.Callback):
    """At every training epoch start: the data module's epoch and a reseeded global RNG.

    Sets :meth:`DGSEDataModule.set_epoch` to ``trainer.current_epoch`` and seeds
    PyTorch (CPU and every GPU) with ``derive_seed(seed, epoch, global_rank)``.

    Args:
        seed: the run's seed.
    """

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)

    def on_train_epoch_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        epoch = int(trainer.current_epoch)
        dm = getattr(trainer, "datamodule", None)
        if isinstance(dm, DGSEDataModule):
            dm.set_epoch(epoch)
        torch.manual_seed(derive_seed(self.seed, epoch, int(trainer.global_rank)))
