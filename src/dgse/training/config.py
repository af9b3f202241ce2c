"""Training configuration: :class:`TrainConfig`, loaded from YAML with overrides.

Defaults are the paper's (Sec. IV "Training and input configuration", Sec. V-A,
Appendix A): DGSE-S at the ``"paper"`` preset, Adam with learning rate
``5e-4`` and weight decay ``1e-4``, batch 300, 100 epochs, task weights
``lambda_w = lambda_c = 1``, ``lambda_s = 0.05``, 30 fresh sensor
configurations per training environment and epoch with the six symmetry
augmentations, 30 fixed configurations per validation environment, fp32.

A YAML file holds a mapping of the :class:`TrainConfig` field names (see its
docstring); ``model_overrides`` and ``loss_weights`` are nested mappings.
:func:`load_config` merges, in this order, the defaults, the file and the
overrides (``{"epochs": 3, "model_overrides.base_width": 4}``: dotted keys
reach into the nested mappings).  Every unknown key and every bad value raises
:class:`~dgse.errors.InputDataError` naming the key (and the file).

Relative paths (``data``, ``out_dir``, ``export``) are relative to the working
directory of the process, not to the YAML file.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from dataclasses import replace as _dc_replace
from pathlib import Path
from typing import Any

import yaml

from dgse.errors import InputDataError
from dgse.files import write_text
from dgse.models.config import PRESETS, VARIANTS, LossWeights, ModelConfig, preset_config
from dgse.options import check_switch

__all__ = [
    "PRECISIONS",
    "RESUME_KEYS",
    "TrainConfig",
    "load_config",
    "parse_duration",
]

#: Precisions :class:`TrainConfig` accepts (Lightning names).  ``"16-mixed"`` needs a GPU.
PRECISIONS: tuple[str, ...] = ("32", "bf16-mixed", "16-mixed")

#: Fields a resumed run must share with the run that wrote ``last.safetensors``
#: (besides the resolved model architecture); everything else (epochs, time
#: budget, devices, precision, workers, logging, paths) may change on resume.
RESUME_KEYS: tuple[str, ...] = (
    "batch_size",
    "lr",
    "weight_decay",
    "loss_weights",
    "configs_per_env",
    "augment",
    "seed",
)

_DURATION = re.compile(r"^(?:(\d+):)?(\d+):(\d{1,2}):(\d{1,2})$")


def parse_duration(value: str | int | float | None, key: str = "max_time") -> float | None:
    """Seconds of a duration ``"HH:MM:SS"``, ``"DD:HH:MM:SS"`` or a number of seconds.

    Returns None for None.  Raises :class:`InputDataError` (naming ``key``) otherwise.

    Example:
        >>> parse_duration("01:30:00")
        5400.0
    """
    if value is None:
        return None
    if isinstance(value, bool):
        raise InputDataError(f"{key} must be a duration HH:MM:SS or seconds, got {value!r}")
    if isinstance(value, int | float):
        seconds = float(value)
    else:
        text = str(value).strip()
        m = _DURATION.match(text)
        if m:
            d, h, mi, s = (int(g) if g else 0 for g in m.groups())
            if mi >= 60 or s >= 60:
                raise InputDataError(f"{key}: minutes and seconds must be < 60 in {text!r}")
            seconds = float(((d * 24 + h) * 60 + mi) * 60 + s)
        else:
            try:
                seconds = float(text)
            except ValueError:
                raise InputDataError(
                    f"{key} must be a duration HH:MM:SS, DD:HH:MM:SS or seconds, got {text!r}"
                ) from None
    if not (math.isfinite(seconds) and seconds > 0):
        raise InputDataError(f"{key} must be a positive duration, got {value!r}")
    return seconds


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _as_float(key: str, v: Any) -> float:
    """A float from a number or a numeric string (YAML 1.1 reads ``1e-4`` as a string)."""
    if isinstance(v, bool):
        raise InputDataError(f"{key} must be a number, got {v!r}")
    if isinstance(v, int | float):
        return float(v)
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            pass
    raise InputDataError(f"{key} must be a number, got {v!r}")


def _check_int(key: str, v: Any, lo: int) -> int:
    if not _is_int(v) or v < lo:
        raise InputDataError(f"{key} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _check_str(key: str, v: Any, optional: bool = False) -> str | None:
    if v is None and optional:
        return None
    if not isinstance(v, str) or not v:
        raise InputDataError(f"{key} must be a non-empty string, got {v!r}")
    return v


def _check_limit(key: str, v: Any) -> int | float | None:
    """Lightning's ``limit_*_batches``: None (all), an int number of batches, or a fraction in [0, 1]."""
    if v is None:
        return None
    if _is_int(v) and v >= 0:
        return int(v)
    if isinstance(v, float) and 0.0 <= v <= 1.0:
        return v
    raise InputDataError(f"{key} must be null, a number of batches >= 0 or a fraction in [0, 1], got {v!r}")


