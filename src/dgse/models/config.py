"""The architecture settings of the DGSE networks and their training loss weights, without PyTorch.

:class:`ModelConfig` and the named presets (:func:`preset_config`) describe a
network; :class:`LossWeights` the task weights of its training loss.  They are
here, apart from the networks (:mod:`dgse.models.networks`), so that a training
configuration (:mod:`dgse.training.config`) is checked before PyTorch is
imported.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, Literal, get_args

from dgse.errors import InputDataError

__all__ = [
    "PRESETS",
    "VARIANTS",
    "Activation",
    "LossWeights",
    "ModelConfig",
    "Norm",
    "UNetArch",
    "Variant",
    "preset_config",
]

Norm = Literal["group", "batch", "none"]
Activation = Literal["relu", "silu", "gelu", "leaky_relu"]
Variant = Literal["dgse-o", "dgse-p", "dgse-s"]
VARIANTS: tuple[str, ...] = get_args(Variant)

#: Base widths of the named presets (all depth 3); see the module docstring for the counts.
PRESETS: dict[str, dict[str, int]] = {
    "paper": {"dgse-o": 21, "dgse-p": 21, "dgse-s": 17},
    "small": {"dgse-o": 10, "dgse-p": 10, "dgse-s": 8},
}


@dataclass(frozen=True)
class UNetArch:
    """Architecture of one U-Net or of one of its halves (:mod:`dgse.models.unet`).

    Attributes:
        base_width: channels of the first level; level ``l`` has ``base_width * 2**l``.
        depth: number of 2x down-samplings (the bottleneck is at ``H / 2**depth``).
        norm: ``"group"``, ``"batch"`` or ``"none"``.
        activation: ``"relu"``, ``"silu"``, ``"gelu"`` or ``"leaky_relu"``.
        norm_groups: maximum number of GroupNorm groups.
    """

    base_width: int = 16
    depth: int = 4
    norm: Norm = "group"
    activation: Activation = "relu"
    norm_groups: int = 8

    def __post_init__(self) -> None:
        if self.base_width < 1:
            raise InputDataError(f"U-Net base width must be >= 1, got {self.base_width}")
        if self.depth < 1:
            raise InputDataError(f"U-Net depth must be >= 1, got {self.depth}")


@dataclass(frozen=True)
class ModelConfig(UNetArch):
    """Architecture of one DGSE network: the :class:`UNetArch` of every U-Net in it, and more.

    Attributes:
        variant: ``"dgse-o"``, ``"dgse-p"`` or ``"dgse-s"``.
        base_width: channels of the first U-Net level (each sub-network of DGSE-S
            has this width).
        depth: number of 2x down-samplings of every U-Net.
        norm, activation, norm_groups: as :class:`UNetArch`.
        logvar_min, logvar_max: range of the predicted log-variances (soft clamp).
        preset: name of the preset this config came from (bookkeeping only).
    """

    base_width: int = 17
    depth: int = 3
    variant: Variant = "dgse-s"
    logvar_min: float = -12.0
    logvar_max: float = 6.0
    preset: str | None = None

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise InputDataError(f"unknown DGSE variant {self.variant!r}; known: {', '.join(VARIANTS)}")
        if not (isinstance(self.base_width, int) and self.base_width >= 1):
            raise InputDataError(f"base_width must be a positive int, got {self.base_width!r}")
        if not (isinstance(self.depth, int) and 1 <= self.depth <= 8):
            raise InputDataError(f"depth must be an int in 1..8, got {self.depth!r}")
        if self.norm not in get_args(Norm):
            raise InputDataError(f"unknown norm {self.norm!r}; known: {', '.join(get_args(Norm))}")
        if self.activation not in get_args(Activation):
            raise InputDataError(
                f"unknown activation {self.activation!r}; known: {', '.join(get_args(Activation))}"
            )
        if not (isinstance(self.norm_groups, int) and self.norm_groups >= 1):
            raise InputDataError(f"norm_groups must be a positive int, got {self.norm_groups!r}")
        lo, hi = float(self.logvar_min), float(self.logvar_max)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise InputDataError(f"need finite logvar_min < logvar_max, got {lo}, {hi}")

    @property
    def stride(self) -> int:
        """Total down-sampling factor ``2**depth`` (inputs are padded to a multiple of it)."""
        return 2**self.depth

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable dict (inverse of :meth:`from_dict`)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelConfig:
        """A config from :meth:`to_dict` output; unknown keys raise :class:`InputDataError`."""
        if not isinstance(data, dict):
            raise InputDataError(f"model config must be a dict, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputDataError(f"unknown model config keys: {', '.join(unknown)}")
        return cls(**data)


def preset_config(preset: str, variant: Variant, **overrides: Any) -> ModelConfig:
    """The config of a named preset (``"paper"`` or ``"small"``) for ``variant``.

    ``overrides`` replace config fields (the result's ``preset`` is then None).

    Example:
        >>> preset_config("small", "dgse-s").base_width
        8
    """
    if preset not in PRESETS:
        raise InputDataError(f"unknown preset {preset!r}; known: {', '.join(PRESETS)}")
    if variant not in VARIANTS:
        raise InputDataError(f"unknown DGSE variant {variant!r}; known: {', '.join(VARIANTS)}")
    cfg = ModelConfig(variant=variant, base_width=PRESETS[preset][variant], depth=3, preset=preset)
    if not overrides:
        return cfg
    # a modified preset is no longer that preset (unless the caller names it)
    return replace(cfg, **{"preset": None, **overrides})


@dataclass(frozen=True)
class LossWeights:
    """Task weights ``lambda_w``, ``lambda_c``, ``lambda_s`` (paper defaults 1, 1, 0.05)."""

    wind: float = 1.0
    conc: float = 1.0
    source: float = 0.05

    def __post_init__(self) -> None:
        for name in ("wind", "conc", "source"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputDataError(f"loss weight {name} must be finite and >= 0, got {v}")
