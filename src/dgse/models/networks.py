"""The three DGSE networks of the paper (Sec. III): DGSE-O, DGSE-P and DGSE-S.

Every network reads the five-channel canvas of :func:`dgse.data.rasterize.rasterize`
(``(B, 5, H, W)``: gas, wind x, wind y, occupancy, valid mask; any ``H x W``)
and returns a :class:`DGSEOutput`:

* **DGSE-O** (Eq. 2-3): one U-Net ``5 -> 1`` giving source logits.
* **DGSE-P** (Eq. 4-7): one shared U-Net encoder and three task decoders with
  skip connections: wind (mean and log-variance of ``[u_x, u_y]``, 4
  channels), log-concentration (mean, log-variance: 2 channels) and source (1
  logit channel).
* **DGSE-S** (Eq. 12-19): three conditional U-Nets,
  ``p(w | z^w, z^c, o)`` (input: the 5 canvas channels; output 4 channels),
  ``p(c | w, z^c, o)`` (input: a wind sample ``w*`` (2), the gas channel,
  occupancy, valid mask; output 2 channels; the wind observations are not an
  input, Eq. 12) and ``p(s | w, c, o)`` (input: ``w*`` (2), a log-concentration
  sample ``c*``, occupancy, valid mask; output 1 logit channel).  The forward
  pass used for training draws ``w* = mu_w + sigma_w * eps`` and
  ``c* = mu_c + sigma_c * eps`` by reparameterization (Eq. 17-18, one sample
  each: ``R_w = R_c = 1``), so the source loss back-propagates into all three
  sub-networks.  Samples are set to 0 outside the valid region (where the
  targets are 0).

Heads.  Wind and log-concentration are diagonal Gaussians; their
log-variances pass through a smooth clamp (:func:`soft_clamp`) into
``[logvar_min, logvar_max] = [-12, 6]`` by default (standard deviations from
``0.0025`` to ``20`` in m/s or log-ppm units): wide enough for the paper's
very confident wall and far-field cells (its validation CF loss of -3.7 nats
per cell implies a mean log-variance around -9), narrow enough that
``exp(-logvar)`` cannot overflow or blow up the gradients.  The clamp is
nearly the identity inside the range and keeps a non-zero gradient
everywhere.  The source is a categorical over the valid canvas cells:
:attr:`DGSEOutput.source_logits` holds ``-inf`` at invalid cells, and
:meth:`DGSEOutput.source_log_probs` / :meth:`DGSEOutput.source_probs` are the
masked (log-)softmax (exact zeros off the valid region, never NaN, even for a
sample without a valid cell, whose probabilities are then all 0).

Presets (:func:`preset_config`), depth 3 U-Nets (down-sampling 8), GroupNorm,
ReLU; parameters as measured by ``tests/models/test_networks.py`` and FLOPs
(``torch.utils.flop_counter``, 2 per multiply-add) of one forward pass on a
100 x 100 canvas (one conditional pass of each sub-network for DGSE-S):

=======  =======================  ====================  ===================  =====================
variant  paper (Appendix A)       ``"paper"`` preset    ``"small"`` preset   paper / this FLOPs
=======  =======================  ====================  ===================  =====================
DGSE-O   0.82 M params, 1.61 G    base 21: 0.831 M      base 10: 0.189 M     1.61 G / 1.32 G
DGSE-P   1.54 M params, 3.15 G    base 21: 1.481 M      base 10: 0.337 M     3.15 G / 2.99 G
DGSE-S   1.59 M params, 2.92 G    base 17: 1.635 M      base 8:  0.364 M     2.92 G / 2.61 G
=======  =======================  ====================  ===================  =====================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from dgse.data.rasterize import CH_GAS, CH_OCCUPANCY, CH_VALID, UNOBSERVED_GAS
from dgse.errors import InputDataError
from dgse.models.config import PRESETS, VARIANTS, ModelConfig, Variant, preset_config
from dgse.models.unet import UNet, UNetDecoder, UNetEncoder, crop_to, pad_to_multiple

__all__ = [
    "DGSE_O",
    "DGSE_P",
    "DGSE_S",
    "PRESETS",
    "VARIANTS",
    "DGSEModel",
    "DGSEOutput",
    "ModelConfig",
    "Variant",
    "build_model",
    "count_parameters",
    "create_model",
    "masked_log_softmax",
    "preset_config",
    "soft_clamp",
]

#: Padding values of the five input channels (gas, wind x, wind y, occupancy, valid):
#: the canvas' own padding, so an internally padded canvas looks like a larger canvas.
INPUT_FILL = (UNOBSERVED_GAS, 0.0, 0.0, 1.0, 0.0)


def soft_clamp(x: torch.Tensor, lo: float, hi: float) -> torch.Tensor:
    """Smoothly squash ``x`` into ``(lo, hi)``; close to the identity well inside the range.

    ``hi - softplus(hi - (lo + softplus(x - lo)))``: bounded, monotone, with a
    non-zero gradient everywhere (unlike ``clamp``).
    """
    y = lo + F.softplus(x - lo)
    return hi - F.softplus(hi - y)


def masked_log_softmax(logits: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Log-softmax over the cells of each sample, restricted to ``valid`` cells.

    Args:
        logits: ``(B, H, W)`` (any values at invalid cells).
        valid: ``(B, H, W)`` bool.

    Returns:
        ``(B, H, W)``: log-probabilities, ``-inf`` at invalid cells.  A sample
        without any valid cell gets ``-inf`` everywhere (probabilities 0, not NaN).
    """
    B = logits.shape[0]
    flat = logits.reshape(B, -1)
    if flat.dtype not in (torch.float32, torch.float64):
        flat = flat.float()
    v = valid.reshape(B, -1)
    has_valid = v.any(dim=1, keepdim=True)
    masked = flat.masked_fill(~v, float("-inf"))
    # rows without a valid cell would give NaN: compute them on zeros and mask afterwards
    safe = torch.where(has_valid, masked, torch.zeros_like(masked))
    out = torch.log_softmax(safe, dim=1).masked_fill(~v, float("-inf"))
    return out.reshape(logits.shape)


