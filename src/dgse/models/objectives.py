"""Training objectives of DGSE-O, DGSE-P and DGSE-S, as losses (negative log-likelihoods).

* :func:`gaussian_nll` (Eq. 9-10): ``0.5 * sum_k [log(2 pi) + s_k + exp(-s_k) (t_k - mu_k)^2]``
  per cell (summed over the components ``k``: 2 for the wind, 1 for the
  log-concentration), averaged over the valid cells of each sample (the
  paper's spatial averaging), giving one value per sample.
* :func:`source_cross_entropy` (Eq. 11): ``-log pi_true`` with the softmax
  restricted to the valid cells, one value per sample.
* :func:`dgse_loss`: the batch means and the weighted total.  DGSE-O: the
  cross-entropy alone.  DGSE-P (Eq. 7) and DGSE-S (Eq. 16 with
  ``R_w = R_c = 1``: the output of one stochastic ``DGSE_S.forward``, whose
  concentration and source terms are conditioned on the reparameterized
  samples): ``lambda_w NLL_w + lambda_c NLL_c + lambda_s CE`` with the paper's
  ``lambda_w = lambda_c = 1``, ``lambda_s = 0.05`` (:class:`LossWeights`).
* :func:`mc_marginal_nll` (Appendix B, Eq. B.1-B.2): Monte Carlo estimates
  of the original marginal losses of DGSE-S with ``S_c`` wind and
  ``S_c * S_s`` concentration samples (log-mean-exp), for validating the
  Jensen surrogate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch

from dgse.data.rasterize import Targets
from dgse.errors import InputDataError
from dgse.models.config import LossWeights
from dgse.models.inference import log_mean_exp, make_generator, run_sequential
from dgse.models.networks import DGSE_S, DGSEOutput, masked_log_softmax

__all__ = [
    "LOG_2PI",
    "LossWeights",
    "TargetBatch",
    "dgse_loss",
    "gaussian_nll",
    "mc_marginal_nll",
    "source_cross_entropy",
]

LOG_2PI = math.log(2.0 * math.pi)


@dataclass(eq=False)
class TargetBatch:
    """Targets of a batch on the canvas, as tensors.

    Attributes:
        wind: ``float32 (B, 2, H, W)`` true wind.
        log_conc: ``float32 (B, H, W)`` ``log(c + 1)``.
        source: ``int64 (B,)`` flat canvas index ``i * W + j`` of the source cell.
        valid: ``bool (B, H, W)`` valid mask.
    """

    wind: torch.Tensor
    log_conc: torch.Tensor
    source: torch.Tensor
    valid: torch.Tensor

    @classmethod
    def from_targets(cls, targets: Sequence[Targets], device: torch.device | str = "cpu") -> TargetBatch:
        """Stack :class:`dgse.data.rasterize.Targets` (all on the same canvas)."""
        if not targets:
            raise InputDataError("no targets to stack")
        shapes = {t.canvas_shape for t in targets}
        if len(shapes) != 1:
            raise InputDataError(f"targets on different canvases: {sorted(shapes)}")
        return cls(
            wind=torch.from_numpy(np.stack([t.wind for t in targets]).astype(np.float32)).to(device),
            log_conc=torch.from_numpy(np.stack([t.log_concentration for t in targets]).astype(np.float32)).to(
                device
            ),
            source=torch.tensor([t.source_index for t in targets], dtype=torch.int64, device=device),
            valid=torch.from_numpy(np.stack([t.valid for t in targets]).astype(bool)).to(device),
        )

    def to(self, device: torch.device | str) -> TargetBatch:
        """The same targets on ``device``."""
        return TargetBatch(
            self.wind.to(device), self.log_conc.to(device), self.source.to(device), self.valid.to(device)
        )


def _cell_mean(values: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean of ``(B, H, W)`` values over each sample's valid cells -> ``(B,)`` (0 without valid cells)."""
    v = valid.to(values.dtype)
    total = (values * v).flatten(1).sum(1)
    return total / v.flatten(1).sum(1).clamp_min(1.0)


def gaussian_nll(
    mean: torch.Tensor, logvar: torch.Tensor, target: torch.Tensor, valid: torch.Tensor
) -> torch.Tensor:
    """Per-sample Gaussian negative log-likelihood averaged over valid cells (Eq. 9-10).

    Args:
        mean, logvar, target: ``(B, C, H, W)`` (components summed per cell) or ``(B, H, W)``.
        valid: ``(B, H, W)`` bool.

    Returns:
        ``(B,)``: ``mean over valid cells of 0.5 * sum_k [log 2pi + s + exp(-s) (t - mu)^2]``.
    """
    if not (mean.shape == logvar.shape == target.shape):
        raise InputDataError(
            f"shapes differ: mean {mean.shape}, logvar {logvar.shape}, target {target.shape}"
        )
    mean, logvar, target = mean.float(), logvar.float(), target.float()
    per = 0.5 * (LOG_2PI + logvar + torch.exp(-logvar) * (target - mean).square())
    if per.ndim == 4:
        per = per.sum(dim=1)
    return _cell_mean(per, valid)


