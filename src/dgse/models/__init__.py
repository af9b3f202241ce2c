"""DGSE neural networks (paper Sec. III): U-Nets, the three variants, losses, inference, checkpoints.

Needs PyTorch.  Main entry points:

* :func:`create_model` / :func:`build_model` with :class:`ModelConfig` and the
  ``"paper"`` / ``"small"`` presets (:func:`preset_config`);
* :func:`dgse_loss` (training) and :func:`mc_marginal_nll` (Appendix B);
* :func:`predict` (single pass or MC marginalization with ``K``, ``T``);
* :func:`save_model` / :func:`load_model` (safetensors, no pickles).
"""

from dgse.models.checkpoint import CheckpointError, load_model, read_checkpoint_info, save_model
from dgse.models.inference import Prediction, moment_match, predict
from dgse.models.networks import (
    DGSE_O,
    DGSE_P,
    DGSE_S,
    PRESETS,
    VARIANTS,
    DGSEModel,
    DGSEOutput,
    ModelConfig,
    build_model,
    count_parameters,
    create_model,
    preset_config,
)
from dgse.models.objectives import (
    LossWeights,
    TargetBatch,
    dgse_loss,
    gaussian_nll,
    mc_marginal_nll,
    source_cross_entropy,
)
from dgse.models.unet import UNet, UNetDecoder, UNetEncoder

__all__ = [
    "DGSE_O",
    "DGSE_P",
    "DGSE_S",
    "PRESETS",
    "VARIANTS",
    "CheckpointError",
    "DGSEModel",
    "DGSEOutput",
    "LossWeights",
    "ModelConfig",
    "Prediction",
    "TargetBatch",
    "UNet",
    "UNetDecoder",
    "UNetEncoder",
    "build_model",
    "count_parameters",
    "create_model",
    "dgse_loss",
    "gaussian_nll",
    "load_model",
    "mc_marginal_nll",
    "moment_match",
    "predict",
    "preset_config",
    "read_checkpoint_info",
    "save_model",
    "source_cross_entropy",
]
