"""The estimator interface: a map, its prior knowledge and readings in, a :class:`Belief` out.

:class:`Estimator` is what every estimator implements (the DGSE networks,
``dgse-phys``, the classical baselines); :class:`StreamingEstimator` keeps the
belief of a growing set of readings (a moving robot's).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dgse.belief.belief import Belief
from dgse.belief.knowledge import Knowledge
from dgse.errors import InputDataError
from dgse.sensing.sensors import Observations, check_sensor_cells

__all__ = ["Estimator", "EstimatorFactory", "StreamingEstimator"]


@runtime_checkable
class Estimator(Protocol):
    """Anything that turns a map, its prior knowledge and observations into a :class:`Belief`.

    The evaluation, search and benchmark loops call ``set_knowledge`` before a
    scenario's estimates with a :class:`~dgse.belief.knowledge.Knowledge`
    of the level they were asked for (never the case itself); a level outside
    ``knowledge_levels`` raises :class:`~dgse.errors.UnsupportedError`.
    :class:`~dgse.belief.knowledge.KnowledgeUser` implements both.
    """

    knowledge_levels: tuple[str, ...]
    #: its name, as results record it
    name: str
    #: the seed of its random draws (None: fresh); set by the loops before each estimate
    seed: int | None

    def describe(self) -> dict[str, Any]:
        """The settings that make its estimates what they are (recorded with results)."""
        ...

    def set_knowledge(self, knowledge: Knowledge) -> None:
        """Use ``knowledge`` (its map, and the openings or wind its level includes) from now on."""
        ...

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The belief given ``occupancy`` (``(H, W)``, 1 solid), cell size ``resolution`` (m)
        and ``observations`` (sensor cells on that map)."""
        ...


EstimatorFactory = Callable[..., Estimator]


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
