"""The toolkit's estimators and the registry of every estimator by name.

``get_estimator(name, **kwargs)`` builds a registered estimator
(:func:`estimator_names` lists them); every estimator implements
:class:`dgse.belief.Estimator`.  DGSE's own: the networks DGSE-O/P/S
(:mod:`dgse.estimators.dgse`, PyTorch imported only when used) and the
physics-guided ``dgse-phys`` (:mod:`dgse.estimators.phys`).
"""

from dgse.estimators.registry import estimator_names, get_estimator, register_estimator

__all__ = ["estimator_names", "get_estimator", "register_estimator"]
