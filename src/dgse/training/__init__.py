"""Training the DGSE networks with Lightning (paper Sec. III-B/C, Sec. IV, Appendix A).

Needs PyTorch and Lightning.  Main entry points:

* :class:`TrainConfig` / :func:`load_config`: the run's settings (YAML + overrides);
* :func:`train`: a resumable training run that writes ``last.safetensors``
  (weights + optimizer state), ``best.safetensors`` (lowest validation source
  loss), ``history.csv`` and Lightning's CSV log into the run directory;
* :func:`export_model`: the selected model of a run as a model checkpoint;
* :class:`DGSELightningModule`, :class:`DGSEDataModule`: the Lightning pieces.

``dgse train`` (:mod:`dgse.cli.train`) is the command line front end.
"""

from dgse.training.config import PRECISIONS, TrainConfig, load_config, parse_duration
from dgse.training.datamodule import DGSEDataModule, EpochSetup, EpochShuffleSampler
from dgse.training.module import DGSELightningModule, localization_error
from dgse.training.train import (
    BEST_NAME,
    HISTORY_NAME,
    LAST_NAME,
    StopControl,
    TrainResult,
    TrainState,
    TrainStateCheckpoint,
    export_model,
    read_train_state,
    train,
)

__all__ = [
    "BEST_NAME",
    "HISTORY_NAME",
    "LAST_NAME",
    "PRECISIONS",
    "DGSEDataModule",
    "DGSELightningModule",
    "EpochSetup",
    "EpochShuffleSampler",
    "StopControl",
    "TrainConfig",
    "TrainResult",
    "TrainState",
    "TrainStateCheckpoint",
    "export_model",
    "load_config",
    "localization_error",
    "parse_duration",
    "read_train_state",
    "train",
]
