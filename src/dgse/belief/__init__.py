"""What every estimator takes and returns.

* :mod:`~dgse.belief.belief`: :class:`Belief`, the answer of every estimator on the map's
  grid (source posterior, wind and concentration means and variances);
* :mod:`~dgse.belief.knowledge`: :class:`Knowledge`, what an estimator is told besides the
  readings (``map`` < ``openings`` < ``wind``), and :class:`KnowledgeUser`;
* :mod:`~dgse.belief.estimator`: the :class:`Estimator` protocol and
  :class:`StreamingEstimator` for a growing set of readings;
* :mod:`~dgse.belief.inputs`: the input checks every estimator shares;
* :mod:`~dgse.belief.predictive`: the predictive distribution of a gas reading a belief
  answers (:class:`~dgse.belief.predictive.ReadingMixture`).
"""

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.belief.estimator import Estimator, EstimatorFactory, StreamingEstimator
from dgse.belief.knowledge import Knowledge, KnowledgeUser

__all__ = [
    "Belief",
    "Estimator",
    "EstimatorFactory",
    "Knowledge",
    "KnowledgeUser",
    "StreamingEstimator",
    "normalize_source_probs",
]
