"""The LightningModule that trains a DGSE network (paper Sec. III-B/C, Appendix A).

Training step: one forward pass and :func:`~dgse.models.objectives.dgse_loss`:
the source cross-entropy (Eq. 3, 11) for DGSE-O; ``lambda_w NLL_w + lambda_c
NLL_c + lambda_s CE`` (Eq. 7-11) for DGSE-P; for DGSE-S the same weighted sum
on one stochastic pass with reparameterized wind and concentration samples,
i.e. the single-sample estimate (``R_w = R_c = 1``) of the Jensen lower bound
of Eq. 16, whose source and concentration terms back-propagate through the
samples into the upstream sub-networks.  The noise comes from PyTorch's
global RNG (reseeded every epoch, see :class:`~dgse.training.datamodule.EpochSetup`).

Validation step: the same single forward pass, so the validation losses are
the quantities the paper's checkpoint selection and Appendix B use (for
DGSE-S the surrogate terms of Eq. 16 evaluated on one sampled pass, not a
``K x T`` marginalization).  The DGSE-S noise of validation comes from a
generator seeded identically at every validation (per rank), so successive
validations see the same noise and their differences reflect the weights
only.  Logged per epoch, as means over validation samples:

===================  ==========================================================
``val/source_loss``  source cross-entropy ``-log pi_true`` (the selection metric)
``val/wind_nll``     wind Gaussian NLL per valid cell (DGSE-P/S only)
``val/conc_nll``     log-concentration Gaussian NLL per valid cell (DGSE-P/S only)
``val/loss``         the weighted training objective
``val/loc_error_m``  distance in m between the probability-weighted mean source
                     position ``s_hat`` (Alg. 1) and the centre of the true source cell
===================  ==========================================================

Training metrics ``train/loss`` (per step and per epoch), ``train/source_loss``,
``train/wind_nll``, ``train/conc_nll`` (per epoch) are those of the rank-0
process.  Every metric is logged with the batch's size, so epoch values are
means over samples, independent of the batch size (a smaller last batch
weighs less).

Optimizer: Adam with the configured learning rate and (L2) weight decay, no
schedule (the paper's).
"""

from __future__ import annotations

from typing import Any

import lightning as L
import torch

from dgse.models.networks import DGSEModel, DGSEOutput, ModelConfig, build_model
from dgse.models.objectives import LossWeights, TargetBatch, dgse_loss
from dgse.training.datamodule import derive_seed

__all__ = ["DGSELightningModule", "localization_error", "targets_of"]


def targets_of(batch: dict[str, torch.Tensor]) -> TargetBatch:
    """The :class:`TargetBatch` of a collated dataset batch (keys ``wind``, ``log_conc``, ...)."""
    return TargetBatch(
        wind=batch["wind"],
        log_conc=batch["log_conc"],
        source=batch["source_index"],
        valid=batch["valid"],
    )


def localization_error(probs: torch.Tensor, source_index: torch.Tensor, cell_size: float) -> torch.Tensor:
    """Per-sample distance (m) from the probability-weighted mean position to the true source cell.

    Args:
        probs: ``(B, H, W)`` source probabilities (sum 1 over the valid cells).
        source_index: ``(B,)`` flat canvas index ``i * W + j`` of the true cell.
        cell_size: cell side in m; positions are cell centres ``((i + 0.5) h, (j + 0.5) h)``.

    Returns:
        ``(B,)`` float32 distances.
    """
    p = probs.float()
    _, H, W = p.shape
    rows = (torch.arange(H, device=p.device, dtype=torch.float32) + 0.5) * cell_size
    cols = (torch.arange(W, device=p.device, dtype=torch.float32) + 0.5) * cell_size
    r_hat = (p.sum(dim=2) * rows).sum(dim=1)
    c_hat = (p.sum(dim=1) * cols).sum(dim=1)
    idx = source_index.long()
    r_true = (torch.div(idx, W, rounding_mode="floor").float() + 0.5) * cell_size
    c_true = ((idx % W).float() + 0.5) * cell_size
    return torch.hypot(r_hat - r_true, c_hat - c_true)