def _check_devices(v: Any) -> int | str | list[int]:
    if isinstance(v, str) and v:
        return v
    if _is_int(v) and (v >= 1 or v == -1):
        return int(v)
    if isinstance(v, list | tuple) and v and all(_is_int(d) and d >= 0 for d in v):
        return [int(d) for d in v]
    raise InputDataError(f"devices must be 'auto', a count >= 1, -1 (all) or a list of indices, got {v!r}")


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs (see the module docstring for loading).

    Attributes:
        model: network variant, ``"dgse-o"``, ``"dgse-p"`` or ``"dgse-s"``.
        preset: architecture preset, ``"paper"`` or ``"small"`` (:func:`preset_config`).
        model_overrides: :class:`~dgse.models.networks.ModelConfig` fields replacing
            the preset's (e.g. ``{"base_width": 4, "depth": 2}``).
        data: path of the dataset store (``.h5``) with ``train`` and ``val`` splits.
        out_dir: directory for checkpoints and logs (see :func:`dgse.training.train.train`).
        export: if set, the selected model is also written to this ``.safetensors`` path.
        init: a fresh run starts from these weights instead of a random initialization
            (fine-tuning): a ``.safetensors`` model file of the same architecture, or
            ``"default"`` for the shipped weights of ``model``.  A resumed run continues
            from its own weights and ignores it.
        epochs: number of epochs to train (in total, counting resumed ones).
        batch_size: samples per optimizer step and device.
        lr, weight_decay: Adam parameters.
        loss_weights: task weights ``lambda_w, lambda_c, lambda_s`` (keys ``wind``, ``conc``, ``source``).
        configs_per_env: fresh sensor configurations per training environment and epoch.
        val_configs_per_env: the first this many fixed configurations of every
            validation environment are validated (0: no validation, no ``best``).
        augment: random symmetry transform of every training sample.
        seed: seed of the data draws, the shuffling, the network initialization and
            the DGSE-S reparameterization noise.
        max_time: wall-clock budget of this invocation (``"HH:MM:SS"``,
            ``"DD:HH:MM:SS"`` or seconds); training stops cleanly after the batch
            that exceeds it (see :mod:`dgse.training.train`).  None: no limit.
        precision: ``"32"``, ``"bf16-mixed"`` (CPU or GPU) or ``"16-mixed"`` (GPU).
        accelerator, devices, strategy, num_nodes: passed to ``lightning.Trainer``
            (``"auto"``, ``"cpu"``, ``"gpu"``; a device count, -1 or a list of
            indices; ``"auto"``, ``"ddp"``, ...; nodes of a multi-node DDP run).
        num_workers: DataLoader worker processes per device (0: load in the main process).
        threads: ``torch.set_num_threads`` for the training process (None: PyTorch's default).
        val_every_n_epochs: validate after every this many epochs.
        limit_train_batches, limit_val_batches: Lightning's limits for development
            runs (None: all batches; an int: that many batches; a float: that fraction).
        num_sanity_val_steps: validation batches run before training, to fail early.
        log_every_n_steps: step-level logging interval.
        gradient_clip_val: clip the gradient norm to this (None: no clipping, the paper's).
        progress_bar: show a progress bar.
        lightning_messages: show Lightning's informational messages (device
            banners, tips, limit notes); off by default.
        fast_dev_run: one epoch of 2 training and 1 validation batch that still
            writes logs and checkpoints (unlike Lightning's own ``fast_dev_run``).
        cell_size: cell side in m for the localization error (None: the data's resolution).
    """

    model: str = "dgse-s"
    preset: str = "paper"
    model_overrides: Mapping[str, Any] = field(default_factory=dict)
    data: str | None = None
    out_dir: str = "runs/dgse"
    export: str | None = None
    init: str | None = None
    epochs: int = 100
    batch_size: int = 300
    lr: float = 5e-4
    weight_decay: float = 1e-4
    loss_weights: LossWeights = field(default_factory=LossWeights)
    configs_per_env: int = 30
    val_configs_per_env: int = 30
    augment: bool = True
    seed: int = 0
    max_time: str | float | None = None
    precision: str = "32"
    accelerator: str = "auto"
    devices: int | str | list[int] = "auto"
    strategy: str = "auto"
    num_nodes: int = 1
    num_workers: int = 0
    threads: int | None = None
    val_every_n_epochs: int = 1
    limit_train_batches: int | float | None = None
    limit_val_batches: int | float | None = None
    num_sanity_val_steps: int = 2
    log_every_n_steps: int = 50
    gradient_clip_val: float | None = None
    progress_bar: bool = True
    lightning_messages: bool = False
    fast_dev_run: bool = False
    cell_size: float | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.model not in VARIANTS:
            raise InputDataError(f"model must be one of {', '.join(VARIANTS)}, got {self.model!r}")
        if self.preset not in PRESETS:
            raise InputDataError(f"preset must be one of {', '.join(PRESETS)}, got {self.preset!r}")
        if not isinstance(self.model_overrides, Mapping):
            raise InputDataError(f"model_overrides must be a mapping, got {self.model_overrides!r}")
        set_(self, "model_overrides", dict(self.model_overrides))
        self.model_config()  # validates the overrides
        _check_str("data", self.data, optional=True)
        _check_str("out_dir", self.out_dir)
        _check_str("export", self.export, optional=True)
        _check_str("init", self.init, optional=True)
        for key, lo in (
            ("epochs", 1),
            ("batch_size", 1),
            ("configs_per_env", 1),
            ("val_configs_per_env", 0),
            ("seed", 0),
            ("num_nodes", 1),
            ("num_workers", 0),
            ("val_every_n_epochs", 1),
            ("log_every_n_steps", 1),
        ):
            _check_int(key, getattr(self, key), lo)
        if not (_is_int(self.num_sanity_val_steps) and self.num_sanity_val_steps >= -1):
            raise InputDataError(
                f"num_sanity_val_steps must be an integer >= -1, got {self.num_sanity_val_steps!r}"
            )
        if self.threads is not None:
            _check_int("threads", self.threads, 1)
        lr = _as_float("lr", self.lr)
        if not (math.isfinite(lr) and lr > 0):
            raise InputDataError(f"lr must be a positive number, got {self.lr!r}")
        set_(self, "lr", lr)
        wd = _as_float("weight_decay", self.weight_decay)
        if not (math.isfinite(wd) and wd >= 0):
            raise InputDataError(f"weight_decay must be a number >= 0, got {self.weight_decay!r}")
        set_(self, "weight_decay", wd)
        for key in ("gradient_clip_val", "cell_size"):
            v = getattr(self, key)
            if v is not None:
                f = _as_float(key, v)
                if not (math.isfinite(f) and f > 0):
                    raise InputDataError(f"{key} must be a positive number or null, got {v!r}")
                set_(self, key, f)
        if isinstance(self.loss_weights, Mapping):
            set_(self, "loss_weights", _loss_weights(self.loss_weights))
        elif not isinstance(self.loss_weights, LossWeights):
            raise InputDataError(f"loss_weights must be a mapping, got {self.loss_weights!r}")
        for key in ("augment", "progress_bar", "lightning_messages", "fast_dev_run"):
            check_switch(key, getattr(self, key))
        parse_duration(self.max_time)
        if self.precision not in PRECISIONS:
            # YAML reads `precision: 32` as an int
            if str(self.precision) in PRECISIONS:
                set_(self, "precision", str(self.precision))
            else:
                raise InputDataError(
                    f"precision must be one of {', '.join(PRECISIONS)}, got {self.precision!r}"
                )
        _check_str("accelerator", self.accelerator)
        _check_str("strategy", self.strategy)
        set_(self, "devices", _check_devices(self.devices))
        set_(self, "limit_train_batches", _check_limit("limit_train_batches", self.limit_train_batches))
        set_(self, "limit_val_batches", _check_limit("limit_val_batches", self.limit_val_batches))

    # -- derived --------------------------------------------------------------------------
    def model_config(self) -> ModelConfig:
        """The network architecture: the preset with :attr:`model_overrides` applied."""
        fixed = sorted({"variant", "preset"} & set(self.model_overrides))
        if fixed:
            raise InputDataError(
                f"model_overrides cannot set {', '.join(fixed)}: use the model and preset keys"
            )
        try:
            return preset_config(self.preset, self.model, **self.model_overrides)  # type: ignore[arg-type]
        except TypeError:
            known = {f.name for f in fields(ModelConfig)} - {"variant", "preset"}
            unknown = sorted(set(self.model_overrides) - known)
            raise InputDataError(
                f"unknown model_overrides key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}"
            ) from None
        except InputDataError as e:
            raise InputDataError(f"model_overrides: {e}") from None

    @property
    def max_time_s(self) -> float | None:
        """:attr:`max_time` in seconds (None: no limit)."""
        return parse_duration(self.max_time)

    def to_dict(self) -> dict[str, Any]:
        """A plain, JSON- and YAML-serializable dict (inverse of :meth:`from_dict`)."""
        d = asdict(self)
        d["loss_weights"] = asdict(self.loss_weights)
        d["model_overrides"] = dict(self.model_overrides)
        return d

    def resume_identity(self) -> dict[str, Any]:
        """What a resumed run must share with the run it resumes (:data:`RESUME_KEYS` + architecture)."""
        d = self.to_dict()
        out = {k: d[k] for k in RESUME_KEYS}
        out["model_config"] = {k: v for k, v in self.model_config().to_dict().items() if k != "preset"}
        return out

    def config_hash(self) -> str:
        """SHA-256 (hex, 16 digits) of :meth:`resume_identity`."""
        blob = json.dumps(self.resume_identity(), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str | None = None) -> TrainConfig:
        """A config from a mapping of field names; unknown keys raise :class:`InputDataError`.

        ``source`` (e.g. the YAML file name) is named in error messages.
        """
        where = f" in {source}" if source else ""
        if not isinstance(data, Mapping):
            raise InputDataError(f"a training config must be a mapping{where}, got {type(data).__name__}")
        known = [f.name for f in fields(cls)]
        unknown = sorted(str(k) for k in data if k not in known)
        if unknown:
            raise InputDataError(
                f"unknown training config key(s) {', '.join(unknown)}{where}; known: {', '.join(known)}"
            )
        try:
            return cls(**dict(data))
        except InputDataError as e:
            raise InputDataError(f"{e}{where}") from None

    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with some fields changed (validated again)."""
        return _dc_replace(self, **changes)

    def save_yaml(self, path: str | os.PathLike[str]) -> Path:
        """Write the config as YAML (loadable with :func:`load_config`)."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        return write_text(p, yaml.safe_dump(self.to_dict(), sort_keys=False))


def _loss_weights(m: Mapping[str, Any]) -> LossWeights:
    known = [f.name for f in fields(LossWeights)]
    unknown = sorted(str(k) for k in m if k not in known)
    if unknown:
        raise InputDataError(f"unknown loss_weights key(s) {', '.join(unknown)}; known: {', '.join(known)}")
    values = {k: _as_float(f"loss_weights.{k}", v) for k, v in m.items()}
    return LossWeights(**{**asdict(LossWeights()), **values})


def _read_yaml(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise InputDataError(f"training config {path} not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise InputDataError(f"training config {path} is not valid YAML: {e}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputDataError(f"training config {path} must hold a mapping of keys, got {type(data).__name__}")
    return data


def _apply_override(data: dict[str, Any], key: str, value: Any) -> None:
    head, dot, rest = key.partition(".")
    if not dot:
        data[key] = value
        return
    if head not in ("model_overrides", "loss_weights") or not rest or "." in rest:
        raise InputDataError(
            f"unknown training config key {key!r}: only model_overrides.<key> and "
            "loss_weights.<key> are nested"
        )
    nested = data.get(head)
    if isinstance(nested, LossWeights):
        nested = asdict(nested)
    nested = dict(nested or {})
    nested[rest] = value
    data[head] = nested


def load_config(
    path: str | os.PathLike[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    *,
    origins: Mapping[str, str] | None = None,
) -> TrainConfig:
    """The defaults, updated by the YAML file ``path`` (if given), then by ``overrides``.

    ``overrides`` maps field names (or ``model_overrides.<key>`` /
    ``loss_weights.<key>``) to values; a value of None in ``overrides`` is
    applied too (use it to clear ``max_time`` or ``export``).  The file is
    checked first, then each override in turn, so an error names what caused
    it: the file, or the override as ``origins`` says it was given (e.g.
    ``{"batch_size": "--batch-size 0"}``; default ``override 'batch_size'``).
    The network's architecture (preset plus ``model_overrides``) is checked too.

    Raises:
        InputDataError: a missing or malformed file, an unknown key, a bad value.
    """
    source = str(path) if path is not None else None
    data: dict[str, Any] = _read_yaml(Path(path)) if path is not None else {}
    if "model_overrides" in data and data["model_overrides"] is None:
        data["model_overrides"] = {}
    config = _checked(data, source)
    for key, value in (overrides or {}).items():
        origin = (origins or {}).get(key, f"override {key!r}")
        try:
            _apply_override(data, key, value)
            config = _checked(data, None)
        except InputDataError as e:
            raise InputDataError(f"{origin}: {e}") from None
    return config


def _checked(data: Mapping[str, Any], source: str | None) -> TrainConfig:
    """The config of ``data``, its network's architecture checked too."""
    config = TrainConfig.from_dict(data, source)
    try:
        config.model_config()
    except InputDataError as e:
        raise InputDataError(f"{e} in {source}" if source else str(e)) from None
    return config
