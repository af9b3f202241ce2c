"""Point sensors: where they are, what they read (spec section 5).

A sensor sits at a free grid cell ``(i, j)`` (row ``i`` along y, column ``j``
along x) and reads the case's true gas concentration and wind there, corrupted
by the sample's noise (:mod:`dgse.sensing.noise`).  Truth (the :class:`Case`)
and observation (:class:`Observations`) are kept apart: nothing here modifies
a case.

Random draws always come from a caller-supplied ``numpy.random.Generator``, so
equal seeds give equal observations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dgse.errors import InputDataError
from dgse.sensing.noise import NoiseModel, NoiseParams, gas_reading, wind_reading
from dgse.world.case import Case

__all__ = [
    "Observations",
    "check_sensor_cells",
    "frame_index",
    "mean_free_concentration",
    "measure",
    "observation_counts",
    "random_observation_count",
    "random_observations",
    "random_sensor_cells",
]

#: Minimum, maximum and step of the number of sensors per training sample (paper Sec. IV).
MIN_SENSORS, MAX_SENSORS, SENSOR_STEP = 5, 300, 5


@dataclass(frozen=True, eq=False)
class Observations:
    """A set of (noisy) point measurements.

    Attributes:
        cells: ``int64 (n, 2)`` sensor cells ``(i, j)``.
        gas: ``float64 (n,)`` gas readings in ppm (>= 0).
        wind: ``float64 (n, 2)`` wind readings ``[u_x, u_y]`` in m/s.
        times: optional ``float64 (n,)`` measurement times in s.
        noise: the noise parameters the readings were drawn with, if known
            (bookkeeping only; never needed to use the readings).
    """

    cells: np.ndarray
    gas: np.ndarray
    wind: np.ndarray
    times: np.ndarray | None = None
    noise: NoiseParams | None = field(default=None)

    def __post_init__(self) -> None:
        cells = np.asarray(self.cells)
        if cells.size == 0:
            cells = cells.reshape(0, 2)
        if cells.ndim != 2 or cells.shape[1] != 2:
            raise InputDataError(f"observation cells must have shape (n, 2), got {cells.shape}")
        if not np.issubdtype(cells.dtype, np.integer):
            if not np.all(np.isfinite(cells)) or np.any(cells != np.round(cells)):
                raise InputDataError("observation cells must be integer (i, j) indices")
        n = cells.shape[0]
        gas = np.asarray(self.gas, dtype=np.float64).reshape(-1)
        wind = np.asarray(self.wind, dtype=np.float64)
        if wind.size == 0:
            wind = wind.reshape(0, 2)
        if gas.shape != (n,):
            raise InputDataError(f"gas readings have shape {gas.shape}, expected ({n},)")
        if wind.shape != (n, 2):
            raise InputDataError(f"wind readings have shape {wind.shape}, expected ({n}, 2)")
        if not (np.isfinite(gas).all() and np.isfinite(wind).all()):
            raise InputDataError("observations contain non-finite readings")
        object.__setattr__(self, "cells", cells.astype(np.int64))
        object.__setattr__(self, "gas", gas)
        object.__setattr__(self, "wind", wind)
        if self.times is not None:
            times = np.broadcast_to(np.asarray(self.times, dtype=np.float64), (n,)).copy()
            object.__setattr__(self, "times", times)

    def __len__(self) -> int:
        return int(self.cells.shape[0])

    @classmethod
    def empty(cls) -> Observations:
        """No observations."""
        return cls(np.zeros((0, 2), np.int64), np.zeros(0), np.zeros((0, 2)))

    def positions(self, resolution: float) -> np.ndarray:
        """Sensor positions ``(n, 2)`` as cell-centre ``(x, y)`` in m."""
        c = self.cells
        return np.stack([c[:, 1] + 0.5, c[:, 0] + 0.5], axis=1) * float(resolution)

    def take(self, index) -> Observations:
        """The observations selected by ``index`` (slice, integer or boolean array)."""
        idx = np.arange(len(self))[index]
        idx = np.atleast_1d(idx)
        times = None if self.times is None else self.times[idx]
        return Observations(self.cells[idx], self.gas[idx], self.wind[idx], times, self.noise)

    def concat(self, other: Observations) -> Observations:
        """These observations followed by ``other`` (e.g. a robot's next measurement).

        Times are kept only when both have them; ``noise`` only when equal.
        """
        times = None
        if self.times is not None and other.times is not None:
            times = np.concatenate([self.times, other.times])
        noise = self.noise if self.noise == other.noise else None
        return Observations(
            np.concatenate([self.cells, other.cells]),
            np.concatenate([self.gas, other.gas]),
            np.concatenate([self.wind, other.wind]),
            times,
            noise,
        )


def observation_counts() -> tuple[int, ...]:
    """The paper's numbers of sensors per sample: ``(5, 10, 15, ..., 300)`` (60 values)."""
    return tuple(range(MIN_SENSORS, MAX_SENSORS + 1, SENSOR_STEP))


def random_observation_count(rng: np.random.Generator) -> int:
    """One number of sensors drawn uniformly from :func:`observation_counts`."""
    counts = observation_counts()
    return counts[int(rng.integers(len(counts)))]


def check_sensor_cells(occupancy: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Validate sensor cells against a map and return them as ``int64 (n, 2)``.

    Args:
        occupancy: ``(H, W)`` map, 1 solid, 0 free.
        cells: ``(n, 2)`` cells ``(i, j)`` (integer-valued).

    Raises:
        InputDataError: naming the first cell outside the map or in a solid cell.
    """
    occ = np.asarray(occupancy)
    H, W = occ.shape
    c = np.asarray(cells)
    if c.size == 0:
        return np.zeros((0, 2), np.int64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise InputDataError(f"sensor cells must have shape (n, 2), got {c.shape}")
    if not np.issubdtype(c.dtype, np.integer):
        if not np.all(np.isfinite(c)) or np.any(c != np.round(c)):
            raise InputDataError("sensor cells must be integer (i, j) indices")
    c = c.astype(np.int64)
    outside = (c[:, 0] < 0) | (c[:, 0] >= H) | (c[:, 1] < 0) | (c[:, 1] >= W)
    if outside.any():
        i, j = c[np.argmax(outside)]
        raise InputDataError(
            f"sensor cell ({i}, {j}) lies outside the map (rows 0..{H - 1}, columns 0..{W - 1})"
        )
    solid = occ[c[:, 0], c[:, 1]] != 0
    if solid.any():
        i, j = c[np.argmax(solid)]
        raise InputDataError(f"sensor cell ({i}, {j}) lies in a wall (solid cell)")
    return c


def random_sensor_cells(free_mask: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` distinct free cells drawn uniformly without replacement.

    Args:
        free_mask: boolean ``(H, W)``, true on free cells.
        n: number of sensors, ``0 <= n <= free_mask.sum()``.
        rng: the random generator.

    Returns:
        ``int64 (n, 2)`` cells ``(i, j)`` in draw order.
    """
    free = np.flatnonzero(np.asarray(free_mask, dtype=bool))
    n = int(n)
    if n < 0:
        raise InputDataError(f"number of sensors must be >= 0, got {n}")
    if n > free.size:
        raise InputDataError(f"cannot place {n} sensors on a map with only {free.size} free cells")
    W = np.asarray(free_mask).shape[1]
    flat = rng.choice(free, size=n, replace=False)
    return np.stack([flat // W, flat % W], axis=1).astype(np.int64)


def mean_free_concentration(case: Case) -> float:
    """Mean steady concentration over the case's free cells, ppm (``c_bar`` of Table I)."""
    return float(case.concentration[case.free].astype(np.float64).mean())


def frame_index(case: Case, t) -> np.ndarray:
    """Frame ``floor(t / frame_dt) mod T`` of ``case.frames`` for time(s) ``t`` in s."""
    if case.frames is None:
        raise InputDataError(f"case {case.name!r} has no frames")
    dt = float(case.meta["frame_dt"])
    if not dt > 0:
        raise InputDataError(f"case {case.name!r} has frame_dt {dt}, must be > 0")
    t = np.asarray(t, dtype=np.float64)
    if not np.isfinite(t).all():
        raise InputDataError("measurement times must be finite")
    return np.mod(np.floor(t / dt).astype(np.int64), case.frames.shape[0])


def measure(
    case: Case,
    cells: np.ndarray,
    noise_params: NoiseParams,
    rng: np.random.Generator,
    t=None,
) -> Observations:
    """Noisy readings of ``case`` at sensor ``cells``.

    The true gas value comes from ``case.frames[floor(t / frame_dt) mod T]``
    when the case has frames and ``t`` is given, else from the steady
    ``case.concentration``; the wind is always the steady ``case.wind``.

    Args:
        case: the true scenario.
        cells: ``(n, 2)`` integer cells ``(i, j)``, each free and on the map.
        noise_params: the sample's noise parameters.
        rng: consumes gas noise draws, then wind noise draws.
        t (float | np.ndarray | None): optional measurement time in s, scalar or ``(n,)``; stored in
            ``Observations.times``.

    Raises:
        InputDataError: a sensor cell outside the map or in a wall (named).
    """
    c = check_sensor_cells(case.occupancy, cells)
    i, j = c[:, 0], c[:, 1]
    times = None
    if t is not None:
        times = np.broadcast_to(np.asarray(t, dtype=np.float64), (len(c),))
        if not np.isfinite(times).all():
            raise InputDataError("measurement times must be finite")
    if times is not None and case.frames is not None:
        c_true = case.frames[frame_index(case, times), i, j]
    else:
        c_true = case.concentration[i, j]
    w_true = case.wind[:, i, j].T
    gas = gas_reading(c_true, noise_params, rng)
    wind = wind_reading(w_true, noise_params, rng)
    return Observations(c, gas, wind, times, noise_params)


def random_observations(
    case: Case,
    n: int,
    rng: np.random.Generator,
    noise_model: NoiseModel | None = None,
    t=None,
) -> Observations:
    """``n`` sensors at random free cells with freshly drawn noise (one training sample).

    Draw order from ``rng``: the noise parameters (:meth:`NoiseModel.draw`,
    ``c_bar`` = :func:`mean_free_concentration`), the cells
    (:func:`random_sensor_cells`), then the readings (:func:`measure`).
    """
    model = noise_model or NoiseModel()
    params = model.draw(rng, mean_free_concentration(case))
    cells = random_sensor_cells(case.free, n, rng)
    return measure(case, cells, params, rng, t=t)