class DGSELightningModule(L.LightningModule):
    """Trains one DGSE network (see the module docstring).

    Args:
        model_config: the architecture (:class:`ModelConfig`).
        lr: Adam learning rate (paper: 5e-4).
        weight_decay: Adam weight decay (paper: 1e-4).
        loss_weights: task weights (paper: 1, 1, 0.05).
        cell_size: cell side in m, for ``val/loc_error_m``.
        seed: seed of the validation noise (DGSE-S).

    Attributes:
        model: the :class:`DGSEModel` being trained.
    """

    def __init__(
        self,
        model_config: ModelConfig,
        lr: float = 5e-4,
        weight_decay: float = 1e-4,
        loss_weights: LossWeights | None = None,
        cell_size: float = 0.1,
        seed: int = 0,
    ) -> None:
        super().__init__()
        self.model: DGSEModel = build_model(model_config)
        self.lr = float(lr)
        self.weight_decay = float(weight_decay)
        self.loss_weights = loss_weights or LossWeights()
        self.cell_size = float(cell_size)
        self.seed = int(seed)
        self._val_generator: torch.Generator | None = None

    @property
    def variant(self) -> str:
        """The network variant (``"dgse-o"``, ``"dgse-p"`` or ``"dgse-s"``)."""
        return self.model.config.variant

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None) -> DGSEOutput:
        """One forward pass of the network (stochastic for DGSE-S)."""
        return self.model(x, generator=generator)

    def _losses(
        self, batch: dict[str, torch.Tensor], generator: torch.Generator | None
    ) -> tuple[dict[str, torch.Tensor], DGSEOutput]:
        out = self.model(batch["inputs"], generator=generator)
        return dgse_loss(out, targets_of(batch), self.loss_weights), out

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        """The weighted objective of one batch (Eq. 7 / Eq. 16 with ``R_w = R_c = 1``)."""
        losses, _ = self._losses(batch, None)
        B = int(batch["inputs"].shape[0])
        self.log("train/loss", losses["loss"], on_step=True, on_epoch=True, prog_bar=True, batch_size=B)
        self.log("train/source_loss", losses["source_ce"], on_step=False, on_epoch=True, batch_size=B)
        for key in ("wind_nll", "conc_nll"):
            if key in losses:
                self.log(f"train/{key}", losses[key], on_step=False, on_epoch=True, batch_size=B)
        return losses["loss"]

    def on_validation_epoch_start(self) -> None:
        """A fresh validation noise generator, seeded the same at every validation."""
        gen = torch.Generator(device=self.device)
        gen.manual_seed(derive_seed(self.seed, 0x7A1, int(self.global_rank)))
        self._val_generator = gen

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        """Validation losses and the localization error of one batch (logged per epoch)."""
        losses, out = self._losses(batch, self._val_generator)
        B = int(batch["inputs"].shape[0])
        err = localization_error(out.source_probs(), batch["source_index"], self.cell_size).mean()
        kw: dict[str, Any] = {"on_step": False, "on_epoch": True, "batch_size": B, "sync_dist": True}
        self.log("val/source_loss", losses["source_ce"], prog_bar=True, **kw)
        self.log("val/loss", losses["loss"], **kw)
        for key in ("wind_nll", "conc_nll"):
            if key in losses:
                self.log(f"val/{key}", losses[key], **kw)
        self.log("val/loc_error_m", err, prog_bar=True, **kw)

    def configure_optimizers(self) -> torch.optim.Optimizer:
        """Adam(lr, weight_decay) over all parameters (paper Appendix A)."""
        return torch.optim.Adam(self.model.parameters(), lr=self.lr, weight_decay=self.weight_decay)