def _source_index(source: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    if source.ndim == 1:
        return source.long()
    if source.shape != shape:
        raise InputDataError(f"one-hot source map {tuple(source.shape)} does not match {tuple(shape)}")
    return source.flatten(1).argmax(dim=1)


def source_cross_entropy(logits: torch.Tensor, source: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Per-sample cross-entropy ``-log pi_true`` of a masked softmax (Eq. 11).

    Args:
        logits: ``(B, H, W)`` source logits (values at invalid cells are ignored).
        source: ``int64 (B,)`` flat index of the true cell, or a one-hot map ``(B, H, W)``.
        valid: ``(B, H, W)`` bool.

    Returns:
        ``(B,)`` (``inf`` when a true cell lies outside the valid region).
    """
    logp = masked_log_softmax(logits.float(), valid).flatten(1)
    idx = _source_index(source, logits.shape)
    return -logp.gather(1, idx.unsqueeze(1)).squeeze(1)


def dgse_loss(
    output: DGSEOutput, targets: TargetBatch, weights: LossWeights | None = None
) -> dict[str, torch.Tensor]:
    """The training loss of any DGSE variant with its components (batch means, scalars).

    Args:
        output: the network's :class:`DGSEOutput` (for DGSE-S one stochastic forward).
        targets: the batch's :class:`TargetBatch`.
        weights: task weights (paper defaults); unused by DGSE-O.

    Returns:
        ``{"loss", "source_ce"}`` for DGSE-O, plus ``"wind_nll"`` and
        ``"conc_nll"`` for DGSE-P and DGSE-S; ``"loss"`` is the weighted total
        (a negative lower bound for DGSE-S, Eq. 16) to minimize.
    """
    w = weights or LossWeights()
    ce = source_cross_entropy(output.source_logits, targets.source, targets.valid).mean()
    if output.wind_mean is None:
        return {"loss": ce, "source_ce": ce}
    if output.wind_logvar is None or output.logc_mean is None or output.logc_logvar is None:
        raise InputDataError("output has a wind mean but lacks other field parameters")
    nll_w = gaussian_nll(output.wind_mean, output.wind_logvar, targets.wind, targets.valid).mean()
    nll_c = gaussian_nll(output.logc_mean, output.logc_logvar, targets.log_conc, targets.valid).mean()
    total = w.wind * nll_w + w.conc * nll_c + w.source * ce
    return {"loss": total, "wind_nll": nll_w, "conc_nll": nll_c, "source_ce": ce}


def mc_marginal_nll(
    model: DGSE_S,
    inputs: torch.Tensor,
    targets: TargetBatch,
    S_c: int = 50,
    S_s: int = 50,
    *,
    generator: torch.Generator | None = None,
    seed: int | None = None,
    mode: Literal["field", "cell"] = "field",
    max_batch: int | None = None,
    reduction: Literal["mean", "none"] = "mean",
) -> dict[str, torch.Tensor]:
    """MC estimates of the original (marginal) DGSE-S losses, Appendix B Eq. B.1-B.2.

    ``conc_nll = -log[(1/S_c) sum_i p(c_true | w_i, z^c, o)]`` and
    ``source_ce = -log[(1/(S_c S_s)) sum_ij p(s_true | w_i, c_ij, o)]``,
    evaluated with log-mean-exp.  ``mode="field"`` treats ``p(c_true | ...)``
    as the joint density of the whole field (Eq. B.1 literally) and divides
    the result by the number of valid cells (the training loss' spatial
    averaging); ``mode="cell"`` mixes per cell, then averages over cells.  With
    ``S_c = S_s = 1`` both equal the surrogate terms of :func:`dgse_loss`
    for the same noise.  Runs without gradients.

    Args:
        model: DGSE-S network.
        inputs: ``(B, 5, H, W)`` canvas input.
        targets: the batch's targets.
        S_c, S_s: numbers of wind samples and of concentration samples per wind sample.
        generator, seed: noise source (see :func:`dgse.models.inference.predict`).
        mode: ``"field"`` or ``"cell"`` (see above).
        max_batch: at most this many canvases per network call.
        reduction: ``"mean"`` (batch means, scalars) or ``"none"`` (``(B,)``).

    Returns:
        ``{"conc_nll", "source_ce"}``.
    """
    if mode not in ("field", "cell"):
        raise InputDataError(f"mode must be 'field' or 'cell', got {mode!r}")
    x = inputs
    B = x.shape[0]
    gen = make_generator(x.device, generator, seed)
    src = targets.source.to(x.device).long()
    true_logp = torch.empty(S_s * S_c * B, dtype=torch.float32, device=x.device)

    def consume(a: int, b: int, logp: torch.Tensor) -> None:
        bi = torch.arange(a, b, device=x.device) % B
        true_logp[a:b] = logp.reshape(b - a, -1).gather(1, src[bi].unsqueeze(1)).squeeze(1)

    with torch.no_grad():
        params = run_sequential(model, x, S_c, S_s, consume, gen, max_batch)
    valid = targets.valid.to(x.device)
    mu, lv = params.logc_mean, params.logc_logvar  # (S_c, B, H, W)
    per_cell = 0.5 * (LOG_2PI + lv + torch.exp(-lv) * (targets.log_conc.to(x.device).float() - mu).square())
    loglik = -per_cell  # (S_c, B, H, W)
    v = valid.to(loglik.dtype)
    n_valid = v.flatten(1).sum(1).clamp_min(1.0)  # (B,)
    if mode == "field":
        field_ll = (loglik * v).flatten(2).sum(2)  # (S_c, B)
        conc_nll = -log_mean_exp(field_ll, dim=0) / n_valid
    else:
        mixed = log_mean_exp(loglik, dim=0)  # (B, H, W)
        conc_nll = -(mixed * v).flatten(1).sum(1) / n_valid
    source_ce = -log_mean_exp(true_logp.reshape(S_s * S_c, B), dim=0)
    if reduction == "mean":
        return {"conc_nll": conc_nll.mean(), "source_ce": source_ce.mean()}
    return {"conc_nll": conc_nll, "source_ce": source_ce}
