"""The estimator interface, a streaming wrapper and the registry of estimators by name.

Every estimator (DGSE networks, classical baselines) implements
:class:`Estimator`: ``estimate(occupancy, resolution, observations) -> Belief``,
after being told what it may know besides the readings with
``set_knowledge(knowledge)`` (:mod:`dgse.belief.knowledge`: ``map``,
``openings`` or ``wind``); ``knowledge_levels`` states the levels it works at.

The registry maps a name to a factory ``factory(**kwargs) -> Estimator``.  A
factory may be given lazily as ``"package.module:function"``: it is imported
on first use, so listing names (:func:`estimator_names`) never imports heavy
dependencies (PyTorch for the DGSE estimators).  Built-in names:
``"dgse-o"``, ``"dgse-p"``, ``"dgse-s"`` (:mod:`dgse.estimators.dgse`).  A
module adding estimators calls :func:`register_estimator` at import time, or
a lazy entry is added to ``_BUILTIN`` here.
"""

from __future__ import annotations

import importlib
import re
from typing import Any

from dgse.belief.estimator import Estimator, EstimatorFactory
from dgse.belief.knowledge import Knowledge
from dgse.errors import InputDataError, UnsupportedError

__all__ = [
    "Estimator",
    "EstimatorFactory",
    "estimator_accepts",
    "estimator_names",
    "get_estimator",
    "register_estimator",
]


_NAME = re.compile(r"^[a-z0-9][a-z0-9_.+-]*$")
#: Lazily imported built-in estimators: name -> "module:factory".
_BUILTIN: dict[str, str] = {
    "dgse-o": "dgse.estimators.dgse:make_dgse_o",
    "dgse-p": "dgse.estimators.dgse:make_dgse_p",
    "dgse-s": "dgse.estimators.dgse:make_dgse_s",
    # the physics-guided estimator: the adjoint posterior mixed over flow hypotheses
    "dgse-phys": "dgse.estimators.phys:make_dgse_phys",
    # gas distribution mapping baselines (paper Sec. V-B)
    "kdmv": "dgse.mapping.kernel:KernelDMV",
    "kdmvw": "dgse.mapping.kernel:KernelDMVW",
    "ggmrf": "dgse.mapping.gmrf:GGMRF",
    "gwgmrf": "dgse.mapping.gwgmrf:GWGMRF",
    "gabp": "dgse.mapping.gabp:GaBPPlus",
    # source localization baselines and the physics oracle (paper Sec. V-C, V-D)
    "adjoint": "dgse.localization.adjoint:make_adjoint",
    "adjoint-oracle": "dgse.localization.adjoint:make_adjoint_oracle",
    "dualmode": "dgse.localization.particle_filter:ParticleFilterEstimator",
    "pmfs": "dgse.localization.pmfs:make_pmfs",
    "grgsl": "dgse.localization.grgsl:GrGSLEstimator",
}
_REGISTRY: dict[str, EstimatorFactory | str] = dict(_BUILTIN)


def register_estimator(name: str, factory: EstimatorFactory | str, *, replace: bool = False) -> None:
    """Register ``factory`` (a callable or ``"module:function"``) under ``name``.

    Names are lower case (``[a-z0-9][a-z0-9_.+-]*``).  Registering a taken
    name raises :class:`InputDataError` unless ``replace`` (re-registering the
    same factory is a no-op).
    """
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputDataError(f"invalid estimator name {name!r} (lower case letters, digits, _ . + -)")
    if isinstance(factory, str):
        if ":" not in factory:
            raise InputDataError(f"lazy factory must be 'module:function', got {factory!r}")
    elif not callable(factory):
        raise InputDataError(f"estimator factory for {name!r} is not callable")
    old = _REGISTRY.get(name)
    if old is not None and old is not factory and old != factory and not replace:
        raise InputDataError(f"estimator {name!r} is already registered (pass replace=True)")
    _REGISTRY[name] = factory


def estimator_names() -> list[str]:
    """The registered estimator names, sorted."""
    return sorted(_REGISTRY)


def _resolve(name: str) -> EstimatorFactory:
    entry = _REGISTRY[name]
    if not isinstance(entry, str):
        return entry
    module, _, attr = entry.partition(":")
    try:
        factory = getattr(importlib.import_module(module), attr)
    except ImportError as e:
        raise UnsupportedError(f"estimator {name!r} cannot be loaded here: {e}") from e
    if _REGISTRY.get(name) == entry:  # the module may have registered itself meanwhile
        _REGISTRY[name] = factory
    return factory


def estimator_accepts(name: str, option: str) -> bool:
    """True when the registered estimator ``name`` takes keyword option ``option`` (False if unknown)."""
    from dgse.options import accepts

    if name not in _REGISTRY:
        return False
    return accepts(_resolve(name), option)


def get_estimator(name: str, knowledge: Knowledge | None = None, **kwargs: Any) -> Estimator:
    """A new estimator ``name`` built with ``kwargs``, told ``knowledge`` if given.

    Raises:
        UnsupportedError: an unknown name (the message lists the known ones)
            or an estimator whose dependencies are missing here.
        InputDataError: an option the estimator does not take, or a value of
            the wrong type (:func:`dgse.options.check_options`).
        UnsupportedError: ``knowledge`` of a level the estimator does not work at.
    """
    from dgse.options import check_options

    if name not in _REGISTRY:
        raise UnsupportedError(
            f"unknown estimator {name!r}; known estimators: {', '.join(estimator_names())}"
        )
    factory = _resolve(name)
    est = factory(**check_options(f"estimator {name!r}", factory, kwargs))
    if not callable(getattr(est, "set_knowledge", None)):
        raise UnsupportedError(
            f"estimator {name!r} does not implement the Estimator protocol (no set_knowledge); "
            "derive it from dgse.belief.knowledge.KnowledgeUser"
        )
    if knowledge is not None:
        est.set_knowledge(knowledge)
    return est
