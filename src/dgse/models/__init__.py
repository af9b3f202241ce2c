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

#: The modules of the package and the names each defines, imported on first use, so that
#: importing one module of the package (its torch-free settings) does not import the others.
_MODULES: dict[str, tuple[str, ...]] = {
    "dgse.models.checkpoint": ("CheckpointError", "load_model", "read_checkpoint_info", "save_model"),
    "dgse.models.config": ("LossWeights", "ModelConfig", "PRESETS", "VARIANTS", "preset_config"),
    "dgse.models.inference": ("Prediction", "moment_match", "predict"),
    "dgse.models.networks": (
        "DGSEModel",
        "DGSEOutput",
        "DGSE_O",
        "DGSE_P",
        "DGSE_S",
        "build_model",
        "count_parameters",
        "create_model",
    ),
    "dgse.models.objectives": (
        "TargetBatch",
        "dgse_loss",
        "gaussian_nll",
        "mc_marginal_nll",
        "source_cross_entropy",
    ),
    "dgse.models.unet": ("UNet", "UNetDecoder", "UNetEncoder"),
}

__all__ = sorted(name for names in _MODULES.values() for name in names)

__getattr__, __dir__ = lazy_attributes(globals(), _MODULES)
