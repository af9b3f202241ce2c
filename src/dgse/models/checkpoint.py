"""Model checkpoints: weights in a safetensors file, the config in its metadata.

One file ``<name>.safetensors`` holds the network's ``state_dict`` (float
tensors, CPU, contiguous) and these string metadata entries (safetensors
metadata is a ``str -> str`` map):

=================  ==========================================================
key                value
=================  ==========================================================
``format``         ``"dgse-checkpoint"``
``format_version`` ``"1"``
``variant``        ``"dgse-o"``, ``"dgse-p"`` or ``"dgse-s"``
``config``         JSON of :meth:`dgse.models.networks.ModelConfig.to_dict`
``training``       JSON object of free-form training metadata (epochs, data, losses, ...)
``dgse_version``   version of the package that wrote the file
``torch_version``  version of PyTorch that wrote the file
=================  ==========================================================

Nothing is ever unpickled.  Every problem with a file (missing, not
safetensors, truncated, not a DGSE checkpoint, another variant than asked
for, tensors missing or of the wrong shape, non-finite weights) raises
:class:`CheckpointError` (an :class:`dgse.errors.InputDataError`) with a
message naming the file.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path
from typing import Any

import torch
from safetensors import safe_open
from safetensors.torch import save_file

from dgse.errors import InputDataError
from dgse.files import atomic_path
from dgse.models.networks import VARIANTS, DGSEModel, ModelConfig, build_model

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "CheckpointError",
    "CheckpointInfo",
    "load_checkpoint",
    "load_model",
    "read_checkpoint_info",
    "save_model",
]

FORMAT = "dgse-checkpoint"
FORMAT_VERSION = 1


class CheckpointError(InputDataError):
    """A model checkpoint that is missing, unreadable or does not fit the requested model."""


@dataclass(frozen=True)
class CheckpointInfo:
    """What a checkpoint's metadata says.

    Attributes:
        path: the file.
        variant: network variant.
        config: the architecture.
        training: free-form training metadata (JSON object).
        format_version: checkpoint format version.
        dgse_version, torch_version: versions that wrote the file ("" if unknown).
    """

    path: Path
    variant: str
    config: ModelConfig
    training: dict[str, Any] = field(default_factory=dict)
    format_version: int = FORMAT_VERSION
    dgse_version: str = ""
    torch_version: str = ""


def _dgse_version() -> str:
    try:
        return _pkg_version("dgse")
    except PackageNotFoundError:
        return ""


def save_model(
    model: DGSEModel, path: str | os.PathLike[str], training: dict[str, Any] | None = None
) -> Path:
    """Write ``model``'s weights and config to ``path`` (a ``.safetensors`` file), atomically.

    Args:
        model: a DGSE network.
        path: destination; parent directories are created.
        training: JSON-serializable training metadata stored with the weights.

    Returns:
        The path written.
    """
    if not isinstance(model, DGSEModel):
        raise CheckpointError(f"can only save DGSE networks, got {type(model).__name__}")
    path = Path(path)
    try:
        training_json = json.dumps(training or {}, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise CheckpointError(f"training metadata is not JSON-serializable: {e}") from e
    tensors = {k: v.detach().to("cpu").contiguous() for k, v in model.state_dict().items()}
    meta = {
        "format": FORMAT,
        "format_version": str(FORMAT_VERSION),
        "variant": model.config.variant,
        "config": json.dumps(model.config.to_dict(), sort_keys=True),
        "training": training_json,
        "dgse_version": _dgse_version(),
        "torch_version": torch.__version__,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata=meta)
    return path


def _open_metadata(path: Path) -> dict[str, str]:
    if not path.exists():
        raise CheckpointError(f"checkpoint {path} not found")
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} is not a file")
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata()
    except Exception as e:  # safetensors raises its own error types for corrupt headers
        raise CheckpointError(f"checkpoint {path} is not a readable safetensors file: {e}") from e
    return dict(meta or {})


def _parse_info(path: Path, meta: dict[str, str]) -> CheckpointInfo:
    if meta.get("format") != FORMAT:
        raise CheckpointError(
            f"{path} is a safetensors file but not a DGSE checkpoint (no {FORMAT!r} metadata)"
        )
    try:
        version = int(meta.get("format_version", ""))
    except ValueError as e:
        raise CheckpointError(f"checkpoint {path}: bad format_version {meta.get('format_version')!r}") from e
    if version > FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {path} has format version {version}; this dgse reads up to {FORMAT_VERSION} "
            "(upgrade dgse)"
        )
    try:
        config = ModelConfig.from_dict(json.loads(meta.get("config", "")))
        training = json.loads(meta.get("training", "{}"))
    except (json.JSONDecodeError, InputDataError, TypeError) as e:
        raise CheckpointError(f"checkpoint {path}: invalid model config: {e}") from e
    variant = meta.get("variant", "")
    if variant not in VARIANTS or variant != config.variant:
        raise CheckpointError(f"checkpoint {path}: variant {variant!r} does not match its config")
    return CheckpointInfo(
        path=path,
        variant=variant,
        config=config,
        training=training if isinstance(training, dict) else {"value": training},
        format_version=version,
        dgse_version=meta.get("dgse_version", ""),
        torch_version=meta.get("torch_version", ""),
    )


def read_checkpoint_info(path: str | os.PathLike[str]) -> CheckpointInfo:
    """The metadata of a checkpoint, without loading its weights."""
    p = Path(path)
    return _parse_info(p, _open_metadata(p))


def load_checkpoint(
    path: str | os.PathLike[str], variant: str | None = None, device: torch.device | str = "cpu"
) -> tuple[DGSEModel, CheckpointInfo]:
    """The network stored in ``path`` (in ``eval()`` mode) and its metadata.

    Args:
        path: a file written by :func:`save_model`.
        variant: if given, the checkpoint must hold this variant.
        device: where to put the weights.

    Raises:
        CheckpointError: see the module docstring.
    """
    p = Path(path)
    info = read_checkpoint_info(p)
    if variant is not None and info.variant != variant:
        raise CheckpointError(f"checkpoint {p} holds a {info.variant!r} model, expected {variant!r}")
    try:
        with safe_open(str(p), framework="pt", device="cpu") as f:
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except Exception as e:
        raise CheckpointError(f"checkpoint {p}: cannot read its tensors (truncated or corrupt?): {e}") from e
    model = build_model(info.config)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(tensors))
    unexpected = sorted(set(tensors) - set(expected))
    if missing or unexpected:
        raise CheckpointError(
            f"checkpoint {p} does not fit a {info.variant} model with its config: "
            f"missing {missing[:5]}{' ...' if len(missing) > 5 else ''}, "
            f"unexpected {unexpected[:5]}{' ...' if len(unexpected) > 5 else ''}"
        )
    wrong = [
        f"{k}: {tuple(tensors[k].shape)} instead of {tuple(v.shape)}"
        for k, v in expected.items()
        if tuple(tensors[k].shape) != tuple(v.shape)
    ]
    if wrong:
        raise CheckpointError(f"checkpoint {p} has tensors of the wrong shape: {'; '.join(wrong[:5])}")
    bad = [k for k, t in tensors.items() if t.is_floating_point() and not bool(torch.isfinite(t).all())]
    if bad:
        raise CheckpointError(f"checkpoint {p} has non-finite weights in {bad[:5]}")
    state = {k: tensors[k].to(expected[k].dtype) for k in expected}
    model.load_state_dict(state, strict=True)
    model.to(device)
    model.eval()
    return model, info


def load_model(
    path: str | os.PathLike[str], variant: str | None = None, device: torch.device | str = "cpu"
) -> DGSEModel:
    """The network stored in ``path``, in ``eval()`` mode (see :func:`load_checkpoint`)."""
    return load_checkpoint(path, variant, device)[0]