@dataclass(eq=False)
class DGSEOutput:
    """Distribution parameters predicted for a batch on the canvas.

    Attributes:
        source_logits: ``(B, H, W)`` source logits, ``-inf`` at invalid cells.
        valid: ``(B, H, W)`` bool valid mask (from the input's channel 4).
        wind_mean: ``(B, 2, H, W)`` mean ``[u_x, u_y]`` in m/s (None for DGSE-O).
        wind_logvar: ``(B, 2, H, W)`` log-variance of the wind (None for DGSE-O).
        logc_mean: ``(B, H, W)`` mean of ``log(c + 1)`` (None for DGSE-O).  For
            DGSE-S: of ``p(c | w*, z^c, o)``, conditioned on :attr:`wind_sample`.
        logc_logvar: ``(B, H, W)`` its log-variance (None for DGSE-O).
        wind_sample: ``(B, 2, H, W)`` the reparameterized wind sample ``w*`` (DGSE-S only).
        logc_sample: ``(B, H, W)`` the log-concentration sample ``c*`` (DGSE-S only).
    """

    source_logits: torch.Tensor
    valid: torch.Tensor
    wind_mean: torch.Tensor | None = None
    wind_logvar: torch.Tensor | None = None
    logc_mean: torch.Tensor | None = None
    logc_logvar: torch.Tensor | None = None
    wind_sample: torch.Tensor | None = None
    logc_sample: torch.Tensor | None = None

    def source_log_probs(self) -> torch.Tensor:
        """``(B, H, W)`` masked log-softmax of :attr:`source_logits` (``-inf`` off the valid cells)."""
        return masked_log_softmax(self.source_logits, self.valid)

    def source_probs(self) -> torch.Tensor:
        """``(B, H, W)`` source probabilities: sum 1 over the valid cells, exactly 0 elsewhere."""
        return self.source_log_probs().exp()


def _valid_of(x: torch.Tensor) -> torch.Tensor:
    if x.ndim != 4 or x.shape[1] != 5:
        raise InputDataError(f"DGSE input must have shape (B, 5, H, W), got {tuple(x.shape)}")
    return x[:, CH_VALID] > 0.5


