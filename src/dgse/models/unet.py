"""A configurable, fully convolutional U-Net and its parts (encoder, decoder).

Layout (``b = base_width``, ``d = depth``)::

    level 0      DoubleConv(in_ch -> b)                      ──skip0──┐
    level 1      MaxPool2 + DoubleConv(b -> 2b)               ──skip1─┐│
    ...                                                               ││
    bottleneck   MaxPool2 + DoubleConv(2^(d-1) b -> 2^d b)            ││
    up d-1..0    ConvTranspose2x2(2^(l+1) b -> 2^l b), concat skip_l, ││
                 DoubleConv(2^(l+1) b -> 2^l b)               <───────┘┘
    head         Conv1x1(b -> out_ch)

``DoubleConv`` is ``(Conv3x3 -> norm -> activation) x 2``; the convolutions
have no bias when a normalization follows.  The network is fully
convolutional: any input ``H x W`` works, it is padded internally (at the
high-index end of both axes, i.e. beyond the map, which sits at the canvas'
lower-left corner) to a multiple of ``2**depth`` with a per-channel fill value
and the output is cropped back to ``H x W``.

Normalization: ``"group"`` (GroupNorm, default: batch-size independent, so a
single-sample inference behaves like training), ``"batch"`` (BatchNorm) or
``"none"``.  GroupNorm uses the largest number of groups ``<= norm_groups``
that divides the channel count (e.g. 7 groups for 21 channels).

:class:`UNetEncoder` and :class:`UNetDecoder` are the two halves, used on
their own by DGSE-P (one shared encoder, three task decoders).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F
from torch import nn

from dgse.errors import InputDataError
from dgse.models.config import Activation, Norm, UNetArch

__all__ = [
    "Activation",
    "DoubleConv",
    "Norm",
    "UNet",
    "UNetArch",
    "UNetDecoder",
    "UNetEncoder",
    "crop_to",
    "make_activation",
    "make_norm",
    "pad_to_multiple",
]


#: The defaults of :class:`UNetArch`, the architecture of a U-Net given none.
_DEFAULT_ARCH = UNetArch()


def make_norm(kind: Norm, channels: int, groups: int = 8) -> nn.Module:
    """A normalization layer for ``channels`` feature maps."""
    if kind == "group":
        g = max(k for k in range(1, max(1, min(groups, channels)) + 1) if channels % k == 0)
        return nn.GroupNorm(g, channels)
    if kind == "batch":
        return nn.BatchNorm2d(channels)
    if kind == "none":
        return nn.Identity()
    raise InputDataError(f"unknown normalization {kind!r}; use 'group', 'batch' or 'none'")


def make_activation(kind: Activation) -> nn.Module:
    """An activation module by name."""
    if kind == "relu":
        return nn.ReLU(inplace=True)
    if kind == "silu":
        return nn.SiLU(inplace=True)
    if kind == "gelu":
        return nn.GELU()
    if kind == "leaky_relu":
        return nn.LeakyReLU(0.01, inplace=True)
    raise InputDataError(f"unknown activation {kind!r}; use 'relu', 'silu', 'gelu' or 'leaky_relu'")


class DoubleConv(nn.Sequential):
    """``(Conv3x3 -> norm -> activation) x 2``: ``(B, in_ch, H, W) -> (B, out_ch, H, W)``."""

    def __init__(
        self, in_ch: int, out_ch: int, norm: Norm = "group", activation: Activation = "relu", groups: int = 8
    ) -> None:
        bias = norm == "none"
        super().__init__(
            nn.Conv2d(in_ch, out_ch, 3, padding=1, bias=bias),
            make_norm(norm, out_ch, groups),
            make_activation(activation),
            nn.Conv2d(out_ch, out_ch, 3, padding=1, bias=bias),
            make_norm(norm, out_ch, groups),
            make_activation(activation),
        )


class _UNetHalf(nn.Module):
    """What both halves of a U-Net share: the checked architecture and the channels per level.

    ``channels`` are the encoder's input or the decoder's output channels; level ``l``
    has ``arch.base_width * 2**l`` channels (``l = 0..depth``); ``_build`` adds the layers.
    """

    def __init__(self, channels: int, arch: UNetArch = _DEFAULT_ARCH) -> None:
        super().__init__()
        self.arch = arch
        self.base_width = arch.base_width
        self.depth = arch.depth
        widths = [arch.base_width * 2**level for level in range(arch.depth + 1)]
        norm, act, groups = arch.norm, arch.activation, arch.norm_groups
        self._build(channels, widths, lambda a, b: DoubleConv(a, b, norm, act, groups))

    def _build(self, channels: int, widths: list[int], conv: Callable[[int, int], DoubleConv]) -> None:
        raise NotImplementedError


class UNetEncoder(_UNetHalf):
    """The contracting half: ``(B, in_ch, H, W) -> (bottleneck, skips)``.

    ``H`` and ``W`` must be multiples of ``2**depth`` (see :func:`pad_to_multiple`).
    ``skips[l]`` has ``base_width * 2**l`` channels at resolution ``H / 2**l``
    (``l = 0..depth-1``); the bottleneck has ``base_width * 2**depth`` channels
    at ``H / 2**depth``.  Arguments: ``channels`` (``in_ch``) and ``arch``, as :class:`UNet`.
    """

    def _build(self, channels: int, widths: list[int], conv: Callable[[int, int], DoubleConv]) -> None:
        self.in_ch = channels
        self.blocks = nn.ModuleList([conv(channels, widths[0])])
        for level in range(1, self.depth + 1):
            self.blocks.append(conv(widths[level - 1], widths[level]))
        self.out_channels = widths[-1]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        skips: list[torch.Tensor] = []
        h = x
        for level, block in enumerate(self.blocks):
            if level > 0:
                h = F.max_pool2d(h, 2)
            h = block(h)
            if level < self.depth:
                skips.append(h)
        return h, skips


class UNetDecoder(_UNetHalf):
    """The expanding half: ``(bottleneck, skips) -> (B, out_ch, H, W)``.

    Matches a :class:`UNetEncoder` of the same ``base_width`` and ``depth``.  Arguments:
    ``channels`` (``out_ch``) and ``arch``, as :class:`UNet`.
    """

    def _build(self, channels: int, widths: list[int], conv: Callable[[int, int], DoubleConv]) -> None:
        self.ups = nn.ModuleList()
        self.blocks = nn.ModuleList()
        for level in reversed(range(self.depth)):
            self.ups.append(nn.ConvTranspose2d(widths[level + 1], widths[level], 2, stride=2))
            self.blocks.append(conv(2 * widths[level], widths[level]))
        self.head = nn.Conv2d(widths[0], channels, 1)
        self.out_ch = channels

    def forward(self, bottleneck: torch.Tensor, skips: Sequence[torch.Tensor]) -> torch.Tensor:
        h = bottleneck
        for up, block, skip in zip(self.ups, self.blocks, reversed(skips), strict=True):
            h = block(torch.cat([skip, up(h)], dim=1))
        return self.head(h)


def pad_to_multiple(
    x: torch.Tensor, multiple: int, fill: float | Sequence[float] = 0.0
) -> tuple[torch.Tensor, tuple[int, int]]:
    """Pad ``x`` (``(B, C, H, W)``) at the high ends of H and W to multiples of ``multiple``.

    Args:
        x: input batch.
        multiple: the padded sides are multiples of this.
        fill: one value for every channel, or one per channel (length ``C``).

    Returns:
        The padded ``(B, C, H', W')`` tensor (``x`` itself when no padding is
        needed) and the original ``(H, W)``.
    """
    H, W = int(x.shape[-2]), int(x.shape[-1])
    ph, pw = (-H) % multiple, (-W) % multiple
    if ph == 0 and pw == 0:
        return x, (H, W)
    if isinstance(fill, (int, float)):
        return F.pad(x, (0, pw, 0, ph), value=float(fill)), (H, W)
    values = torch.as_tensor(list(fill), dtype=x.dtype, device=x.device)
    if values.numel() != x.shape[1]:
        raise InputDataError(f"{values.numel()} fill values for {x.shape[1]} channels")
    values = values.view(1, -1, 1, 1)
    return F.pad(x - values, (0, pw, 0, ph), value=0.0) + values, (H, W)


def crop_to(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """The ``[..., :H, :W]`` part of ``x`` (undoes :func:`pad_to_multiple`)."""
    return x[..., : size[0], : size[1]]


class UNet(nn.Module):
    """A U-Net ``(B, in_ch, H, W) -> (B, out_ch, H, W)`` for any ``H, W``.

    Args:
        in_ch: input channels.
        out_ch: output channels (the 1x1 head, no activation).
        arch: widths, depth, normalization and activation (a
            :class:`~dgse.models.config.ModelConfig` is one too).
        pad_value: value(s) of the internal padding, one float or one per input channel.
    """

    def __init__(
        self,
        in_ch: int,
        out_ch: int,
        arch: UNetArch = _DEFAULT_ARCH,
        pad_value: float | Sequence[float] = 0.0,
    ) -> None:
        super().__init__()
        self.encoder = UNetEncoder(in_ch, arch)
        self.decoder = UNetDecoder(out_ch, arch)
        if not isinstance(pad_value, (int, float)) and len(pad_value) != in_ch:
            raise InputDataError(f"{len(pad_value)} pad values for {in_ch} input channels")
        self.pad_value: float | tuple[float, ...] = (
            float(pad_value) if isinstance(pad_value, (int, float)) else tuple(float(v) for v in pad_value)
        )
        self.in_ch, self.out_ch, self.depth = in_ch, out_ch, arch.depth

    @property
    def stride(self) -> int:
        """Total down-sampling factor ``2**depth``."""
        return 2**self.depth

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        xp, size = pad_to_multiple(x, self.stride, self.pad_value)
        bottleneck, skips = self.encoder(xp)
        return crop_to(self.decoder(bottleneck, skips), size)
