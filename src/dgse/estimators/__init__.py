"""Gas source estimators behind one interface, returning one :class:`Belief` type.

``get_estimator(name, **kwargs)`` builds a registered estimator
(:func:`estimator_names` lists them); every estimator has
``estimate(occupancy, resolution, observations) -> Belief``.  The DGSE
estimators (:mod:`dgse.estimators.dgse`) import PyTorch only when used.
"""

from dgse.estimators.belief import Belief, normalize_source_probs
from dgse.estimators.registry import (
    Estimator,
    EstimatorFactory,
    StreamingEstimator,
    estimator_names,
    get_estimator,
    register_estimator,
)

__all__ = [
    "Belief",
    "Estimator",
    "EstimatorFactory",
    "StreamingEstimator",
    "estimator_names",
    "get_estimator",
    "normalize_source_probs",
    "register_estimator",
]