def _mask_logits(logits: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    return logits.masked_fill(~valid, float("-inf"))


class DGSEModel(nn.Module):
    """Common base of the three DGSE networks: holds the :class:`ModelConfig`."""

    variant: str = ""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        if config.variant != self.variant:
            raise InputDataError(
                f"{type(self).__name__} needs a {self.variant!r} config, got {config.variant!r}"
            )
        self.config = config

    @property
    def stride(self) -> int:
        """Total down-sampling factor of the U-Nets."""
        return self.config.stride

    def _unet(self, in_ch: int, out_ch: int, pad_value: tuple[float, ...]) -> UNet:
        return UNet(in_ch, out_ch, self.config, pad_value)

    def _logvar(self, raw: torch.Tensor) -> torch.Tensor:
        return soft_clamp(raw, self.config.logvar_min, self.config.logvar_max)

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None) -> DGSEOutput:
        raise NotImplementedError


class DGSE_O(DGSEModel):
    """Source-only baseline (Eq. 2): one U-Net ``(B, 5, H, W) -> (B, H, W)`` source logits."""

    variant = "dgse-o"

    def __init__(self, config: ModelConfig | None = None) -> None:
        super().__init__(config or preset_config("paper", "dgse-o"))
        self.net = self._unet(5, 1, INPUT_FILL)

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None) -> DGSEOutput:
        """``x``: ``(B, 5, H, W)``; ``generator`` is unused (deterministic network)."""
        valid = _valid_of(x)
        logits = self.net(x)[:, 0]
        return DGSEOutput(source_logits=_mask_logits(logits, valid), valid=valid)


class DGSE_P(DGSEModel):
    """Parallel multi-task model (Eq. 4-7): shared encoder, wind / concentration / source decoders."""

    variant = "dgse-p"

    def __init__(self, config: ModelConfig | None = None) -> None:
        super().__init__(config or preset_config("paper", "dgse-p"))
        c = self.config
        self.encoder = UNetEncoder(5, c)
        self.wind_decoder = UNetDecoder(4, c)
        self.conc_decoder = UNetDecoder(2, c)
        self.source_decoder = UNetDecoder(1, c)

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None) -> DGSEOutput:
        """``x``: ``(B, 5, H, W)``; ``generator`` is unused (deterministic network)."""
        valid = _valid_of(x)
        xp, size = pad_to_multiple(x, self.stride, INPUT_FILL)
        h, skips = self.encoder(xp)
        wind = crop_to(self.wind_decoder(h, skips), size)
        conc = crop_to(self.conc_decoder(h, skips), size)
        logits = crop_to(self.source_decoder(h, skips), size)[:, 0]
        return DGSEOutput(
            source_logits=_mask_logits(logits, valid),
            valid=valid,
            wind_mean=wind[:, :2],
            wind_logvar=self._logvar(wind[:, 2:]),
            logc_mean=conc[:, 0],
            logc_logvar=self._logvar(conc[:, 1]),
        )


