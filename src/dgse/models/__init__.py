"""DGSE neural networks (paper Sec. III): U-Nets, the three variants, losses, inference, checkpoints.

Needs PyTorch (but :mod:`dgse.models.config`, the architecture settings, does not).  Main
entry points:

* :func:`create_model` / :func:`build_model` with :class:`ModelConfig` and the
  ``"paper"`` / ``"small"`` presets (:func:`preset_config`);
* :func:`dgse_loss` (training) and :func:`mc_marginal_nll` (Appendix B);
* :func:`predict` (single pass or MC marginalization with ``K``, ``T``);
* :func:`save_model` / :func:`load_model` (safetensors, no pickles).
"""

from __future__ import annotations

from dgse.registry import lazy_attributes

#: Where each name of the package lives; imported on first use, so that importing one
#: module of the package (its torch-free settings) does not import the others.
_WHERE: dict[str, str] = {
    "CheckpointError": "dgse.models.checkpoint",
    "load_model": "dgse.models.checkpoint",
    "read_checkpoint_info": "dgse.models.checkpoint",
    "save_model": "dgse.models.checkpoint",
    "LossWeights": "dgse.models.config",
    "ModelConfig": "dgse.models.config",
    "PRESETS": "dgse.models.config",
    "VARIANTS": "dgse.models.config",
    "preset_config": "dgse.models.config",
    "Prediction": "dgse.models.inference",
    "moment_match": "dgse.models.inference",
    "predict": "dgse.models.inference",
    "DGSEModel": "dgse.models.networks",
    "DGSEOutput": "dgse.models.networks",
    "DGSE_O": "dgse.models.networks",
    "DGSE_P": "dgse.models.networks",
    "DGSE_S": "dgse.models.networks",
    "build_model": "dgse.models.networks",
    "count_parameters": "dgse.models.networks",
    "create_model": "dgse.models.networks",
    "TargetBatch": "dgse.models.objectives",
    "dgse_loss": "dgse.models.objectives",
    "gaussian_nll": "dgse.models.objectives",
    "mc_marginal_nll": "dgse.models.objectives",
    "source_cross_entropy": "dgse.models.objectives",
    "UNet": "dgse.models.unet",
    "UNetDecoder": "dgse.models.unet",
    "UNetEncoder": "dgse.models.unet",
}

__all__ = sorted(_WHERE)

__getattr__, __dir__ = lazy_attributes(globals(), _WHERE)
