"""Training runs: :func:`train` on ``lightning.Trainer``, resumable through safetensors files.

``train(config)`` trains the network of a :class:`~dgse.training.config.TrainConfig`
on its dataset store, on the CPU, one GPU, or several GPUs and nodes (DDP:
``devices``, ``num_nodes`` and ``strategy`` are passed to Lightning), in
fp32 or mixed precision, and writes into ``config.out_dir``:

=======================  ======================================================
``config.yaml``          the configuration of the run
``last.safetensors``     the training state after the latest epoch: weights,
                         Adam state and progress (see below); ``--resume`` reads it
``best.safetensors``     the weights of the epoch with the lowest
                         ``val/source_loss`` so far (paper Sec. V-A), a model
                         checkpoint :func:`dgse.models.load_model` reads, with
                         training metadata (epoch, validation metrics, data,
                         config)
``history.csv``          one row per epoch, appended across resumed runs:
                         epoch-mean training and validation metrics, time
``logs/version_N/``      Lightning's CSVLogger of the N-th invocation:
                         ``metrics.csv`` (step- and epoch-level) and ``hparams.yaml``
=======================  ======================================================

and, if ``config.export`` is set, a copy of the selected model there (the
model of ``best.safetensors``; without validation, the final weights).

Checkpoints never use pickles (a repository rule: nothing is ever loaded
with ``torch.load``), so Lightning's ``.ckpt`` files are disabled
(``enable_checkpointing=False``) and :class:`TrainStateCheckpoint` writes the
state itself.  ``last.safetensors`` holds the tensors

* ``model.<name>``: the network's ``state_dict``;
* ``optimizer.<i>.<name>``: the optimizer's per-parameter state (Adam:
  ``exp_avg``, ``exp_avg_sq``, ``step``) of parameter ``i`` in
  ``model.parameters()`` order;

and the metadata entries ``format = "dgse-train-state"``, ``format_version``,
``model_config`` (JSON) and ``train_state``, a JSON object with
``next_epoch`` (epochs done), ``global_step``, ``best_score`` and
``best_epoch``, ``seed``, ``config_hash`` and ``identity`` (the settings a
resumed run must share, :meth:`TrainConfig.resume_identity`), the whole
``config``, ``param_names``, the optimizer's ``param_groups`` and non-tensor
state, the mixed-precision grad-scaler state (``"16-mixed"``), cumulative
training time, ``partial_epoch`` and ``stop_reason``.  Files are written to a
temporary name and renamed, so an interrupted write never leaves a broken file.

Resuming (``train(config, resume=True)``) checks the file (format, identity,
tensor names and shapes; every problem raises
:class:`~dgse.errors.InputDataError` naming the file), loads the weights
before training starts, and, once Lightning has built the optimizer
(``on_fit_start``), the optimizer state and the loop counters, so training
continues at epoch ``next_epoch`` with the same global step; epoch draws,
shuffling and DGSE-S noise are seeded per epoch, so a resumed epoch runs like
the same epoch of an uninterrupted run.

Stopping: the time budget ``max_time`` (per invocation, measured from the
call of :func:`train`; leave a margin for the final validation and save) and
a first Ctrl-C (SIGINT) both stop training after the current batch
(:class:`StopControl`; a second Ctrl-C aborts at once, saves nothing and
:func:`train` raises ``KeyboardInterrupt``).
As with Lightning's ``should_stop``, the stopped epoch is then validated,
counts as done (its remaining batches are skipped) and is saved, with
``partial_epoch = true``; ``--resume`` continues at the next epoch.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path
from types import FrameType
from typing import Any

import lightning as L
import torch
from lightning.fabric.utilities.exceptions import MisconfigurationException
from lightning.pytorch.loggers import CSVLogger
from lightning.pytorch.utilities.rank_zero import rank_zero_only
from safetensors import safe_open
from safetensors.torch import save_file

from dgse.errors import InputDataError
from dgse.files import atomic_path
from dgse.models.checkpoint import (
    CheckpointError,
    load_checkpoint,
    load_model,
    read_checkpoint_info,
    save_model,
)
from dgse.models.inference import native_bf16
from dgse.models.networks import DGSEModel, ModelConfig
from dgse.training.config import TrainConfig
from dgse.training.datamodule import DGSEDataModule, EpochSetup
from dgse.training.module import DGSELightningModule

__all__ = [
    "BEST_NAME",
    "HISTORY_NAME",
    "LAST_NAME",
    "STATE_FORMAT",
    "StopControl",
    "TrainResult",
    "TrainState",
    "TrainStateCheckpoint",
    "export_model",
    "init_weights",
    "prepare_out_dir",
    "read_train_state",
    "train",
]

LAST_NAME = "last.safetensors"
BEST_NAME = "best.safetensors"
HISTORY_NAME = "history.csv"
CONFIG_NAME = "config.yaml"
STATE_FORMAT = "dgse-train-state"
STATE_FORMAT_VERSION = 1
#: The checkpoint selection metric (paper Sec. V-A: the lowest validation SL loss).
MONITOR = "val/source_loss"

_HISTORY_COLUMNS = (
    "epoch",
    "global_step",
    "time_s",
    "train/loss",
    "train/source_loss",
    "train/wind_nll",
    "train/conc_nll",
    "val/loss",
    "val/source_loss",
    "val/wind_nll",
    "val/conc_nll",
    "val/loc_error_m",
    "best",
    "partial",
)


def _version(pkg: str) -> str:
    try:
        return _pkg_version(pkg)
    except PackageNotFoundError:
        return ""


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _json_default(v: Any) -> Any:
    if isinstance(v, torch.Tensor):
        return v.tolist()
    if isinstance(v, tuple | set):
        return list(v)
    if isinstance(v, Path):
        return str(v)
    raise TypeError(f"not JSON-serializable: {type(v).__name__}")


def _atomic_save(tensors: dict[str, torch.Tensor], path: Path, metadata: dict[str, str]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata=metadata)


# -- the training state file ------------------------------------------------------------------
@dataclass(eq=False)
class TrainState:
    """What ``last.safetensors`` holds, as read by :func:`read_train_state`.

    Attributes:
        path: the file.
        model_config: the architecture.
        meta: the ``train_state`` JSON object (see the module docstring).
        model_state: the network's ``state_dict`` (CPU tensors).
        optimizer_state: an optimizer ``state_dict`` (``state`` + ``param_groups``).
    """

    path: Path
    model_config: ModelConfig
    meta: dict[str, Any]
    model_state: dict[str, torch.Tensor]
    optimizer_state: dict[str, Any]

    @property
    def next_epoch(self) -> int:
        """The epoch training continues at (the number of epochs done)."""
        return int(self.meta["next_epoch"])

    @property
    def global_step(self) -> int:
        """Optimizer steps done."""
        return int(self.meta["global_step"])


def _flatten_optimizer(sd: Mapping[str, Any]) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    tensors: dict[str, torch.Tensor] = {}
    scalars: dict[str, dict[str, Any]] = {}
    for pid, st in sd["state"].items():
        for name, v in st.items():
            if isinstance(v, torch.Tensor):
                tensors[f"optimizer.{int(pid)}.{name}"] = v.detach().to("cpu").contiguous()
            else:
                scalars.setdefault(str(int(pid)), {})[name] = v
    return tensors, {"param_groups": sd["param_groups"], "scalars": scalars}


def _unflatten_optimizer(tensors: Mapping[str, torch.Tensor], meta: Mapping[str, Any]) -> dict[str, Any]:
    state: dict[int, dict[str, Any]] = {}
    for key, t in tensors.items():
        _, pid, name = key.split(".", 2)
        state.setdefault(int(pid), {})[name] = t
    for pid, values in (meta.get("scalars") or {}).items():
        state.setdefault(int(pid), {}).update(values)
    groups = []
    for g in meta["param_groups"]:
        g = dict(g)
        if isinstance(g.get("betas"), list):
            g["betas"] = tuple(g["betas"])
        groups.append(g)
    return {"state": state, "param_groups": groups}


def save_train_state(
    path: str | os.PathLike[str],
    model: DGSEModel,
    optimizer: torch.optim.Optimizer,
    meta: Mapping[str, Any],
) -> Path:
    """Write a training state file (see the module docstring) atomically.

    Args:
        path: destination (``last.safetensors``).
        model: the network; its ``state_dict`` is stored as ``model.<name>``.
        optimizer: its state is stored as ``optimizer.<i>.<name>`` plus JSON.
        meta: the progress entries of ``train_state`` (JSON-serializable).
    """
    p = Path(path)
    tensors = {f"model.{k}": v.detach().to("cpu").contiguous() for k, v in model.state_dict().items()}
    opt_tensors, opt_meta = _flatten_optimizer(optimizer.state_dict())
    tensors.update(opt_tensors)
    state = {
        **meta,
        "param_names": [n for n, _ in model.named_parameters()],
        "optimizer": opt_meta,
        "dgse_version": _version("dgse"),
        "torch_version": torch.__version__,
        "lightning_version": _version("lightning"),
        "written": _now(),
    }
    try:
        state_json = json.dumps(state, sort_keys=True, default=_json_default, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise InputDataError(f"training state for {p} is not JSON-serializable: {e}") from e
    metadata = {
        "format": STATE_FORMAT,
        "format_version": str(STATE_FORMAT_VERSION),
        "model_config": json.dumps(model.config.to_dict(), sort_keys=True),
        "train_state": state_json,
    }
    _atomic_save(tensors, p, metadata)
    return p


def read_train_state(path: str | os.PathLike[str], config: TrainConfig | None = None) -> TrainState:
    """Read and check a training state file.

    Args:
        path: ``last.safetensors`` of a run.
        config: if given, the file must come from a run with the same
            :meth:`TrainConfig.resume_identity` (architecture, batch size,
            optimizer, loss weights, data draws, seed).

    Raises:
        InputDataError: a missing, unreadable or foreign file, inconsistent
            contents, or a run that does not match ``config`` (the differing
            settings are named).
    """
    p = Path(path)
    if not p.is_file():
        raise InputDataError(f"nothing to resume: {p} not found")
    try:
        with safe_open(str(p), framework="pt", device="cpu") as f:
            metadata = dict(f.metadata() or {})
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except Exception as e:  # safetensors raises its own error types for corrupt files
        raise InputDataError(f"cannot resume from {p}: not a readable safetensors file ({e})") from None
    if metadata.get("format") != STATE_FORMAT:
        raise InputDataError(
            f"cannot resume from {p}: not a DGSE training state (no {STATE_FORMAT!r} format)"
        )
    try:
        version = int(metadata.get("format_version", ""))
        model_config = ModelConfig.from_dict(json.loads(metadata["model_config"]))
        meta = json.loads(metadata["train_state"])
        optimizer_meta = meta["optimizer"]
        param_names = list(meta["param_names"])
        int(meta["next_epoch"]), int(meta["global_step"])
    except (KeyError, ValueError, TypeError, InputDataError) as e:
        raise InputDataError(f"cannot resume from {p}: invalid metadata ({e})") from None
    if version > STATE_FORMAT_VERSION:
        raise InputDataError(
            f"cannot resume from {p}: format version {version} is newer than this dgse reads"
        )
    if config is not None:
        want = config.resume_identity()
        have = meta.get("identity") or {}
        differ = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
        if differ:
            detail = "; ".join(f"{k}: run {have.get(k)!r}, now {want.get(k)!r}" for k in differ)
            raise InputDataError(
                f"cannot resume from {p}: the run was trained with other settings ({detail}); "
                "use the run's settings or another output directory"
            )
    model_state = {k[len("model.") :]: v for k, v in tensors.items() if k.startswith("model.")}
    opt_tensors = {k: v for k, v in tensors.items() if k.startswith("optimizer.")}
    stray = sorted(k for k in tensors if not k.startswith(("model.", "optimizer.")))
    if stray:
        raise InputDataError(f"cannot resume from {p}: unexpected tensors {stray[:5]}")
    bad = [k for k, t in model_state.items() if t.is_floating_point() and not bool(torch.isfinite(t).all())]
    if bad:
        raise InputDataError(f"cannot resume from {p}: non-finite weights in {bad[:5]}")
    for key in opt_tensors:
        parts = key.split(".", 2)
        if len(parts) != 3 or not parts[1].isdigit() or int(parts[1]) >= len(param_names):
            raise InputDataError(f"cannot resume from {p}: bad optimizer tensor name {key!r}")
    try:
        optimizer_state = _unflatten_optimizer(opt_tensors, optimizer_meta)
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise InputDataError(f"cannot resume from {p}: invalid optimizer state ({e})") from None
    return TrainState(p, model_config, meta, model_state, optimizer_state)


def _load_weights(state: TrainState, model: DGSEModel) -> None:
    """Load the state's weights into ``model`` after checking names and shapes."""
    p = state.path
    names = [n for n, _ in model.named_parameters()]
    if list(state.meta["param_names"]) != names:
        raise InputDataError(f"cannot resume from {p}: its parameters do not match the configured model")
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state.model_state))
    unexpected = sorted(set(state.model_state) - set(expected))
    wrong = [
        k for k, v in expected.items() if k in state.model_state and state.model_state[k].shape != v.shape
    ]
    if missing or unexpected or wrong:
        raise InputDataError(
            f"cannot resume from {p}: its weights do not fit the configured model "
            f"(missing {missing[:3]}, unexpected {unexpected[:3]}, wrong shape {wrong[:3]})"
        )
    for pid, st in state.optimizer_state["state"].items():
        shape = tuple(expected[names[pid]].shape)
        for name, t in st.items():
            if isinstance(t, torch.Tensor) and t.ndim > 0 and tuple(t.shape) != shape:
                raise InputDataError(
                    f"cannot resume from {p}: optimizer state {name} of {names[pid]} has shape "
                    f"{tuple(t.shape)}, the parameter {shape}"
                )
    model.load_state_dict({k: state.model_state[k].to(v.dtype) for k, v in expected.items()}, strict=True)


