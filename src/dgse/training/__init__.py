"""Training the DGSE networks with Lightning (paper Sec. III-B/C, Sec. IV, Appendix A).

Needs PyTorch and Lightning (but :mod:`dgse.training.config` does not: a configuration is
checked before they are imported).  Main entry points:

* :class:`TrainConfig` / :func:`load_config`: the run's settings (YAML + overrides);
* :func:`train`: a resumable training run that writes ``last.safetensors``
  (weights + optimizer state), ``best.safetensors`` (lowest validation source
  loss), ``history.csv`` and Lightning's CSV log into the run directory;
* :func:`export_model`: the selected model of a run as a model checkpoint;
* :class:`DGSELightningModule`, :class:`DGSEDataModule`: the Lightning pieces.

``dgse train`` (:mod:`dgse.cli.train`) is the command line front end.
"""

from __future__ import annotations

import sys
import types
from typing import Any

from dgse.registry import lazy_attributes

#: Where each name of the package lives; imported on first use, so that importing one
#: module of the package (its torch-free settings) does not import the others.
_WHERE: dict[str, str] = {
    "PRECISIONS": "dgse.training.config",
    "TrainConfig": "dgse.training.config",
    "load_config": "dgse.training.config",
    "parse_duration": "dgse.training.config",
    "DGSEDataModule": "dgse.training.datamodule",
    "EpochSetup": "dgse.training.datamodule",
    "EpochShuffleSampler": "dgse.training.datamodule",
    "DGSELightningModule": "dgse.training.module",
    "localization_error": "dgse.training.module",
    "BEST_NAME": "dgse.training.train",
    "HISTORY_NAME": "dgse.training.train",
    "LAST_NAME": "dgse.training.train",
    "StopControl": "dgse.training.train",
    "TrainResult": "dgse.training.train",
    "TrainState": "dgse.training.train",
    "TrainStateCheckpoint": "dgse.training.train",
    "export_model": "dgse.training.train",
    "read_train_state": "dgse.training.train",
    "train": "dgse.training.train",
}

__all__ = sorted(_WHERE)

__getattr__, __dir__ = lazy_attributes(globals(), _WHERE)


class _Package(types.ModuleType):
    """This package: its ``train`` is the function, also once the submodule of that name is imported
    (the import system then sets the package's attribute to the submodule)."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "train" and isinstance(value, types.ModuleType) and hasattr(value, "train"):
            value = value.train
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
