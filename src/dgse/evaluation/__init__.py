"""Estimator evaluation: metrics of one estimate and runs over sets of cases (paper Sec. V-A to V-C).

* :mod:`dgse.evaluation.metrics`: source-localization error, cross-entropy at
  the true cell, wind and concentration RMSE / Gaussian NLL (log and ppm space),
  all pure functions of a :class:`~dgse.belief.belief.Belief` and the true
  :class:`~dgse.world.case.Case`;
* :mod:`dgse.evaluation.evaluate`: :func:`evaluate` of any registered estimator
  on case files or a dataset store, with seeded observations shared by all
  methods, and the JSON result format.

Neither module imports PyTorch (a DGSE estimator does when it is built).
"""

from dgse.evaluation.evaluate import (
    draw_observations,
    evaluate,
    load_estimate,
    observation_seed,
    open_cases,
    save_estimate,
    write_json,
)
from dgse.evaluation.metrics import (
    METRIC_KEYS,
    PROB_FLOOR,
    EstimateMetrics,
    evaluate_belief,
    gaussian_nll,
    source_cross_entropy,
    source_localization_error,
)

__all__ = [
    "METRIC_KEYS",
    "PROB_FLOOR",
    "EstimateMetrics",
    "draw_observations",
    "evaluate",
    "evaluate_belief",
    "gaussian_nll",
    "load_estimate",
    "observation_seed",
    "open_cases",
    "save_estimate",
    "source_cross_entropy",
    "source_localization_error",
    "write_json",
]