def init_weights(model: DGSEModel, init: str | os.PathLike[str]) -> Path:
    """Copy the weights of ``init`` (a model file, or ``"default"``: the shipped ones) into ``model``.

    Raises:
        InputDataError: a missing or unreadable file, or a network of another variant or
            architecture than ``model``.
    """
    from dgse.estimators.dgse import default_model_path

    variant = model.config.variant
    path = default_model_path(variant) if str(init) == "default" else Path(init)
    if not path.is_file():
        raise InputDataError(f"init: {path} is not a model file")
    try:
        source = load_model(path)
    except CheckpointError as e:
        raise InputDataError(f"init: {e} (a run's best.safetensors is a model file)") from None
    want = {k: v for k, v in model.config.to_dict().items() if k != "preset"}
    got = {k: v for k, v in source.config.to_dict().items() if k != "preset"}
    if got != want:
        diff = sorted(k for k in want if want[k] != got.get(k))
        raise InputDataError(
            f"init: {path} holds another network than the configured one (differs in {', '.join(diff)})"
        )
    model.load_state_dict(source.state_dict())
    return path


def _set_progress(trainer: L.Trainer, next_epoch: int, global_step: int, batches_that_stepped: int) -> None:
    """Make Lightning's fit loop continue at ``next_epoch`` with ``global_step`` steps done."""
    fit_loop = trainer.fit_loop
    # (the trackers' static types are their base class: every counter is set through Any)
    epochs: Any = fit_loop.epoch_progress
    for tracker in (epochs.total, epochs.current):
        tracker.ready = tracker.started = tracker.processed = tracker.completed = next_epoch
    optim = fit_loop.epoch_loop.automatic_optimization.optim_progress.optimizer
    optim.step.total.ready = optim.step.total.completed = global_step
    zg: Any = optim.zero_grad.total
    zg.ready = zg.started = zg.completed = global_step
    fit_loop.epoch_loop._batches_that_stepped = batches_that_stepped