class DGSE_S(DGSEModel):
    """Physical dependency-guided sequential model (Eq. 12-19): three conditional U-Nets.

    Sub-networks: :attr:`wind_net` ``p(w | z^w, z^c, o)``, :attr:`conc_net`
    ``p(c | w, z^c, o)``, :attr:`source_net` ``p(s | w, c, o)``.  The stage
    methods (:meth:`wind_params`, :meth:`conc_params`, :meth:`source_logits`,
    :meth:`sample_wind`, :meth:`sample_logc`) are what
    :func:`dgse.models.inference.predict` batches over ``K`` and ``K * T``
    samples.
    """

    variant = "dgse-s"

    def __init__(self, config: ModelConfig | None = None) -> None:
        super().__init__(config or preset_config("paper", "dgse-s"))
        self.wind_net = self._unet(5, 4, INPUT_FILL)
        self.conc_net = self._unet(5, 2, (0.0, 0.0, UNOBSERVED_GAS, 1.0, 0.0))
        self.source_net = self._unet(5, 1, (0.0, 0.0, 0.0, 1.0, 0.0))

    # -- the three conditional stages -------------------------------------------------
    def wind_params(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``p(w | z^w, z^c, o)``: mean and log-variance ``(B, 2, H, W)`` from ``x`` ``(B, 5, H, W)``."""
        out = self.wind_net(x)
        return out[:, :2], self._logvar(out[:, 2:])

    def conc_params(self, wind: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``p(c | w, z^c, o)``: mean and log-variance of ``log(c + 1)``, each ``(B, H, W)``.

        Args:
            wind: ``(B, 2, H, W)`` wind field (a sample ``w*``).
            x: ``(B, 5, H, W)`` canvas input; only gas, occupancy and valid are used.
        """
        inp = torch.cat([wind, x[:, CH_GAS : CH_GAS + 1], x[:, CH_OCCUPANCY : CH_VALID + 1]], dim=1)
        out = self.conc_net(inp)
        return out[:, 0], self._logvar(out[:, 1])

    def source_logits(self, wind: torch.Tensor, logc: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """``p(s | w, c, o)``: ``(B, H, W)`` logits, ``-inf`` at invalid cells.

        Args:
            wind: ``(B, 2, H, W)`` wind sample; logc: ``(B, H, W)`` log-concentration sample;
            x: ``(B, 5, H, W)`` canvas input (only occupancy and valid are used).
        """
        inp = torch.cat([wind, logc.unsqueeze(1), x[:, CH_OCCUPANCY : CH_VALID + 1]], dim=1)
        return _mask_logits(self.source_net(inp)[:, 0], x[:, CH_VALID] > 0.5)

    @staticmethod
    def sample_wind(
        mean: torch.Tensor, logvar: torch.Tensor, eps: torch.Tensor, valid: torch.Tensor
    ) -> torch.Tensor:
        """``w* = (mean + exp(logvar / 2) * eps) * valid`` (Eq. 17): ``(B, 2, H, W)``; valid ``(B, H, W)``."""
        return (mean + torch.exp(0.5 * logvar) * eps) * valid.unsqueeze(1).to(mean.dtype)

    @staticmethod
    def sample_logc(
        mean: torch.Tensor, logvar: torch.Tensor, eps: torch.Tensor, valid: torch.Tensor
    ) -> torch.Tensor:
        """``c* = (mean + exp(logvar / 2) * eps) * valid`` (Eq. 18); all ``(B, H, W)``."""
        return (mean + torch.exp(0.5 * logvar) * eps) * valid.to(mean.dtype)

    def forward(
        self,
        x: torch.Tensor,
        generator: torch.Generator | None = None,
        eps_wind: torch.Tensor | None = None,
        eps_logc: torch.Tensor | None = None,
    ) -> DGSEOutput:
        """One stochastic pass (the training pass, ``R_w = R_c = 1``).

        Args:
            x: ``(B, 5, H, W)`` canvas input.
            generator: source of the noise (``torch.randn``; global RNG if None).
                ``eps_wind`` (``(B, 2, H, W)``) is drawn first, then ``eps_logc``
                (``(B, H, W)``).
            eps_wind, eps_logc: explicit standard-normal noise instead of drawing it.
        """
        valid = _valid_of(x)
        B, _, H, W = x.shape
        mu_w, lv_w = self.wind_params(x)
        if eps_wind is None:
            eps_wind = torch.randn((B, 2, H, W), generator=generator, device=x.device, dtype=x.dtype)
        w = self.sample_wind(mu_w, lv_w, eps_wind, valid)
        mu_c, lv_c = self.conc_params(w, x)
        if eps_logc is None:
            eps_logc = torch.randn((B, H, W), generator=generator, device=x.device, dtype=x.dtype)
        c = self.sample_logc(mu_c, lv_c, eps_logc, valid)
        logits = self.source_logits(w, c, x)
        return DGSEOutput(
            source_logits=logits,
            valid=valid,
            wind_mean=mu_w,
            wind_logvar=lv_w,
            logc_mean=mu_c,
            logc_logvar=lv_c,
            wind_sample=w,
            logc_sample=c,
        )


_CLASSES: dict[str, type[DGSEModel]] = {"dgse-o": DGSE_O, "dgse-p": DGSE_P, "dgse-s": DGSE_S}


def build_model(config: ModelConfig) -> DGSEModel:
    """A freshly initialized network of ``config.variant``."""
    return _CLASSES[config.variant](config)


def create_model(variant: Variant, preset: str = "paper", **overrides: Any) -> DGSEModel:
    """A freshly initialized network from a named preset, e.g. ``create_model("dgse-s", "small")``."""
    return build_model(preset_config(preset, variant, **overrides))


def count_parameters(model: nn.Module, trainable_only: bool = True) -> int:
    """Number of (trainable) parameters of ``model``."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad or not trainable_only)
