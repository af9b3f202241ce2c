"""The estimator interface, a streaming wrapper and the registry of estimators by name.

Every estimator (DGSE networks, classical baselines) implements
:class:`Estimator`: ``estimate(occupancy, resolution, observations) -> Belief``,
after being told what it may know besides the readings with
``set_knowledge(knowledge)`` (:mod:`dgse.estimators.knowledge`: ``map``,
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
import time
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dgse.errors import InputDataError, UnsupportedError
from dgse.estimators.belief import Belief
from dgse.estimators.knowledge import Knowledge
from dgse.sensing.sensors import Observations, check_sensor_cells

__all__ = [
    "Estimator",
    "EstimatorFactory",
    "StreamingEstimator",
    "estimator_accepts",
    "estimator_names",
    "get_estimator",
    "register_estimator",
]


@runtime_checkable
class Estimator(Protocol):
    """Anything that turns a map, its prior knowledge and observations into a :class:`Belief`.

    The evaluation, search and benchmark loops call ``set_knowledge`` before a
    scenario's estimates with a :class:`~dgse.estimators.knowledge.Knowledge`
    of the level they were asked for (never the case itself); a level outside
    ``knowledge_levels`` raises :class:`~dgse.errors.UnsupportedError`.
    :class:`~dgse.estimators.knowledge.KnowledgeUser` implements both.
    """

    knowledge_levels: tuple[str, ...]

    def set_knowledge(self, knowledge: Knowledge) -> None:
        """Use ``knowledge`` (its map, and the openings or wind its level includes) from now on."""
        ...

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The belief given ``occupancy`` (``(H, W)``, 1 solid), cell size ``resolution`` (m)
        and ``observations`` (sensor cells on that map)."""
        ...


EstimatorFactory = Callable[..., Estimator]

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
            "derive it from dgse.estimators.knowledge.KnowledgeUser"
        )
    if knowledge is not None:
        est.set_knowledge(knowledge)
    return est


class StreamingEstimator:
    """Accumulates readings (e.g. of a moving robot) and keeps the current belief.

    The belief is computed lazily: :attr:`belief` re-runs the estimator only
    when readings were added since the last call.

    Example::

        stream = StreamingEstimator(get_estimator("dgse-s", model=path), occupancy, 0.1)
        belief = stream.update(new_readings)      # add and re-estimate
        if belief.normalized_entropy() < 0.2: ...

    Args:
        estimator: any :class:`Estimator`.
        occupancy: ``(H, W)`` map, 1 solid, 0 free.
        resolution: cell size in m.
        observations: initial readings (none by default).
    """

    def __init__(
        self,
        estimator: Estimator,
        occupancy: np.ndarray,
        resolution: float,
        observations: Observations | None = None,
    ) -> None:
        self.estimator = estimator
        self.occupancy = np.asarray(occupancy)
        if self.occupancy.ndim != 2:
            raise InputDataError(f"occupancy must be 2-D, got shape {self.occupancy.shape}")
        self.resolution = float(resolution)
        self._obs = Observations.empty()
        self._belief: Belief | None = None
        self.n_estimates = 0
        self.seconds = 0.0
        if observations is not None:
            self.add(observations)

    @property
    def observations(self) -> Observations:
        """All readings so far, in the order added."""
        return self._obs

    def add(self, observations: Observations) -> None:
        """Append readings (checked against the map now); the belief is recomputed on demand."""
        check_sensor_cells(self.occupancy, observations.cells)
        if len(observations) == 0:
            return
        self._obs = self._obs.concat(observations) if len(self._obs) else observations
        self._belief = None

    def add_reading(
        self, cell: tuple[int, int], gas: float, wind: tuple[float, float], time_s: float | None = None
    ) -> None:
        """Append one reading: gas (ppm) and wind ``[u_x, u_y]`` (m/s) at ``cell = (i, j)``."""
        times = None if time_s is None else np.array([float(time_s)])
        self.add(
            Observations(np.array([cell], dtype=np.int64), np.array([gas]), np.array([wind], float), times)
        )

    @property
    def belief(self) -> Belief:
        """The belief given all readings so far (cached until readings are added)."""
        if self._belief is None:
            t0 = time.perf_counter()
            self._belief = self.estimator.estimate(self.occupancy, self.resolution, self._obs)
            self.seconds += time.perf_counter() - t0
            self.n_estimates += 1
        return self._belief

    def update(self, observations: Observations) -> Belief:
        """:meth:`add` the readings and return the updated :attr:`belief`."""
        self.add(observations)
        return self.belief

    def reset(self) -> None:
        """Forget all readings."""
        self._obs = Observations.empty()
        self._belief = None