# -- callbacks ------------------------------------------------------------------------------
class StopControl(L.Callback):
    """Stops training cleanly after the batch at which the time budget runs out or Ctrl-C is pressed.

    The first SIGINT (installed only when training runs in the main thread) asks
    for a stop; a second one raises ``KeyboardInterrupt`` at once.  In
    multi-process runs rank 0 decides and broadcasts, so all ranks stop at the
    same batch.

    Args:
        max_time_s: budget in seconds (None: none).
        handle_sigint: install the SIGINT handler.
        t0: ``time.monotonic()`` the budget counts from (default: the start of training).

    Attributes:
        reason: None, ``"max_time"`` or ``"interrupted"`` once a stop was requested.
        aborted: a second Ctrl-C came.
    """

    def __init__(
        self, max_time_s: float | None = None, handle_sigint: bool = True, t0: float | None = None
    ) -> None:
        self.max_time_s = max_time_s
        self.handle_sigint = handle_sigint
        self.reason: str | None = None
        self.aborted = False
        self._sigint = False
        self._t0: float | None = t0
        self._old_handler: Any = None
        self._installed = False

    def _on_sigint(self, signum: int, frame: FrameType | None) -> None:
        if self._sigint:
            self.aborted = True
            raise KeyboardInterrupt
        self._sigint = True
        print(
            ("\n" if sys.stderr.isatty() else "")  # off the line of a progress bar
            + "stopping after this batch: validating and saving (Ctrl-C again to abort without saving)",
            file=sys.stderr,
            flush=True,
        )

    def install(self) -> None:
        """Install the SIGINT handler (main thread only)."""
        if (
            self.handle_sigint
            and not self._installed
            and threading.current_thread() is threading.main_thread()
        ):
            self._old_handler = signal.signal(signal.SIGINT, self._on_sigint)
            self._installed = True

    def uninstall(self) -> None:
        """Restore the previous SIGINT handler."""
        if self._installed:
            signal.signal(signal.SIGINT, self._old_handler)
            self._installed = False

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if self._t0 is None:
            self._t0 = time.monotonic()
        self.install()

    def elapsed_s(self) -> float:
        """Seconds since ``t0`` (default: the start of training; 0 before)."""
        return 0.0 if self._t0 is None else time.monotonic() - self._t0

    def on_train_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        local: str | None = None
        if self._sigint:
            local = "interrupted"
        elif self.max_time_s is not None and self.elapsed_s() >= self.max_time_s:
            local = "max_time"
        decision = trainer.strategy.broadcast(local, src=0) if trainer.world_size > 1 else local
        if decision and not trainer.should_stop:
            self.reason = decision
            trainer.should_stop = True
            if decision == "max_time":  # a Ctrl-C was answered when it came
                _note(f"time budget reached: stopping after epoch {trainer.current_epoch} batch {batch_idx}")

    def teardown(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        self.uninstall()


class TrainStateCheckpoint(L.Callback):
    """Writes ``last.safetensors``, ``best.safetensors`` and ``history.csv``; restores on resume.

    Args:
        out_dir: the run's directory.
        config: the run's configuration (stored in the files).
        resume: the state to continue from (None: a fresh run).
        stop: the run's :class:`StopControl` (for the stop reason).
        data_path: the dataset store (recorded in ``best``'s metadata).

    Attributes:
        best_score, best_epoch: the lowest ``val/source_loss`` so far and its epoch (0-based).
        epochs_done, global_step: progress after the latest saved epoch.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike[str],
        config: TrainConfig,
        resume: TrainState | None = None,
        stop: StopControl | None = None,
        data_path: str | None = None,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.config = config
        self.resume = resume
        self.stop = stop
        self.data_path = data_path
        self.best_score: float | None = None
        self.best_epoch: int | None = None
        self.epochs_done = 0
        self.global_step = 0
        self.train_time_s = 0.0
        self.samples_seen = 0  # training samples of this call (all ranks)
        self.call_train_time_s = 0.0  # training time of this call
        self._val: tuple[int, dict[str, float]] | None = None
        self._epoch_t0 = time.monotonic()
        self._best_this_epoch = False
        if resume is not None:
            self.epochs_done = resume.next_epoch
            self.global_step = resume.global_step
            self.train_time_s = float(resume.meta.get("train_time_s", 0.0))
            score = resume.meta.get("best_score")
            if isinstance(score, int | float):
                self.best_score, self.best_epoch = float(score), resume.meta.get("best_epoch")
        best = self.out_dir / BEST_NAME
        if resume is not None and best.is_file():  # a best saved after the last state still counts
            try:
                t = read_checkpoint_info(best).training
                s = t.get("val", {}).get(MONITOR)
                if isinstance(s, int | float) and (self.best_score is None or s < self.best_score):
                    self.best_score, self.best_epoch = float(s), t.get("epoch")
            except InputDataError:
                pass

    @property
    def last_path(self) -> Path:
        """``<out_dir>/last.safetensors``."""
        return self.out_dir / LAST_NAME

    @property
    def best_path(self) -> Path:
        """``<out_dir>/best.safetensors``."""
        return self.out_dir / BEST_NAME

    @property
    def history_path(self) -> Path:
        """``<out_dir>/history.csv``."""
        return self.out_dir / HISTORY_NAME

    # -- restore ---------------------------------------------------------------------------
    def on_fit_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if trainer.is_global_zero:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            self.config.save_yaml(self.out_dir / CONFIG_NAME)
        if self.resume is None:
            return
        st = self.resume
        optimizers = trainer.optimizers
        if len(optimizers) != 1:
            raise InputDataError(
                f"cannot resume from {st.path}: expected one optimizer, got {len(optimizers)}"
            )
        try:
            optimizers[0].load_state_dict(st.optimizer_state)
        except (ValueError, KeyError, RuntimeError) as e:
            raise InputDataError(
                f"cannot resume from {st.path}: optimizer state does not fit ({e})"
            ) from None
        scaler_state = st.meta.get("grad_scaler")
        scaler = getattr(trainer.precision_plugin, "scaler", None)
        if scaler is not None and isinstance(scaler_state, dict):
            scaler.load_state_dict(scaler_state)
        _set_progress(
            trainer, st.next_epoch, st.global_step, int(st.meta.get("batches_that_stepped", st.global_step))
        )
        _note(f"resumed from {st.path}: epoch {st.next_epoch}, step {st.global_step}")

    def on_train_epoch_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._epoch_t0 = time.monotonic()
        self._best_this_epoch = False

    def on_train_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        self.samples_seen += int(batch["inputs"].shape[0]) * int(trainer.world_size)

    # -- best ------------------------------------------------------------------------------
    def on_validation_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if trainer.sanity_checking:
            return
        metrics = {
            k: float(v)
            for k, v in trainer.callback_metrics.items()
            if k.startswith("val/") and v.numel() == 1
        }
        epoch = int(trainer.current_epoch)
        self._val = (epoch, metrics)
        score = metrics.get(MONITOR)
        if score is None or not math.isfinite(score):
            return
        if self.best_score is not None and not score < self.best_score:
            return
        self.best_score, self.best_epoch = score, epoch
        self._best_this_epoch = True
        if trainer.is_global_zero:
            assert isinstance(pl_module, DGSELightningModule)
            save_model(pl_module.model, self.best_path, training=self._best_meta(trainer, metrics))

    def _best_meta(self, trainer: L.Trainer, metrics: dict[str, float]) -> dict[str, Any]:
        return {
            "epoch": int(trainer.current_epoch),
            "global_step": int(trainer.global_step),
            "selection": f"lowest {MONITOR}",
            "val": metrics,
            "data": self.data_path,
            "config": self.config.to_dict(),
            "partial_epoch": self.stop is not None and self.stop.reason is not None,
            "written": _now(),
        }

    # -- last + history --------------------------------------------------------------------
    def on_train_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        epoch = int(trainer.current_epoch)
        epoch_time = time.monotonic() - self._epoch_t0
        self.train_time_s += epoch_time
        self.call_train_time_s += epoch_time
        self.epochs_done = epoch + 1
        self.global_step = int(trainer.global_step)
        reason = self.stop.reason if self.stop is not None else None
        if not trainer.is_global_zero:
            return
        assert isinstance(pl_module, DGSELightningModule)
        scaler = getattr(trainer.precision_plugin, "scaler", None)
        meta = {
            "next_epoch": self.epochs_done,
            "global_step": self.global_step,
            "batches_that_stepped": int(trainer.fit_loop.epoch_loop._batches_that_stepped),
            "best_score": self.best_score,
            "best_epoch": self.best_epoch,
            "partial_epoch": reason is not None,
            "stop_reason": reason,
            "seed": self.config.seed,
            "config_hash": self.config.config_hash(),
            "identity": self.config.resume_identity(),
            "config": self.config.to_dict(),
            "data": self.data_path,
            "train_time_s": self.train_time_s,
            "fast_dev_run": self.config.fast_dev_run,
            "grad_scaler": scaler.state_dict() if scaler is not None else None,
        }
        save_train_state(self.last_path, pl_module.model, trainer.optimizers[0], meta)
        self._append_history(trainer, epoch, epoch_time, reason is not None)

    def _append_history(self, trainer: L.Trainer, epoch: int, epoch_time: float, partial: bool) -> None:
        cm = trainer.callback_metrics
        row: dict[str, Any] = {c: "" for c in _HISTORY_COLUMNS}
        row.update(epoch=epoch, global_step=int(trainer.global_step), time_s=f"{epoch_time:.2f}")
        for key in ("train/loss", "train/source_loss", "train/wind_nll", "train/conc_nll"):
            v = cm.get(f"{key}_epoch", cm.get(key))
            if v is not None:
                row[key] = f"{float(v):.6g}"
        if self._val is not None and self._val[0] == epoch:
            for key, value in self._val[1].items():
                if key in row:
                    row[key] = f"{value:.6g}"
        row["best"] = int(self._best_this_epoch)
        row["partial"] = int(partial)
        new = not self.history_path.is_file()
        with self.history_path.open("a", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(_HISTORY_COLUMNS))
            if new:
                writer.writeheader()
            writer.writerow(row)


# -- the entry point ------------------------------------------------------------------------
@dataclass(frozen=True)
class TrainResult:
    """What a :func:`train` call did and wrote.

    Attributes:
        out_dir: the run's directory.
        last_path: ``last.safetensors`` (the training state to resume from).
        best_path: ``best.safetensors`` (None while no validation ran).
        export_path: the exported model (None unless ``config.export``).
        history_csv: ``history.csv`` (one row per epoch, all invocations).
        metrics_csv: Lightning's ``metrics.csv`` of this invocation (None if nothing was trained).
        epochs_done: epochs completed in total (the epoch a resume continues at).
        global_step: optimizer steps in total.
        best_score: the lowest ``val/source_loss`` (None without validation).
        best_epoch: its epoch (0-based).
        stop_reason: ``"max_epochs"``, ``"max_time"``, ``"interrupted"``,
            ``"fast_dev_run"`` or ``"already_done"`` (nothing left to train).
        wall_time_s: seconds this call took.
        samples_per_s: training samples per second of the epochs of this call (all devices,
            validation time included; 0 if none).
    """

    out_dir: Path
    last_path: Path
    best_path: Path | None
    export_path: Path | None
    history_csv: Path
    metrics_csv: Path | None
    epochs_done: int
    global_step: int
    best_score: float | None
    best_epoch: int | None
    stop_reason: str
    wall_time_s: float
    samples_per_s: float = 0.0


def export_model(out_dir: str | os.PathLike[str], dest: str | os.PathLike[str]) -> Path:
    """Write the selected model of a run to ``dest`` (a ``.safetensors`` model checkpoint).

    The model of ``best.safetensors`` (lowest ``val/source_loss``) with its
    training metadata plus ``exported_from``; a run without a ``best`` file
    (trained without validation) exports the weights of ``last.safetensors``
    with ``selection = "last"``.

    Raises:
        InputDataError: neither file exists or cannot be read.
    """
    out = Path(out_dir)
    best, last = out / BEST_NAME, out / LAST_NAME
    if best.is_file():
        model, info = load_checkpoint(best)
        training = {**info.training, "exported_from": str(best.resolve())}
    elif last.is_file():
        state = read_train_state(last)
        from dgse.models.networks import build_model

        model = build_model(state.model_config)
        _load_weights(state, model)
        training = {
            "epoch": state.next_epoch - 1,
            "global_step": state.global_step,
            "selection": "last",
            "config": state.meta.get("config"),
            "data": state.meta.get("data"),
            "exported_from": str(last.resolve()),
        }
    else:
        raise InputDataError(f"nothing to export: {out} holds neither {BEST_NAME} nor {LAST_NAME}")
    return save_model(model, dest, training=training)


def prepare_out_dir(config: TrainConfig, resume: bool) -> TrainState | None:
    """Check the run directory for a fresh or a resumed run; the state to resume from.

    A fresh run needs a directory without a run in it; the files of a fast dev
    run (``fast_dev_run = true`` in ``last.safetensors``) are removed instead.
    A resumed run needs a matching ``last.safetensors`` (:func:`read_train_state`)
    that is not a fast dev run's.

    Raises:
        InputDataError: see above.
    """
    out = Path(config.out_dir)
    last = out / LAST_NAME
    if resume:
        state = read_train_state(last, config)
        if state.meta.get("fast_dev_run") and not config.fast_dev_run:
            raise InputDataError(
                f"{last} is the state of a fast dev run; start a fresh run instead of resuming"
            )
        return state
    if last.exists() or (out / BEST_NAME).exists():
        try:
            prior = read_train_state(last) if last.exists() else None
        except InputDataError:
            prior = None
        if prior is None or not prior.meta.get("fast_dev_run"):
            raise InputDataError(
                f"{out} already holds a training run ({LAST_NAME}/{BEST_NAME}); resume it (--resume) "
                "or choose another output directory"
            )
    for name in (LAST_NAME, BEST_NAME, HISTORY_NAME):  # a fast dev run's files, or a stale history
        (out / name).unlink(missing_ok=True)
    return None


#: loggers of Lightning's informational messages (device banners, tips, limit notes)
_LIGHTNING_INFO_LOGGERS = ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero")


def _note(message: str) -> None:
    """A line of the run's own news on standard error, from the rank-0 process only."""
    if rank_zero_only.rank == 0:
        print(message, file=sys.stderr, flush=True)


@contextmanager
def quiet_lightning(quiet: bool = True) -> Iterator[None]:
    """While active (if ``quiet``), Lightning's informational messages are off; warnings stay."""
    loggers = [logging.getLogger(n) for n in _LIGHTNING_INFO_LOGGERS] if quiet else []
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.WARNING)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def train(
    config: TrainConfig,
    *,
    resume: bool = False,
    callbacks: Sequence[L.Callback] = (),
    trainer_kwargs: Mapping[str, Any] | None = None,
) -> TrainResult:
    """Train ``config``'s network on its dataset store (see the module docstring).

    Args:
        config: the run's configuration (``config.data`` must be set).
        resume: continue the run in ``config.out_dir`` from its ``last.safetensors``.
            Without it, a directory that already holds a run is an error.
        callbacks: extra Lightning callbacks.
        trainer_kwargs: extra ``lightning.Trainer`` arguments (override the derived ones).

    Returns:
        A :class:`TrainResult`.

    Raises:
        InputDataError: a bad configuration, a missing or unsuitable dataset store,
            a directory that already holds a run (without ``resume``), or a missing,
            corrupt or mismatched training state (with ``resume``).
    """
    t_start = time.monotonic()
    if config.data is None:
        raise InputDataError("no dataset store: set data in the config or pass --data")
    out = Path(config.out_dir)
    state = prepare_out_dir(config, resume)
    if config.threads is not None:
        torch.set_num_threads(config.threads)
    L.seed_everything(config.seed, workers=False, verbose=False)
    start_epoch = state.next_epoch if state is not None else 0

    dm = DGSEDataModule(
        config.data,
        batch_size=config.batch_size,
        configs_per_env=config.configs_per_env,
        val_configs_per_env=config.val_configs_per_env,
        num_workers=config.num_workers,
        seed=config.seed,
        augment=config.augment,
        start_epoch=start_epoch,
    )
    dm.load()
    cell_size = config.cell_size or dm.resolution or 0.1
    module = DGSELightningModule(
        config.model_config(),
        lr=config.lr,
        weight_decay=config.weight_decay,
        loss_weights=config.loss_weights,
        cell_size=cell_size,
        seed=config.seed,
    )
    if state is not None:
        _load_weights(state, module.model)
    elif config.init is not None:
        init_weights(module.model, config.init)

    stop = StopControl(config.max_time_s, t0=t_start)
    ckpt = TrainStateCheckpoint(out, config, state, stop, str(Path(config.data).resolve()))

    def result(reason: str, metrics_csv: Path | None) -> TrainResult:
        export_path = None
        if config.export is not None and (ckpt.best_path.is_file() or ckpt.last_path.is_file()):
            export_path = export_model(out, config.export)
        wall = time.monotonic() - t_start
        return TrainResult(
            out_dir=out,
            last_path=ckpt.last_path,
            best_path=ckpt.best_path if ckpt.best_path.is_file() else None,
            export_path=export_path,
            history_csv=ckpt.history_path,
            metrics_csv=metrics_csv,
            epochs_done=ckpt.epochs_done,
            global_step=ckpt.global_step,
            best_score=ckpt.best_score,
            best_epoch=ckpt.best_epoch,
            stop_reason=reason,
            wall_time_s=wall,
            samples_per_s=(ckpt.samples_seen / ckpt.call_train_time_s if ckpt.call_train_time_s > 0 else 0.0),
        )

    if start_epoch >= config.epochs and not config.fast_dev_run:
        return result("already_done", None)

    validate = config.val_configs_per_env > 0
    logger = CSVLogger(save_dir=str(out), name="logs")
    kwargs: dict[str, Any] = {
        "accelerator": config.accelerator,
        "devices": config.devices,
        "strategy": config.strategy,
        "num_nodes": config.num_nodes,
        "precision": config.precision,
        "max_epochs": start_epoch + 1 if config.fast_dev_run else config.epochs,
        "limit_train_batches": 2 if config.fast_dev_run else config.limit_train_batches,
        "limit_val_batches": (1 if config.fast_dev_run else config.limit_val_batches) if validate else 0,
        "num_sanity_val_steps": 0 if config.fast_dev_run or not validate else config.num_sanity_val_steps,
        "check_val_every_n_epoch": config.val_every_n_epochs,
        "log_every_n_steps": 1 if config.fast_dev_run else config.log_every_n_steps,
        "gradient_clip_val": config.gradient_clip_val,
        "enable_checkpointing": False,
        "enable_progress_bar": config.progress_bar,
        "enable_model_summary": config.progress_bar,
        "logger": logger,
        "callbacks": [EpochSetup(config.seed), ckpt, stop, *callbacks],
        "default_root_dir": str(out),
    }
    kwargs.update(trainer_kwargs or {})
    with quiet_lightning(not config.lightning_messages):
        try:
            trainer = L.Trainer(**kwargs)
        except (MisconfigurationException, ValueError, RuntimeError) as e:
            raise InputDataError(f"cannot set up training: {e}") from None
        if config.precision == "16-mixed" and trainer.strategy.root_device.type == "cpu":
            raise InputDataError("precision 16-mixed needs a GPU; use bf16-mixed on the CPU")
        if config.precision == "bf16-mixed" and not native_bf16(trainer.strategy.root_device):
            warnings.warn(
                f"precision bf16-mixed on {trainer.strategy.root_device}, which does not compute bf16 "
                "natively (a CPU without AVX-512 BF16 or AMX, or an older GPU): it is emulated and "
                "slower than precision 32",
                UserWarning,
                stacklevel=2,
            )
        if trainer.is_global_zero:
            out.mkdir(parents=True, exist_ok=True)
            logger.log_hyperparams(config.to_dict())
        main_thread = threading.current_thread() is threading.main_thread()
        sigint = signal.getsignal(signal.SIGINT) if main_thread else None
        try:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*does not have many workers.*")
                # Lightning's own use of a deprecated PyTorch pytree API: not ours to act on
                warnings.filterwarnings("ignore", message=".*LeafSpec.*is deprecated.*")
                trainer.fit(module, datamodule=dm)
        except SystemExit as e:
            # Lightning exits on a Ctrl-C it catches (the second, or one before training starts):
            # it is the caller's interrupt
            if stop.aborted or isinstance(e.__context__, KeyboardInterrupt):
                raise KeyboardInterrupt from None
            raise
        finally:
            stop.uninstall()
            if sigint is not None:  # Lightning leaves Ctrl-C ignored after it caught one
                signal.signal(signal.SIGINT, sigint)
    if config.fast_dev_run:
        reason = "fast_dev_run"
    elif stop.reason is not None:
        reason = stop.reason
    else:
        reason = "max_epochs"
    metrics_csv = Path(logger.log_dir) / "metrics.csv"
    return result(reason, metrics_csv if metrics_csv.is_file() else None)
