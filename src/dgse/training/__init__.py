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

#: The modules of the package and the names each defines, imported on first use, so that
#: importing one module of the package (its torch-free settings) does not import the others.
_MODULES: dict[str, tuple[str, ...]] = {
    "dgse.training.config": ("PRECISIONS", "TrainConfig", "load_config", "parse_duration"),
    "dgse.training.datamodule": ("DGSEDataModule", "EpochSetup", "EpochShuffleSampler"),
    "dgse.training.module": ("DGSELightningModule", "localization_error"),
    "dgse.training.train": (
        "BEST_NAME",
        "HISTORY_NAME",
        "LAST_NAME",
        "StopControl",
        "TrainResult",
        "TrainState",
        "TrainStateCheckpoint",
        "export_model",
        "read_train_state",
        "train",
    ),
}

__all__ = sorted(name for names in _MODULES.values() for name in names)

__getattr__, __dir__ = lazy_attributes(globals(), _MODULES)


class _Package(types.ModuleType):
    """This package: its ``train`` is the function, also once the submodule of that name is imported
    (the import system then sets the package's attribute to the submodule)."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "train" and isinstance(value, types.ModuleType) and hasattr(value, "train"):
            value = value.train
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
