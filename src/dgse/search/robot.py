"""A simulated mobile robot with gas and wind sensors on a case's map.

The robot lives on the free cells of ``case.occupancy`` and moves between
cell centres along shortest obstacle-free paths
(:class:`~dgse.planning.paths.FreeSpaceGraph`, 8-connected, no corner cutting)
at a constant ``speed``.  It keeps one clock (s) that advances with

* travel: each step of a path takes ``step length / speed``;
* sensing: :meth:`Robot.sense` dwells ``dwell`` seconds at the current cell
  and reads the gas and wind there at the *end* of the dwell;
* waiting: :meth:`Robot.wait` (e.g. the measured computation time of a
  search step, when the search loop counts it).

Readings on the way (``sample_rate_hz``, off by default as in the paper's protocol): while
:meth:`Robot.move_to` drives, the robot also reads every ``1 / sample_rate_hz`` seconds of
travel, counted from the start of each drive, at the cell it is in at that moment (the
cell whose centre is nearest along the path: the cell it leaves until half of a step, the
cell it enters from there on) and at that time; sampling takes no time, so the clock and
the distance are those of the drive without it.  A reading due at (or after) the arrival
at the goal is not taken: the goal's reading (:meth:`Robot.sense`, after the dwell) comes
then.  A drive stopped at ``until`` reads up to that time (:func:`path_samples`).

Readings follow the paper's Table I sensor models
(:mod:`dgse.sensing.noise`): the noise parameters are drawn once per robot
(one episode) with the case's mean free concentration, then every reading
draws fresh noise.  The true gas value comes from the case's frames at the
reading time (``floor(t / frame_dt) mod T``, spec section 2) when the case
has frames and ``use_frames`` is true, else from the steady field; the wind
is always the steady field.

The trajectory (every cell entered, with its arrival time) and the
travelled distance are recorded.  The robot never enters a solid cell.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from dgse.errors import InputDataError
from dgse.planning.paths import Cell, FreeSpaceGraph, graph_for
from dgse.presets import PROTOCOL
from dgse.sensing.noise import NoiseModel, NoiseParams
from dgse.sensing.sensors import Observations, mean_free_concentration, measure
from dgse.world.case import Case

__all__ = ["Robot", "check_sample_rate", "path_samples", "random_start_cell"]

#: A reading this close (s) to the arrival at the goal counts as due at the arrival; a time
#: this close to the middle of a step counts as in the cell entered (clock rounding).
TIME_TOLERANCE_S = 1e-9


def random_start_cell(
    graph: FreeSpaceGraph,
    rng: np.random.Generator,
    target: Sequence[int] | None = None,
    min_distance_m: float = 0.0,
) -> Cell:
    """A free cell drawn uniformly, connected to ``target`` and at least ``min_distance_m`` from it.

    Args:
        graph: the map's move graph.
        rng: consumes one integer draw.
        target: usually the source cell; the start is drawn among the free
            cells from which it can be reached.  None: any free cell.
        min_distance_m: least path length (m) from the start to ``target``.
            When no connected cell is that far, the draw falls back to the
            cells at least half the largest distance away.

    Returns:
        ``(i, j)``.
    """
    if target is None:
        candidates = graph.free.copy()
    else:
        dist = graph.distances_from(target)
        candidates = np.isfinite(dist) & (dist >= float(min_distance_m))
        if not candidates.any():
            finite = np.isfinite(dist)
            candidates = finite & (dist >= 0.5 * dist[finite].max())
    flat = np.flatnonzero(candidates)
    k = int(flat[int(rng.integers(flat.size))])
    W = graph.shape[1]
    return (k // W, k % W)


def check_sample_rate(sample_rate_hz: float | None) -> float | None:
    """``sample_rate_hz`` as a float (None stays None: readings only at the goals).

    Raises:
        InputDataError: anything but a positive finite number of readings per second (the
            message names the argument as ``{sample_rate_hz}``).
    """
    if sample_rate_hz is None:
        return None
    try:
        rate = float(sample_rate_hz)
    except (TypeError, ValueError):
        rate = math.nan
    if isinstance(sample_rate_hz, bool) or not (math.isfinite(rate) and rate > 0):
        raise InputDataError(
            "{sample_rate_hz} must be a positive number of readings per second (Hz), "
            f"got {sample_rate_hz!r}",
            names={"sample_rate_hz": "sample_rate_hz"},
        )
    return rate


def path_samples(
    path: np.ndarray, arrivals: np.ndarray, interval: float, until: float = math.inf
) -> tuple[np.ndarray, np.ndarray]:
    """Where and when a robot driving along ``path`` reads every ``interval`` seconds.

    Args:
        path: ``int (m + 1, 2)`` the cells of the drive, from the robot's cell to the goal.
        arrivals: ``(m + 1,)`` the time at each cell's centre, s (``arrivals[0]``: the start
            of the drive); increasing.
        interval: seconds of travel between readings (> 0).
        until: no reading after this time (the drive stops there), s.

    Returns:
        ``cells int64 (n, 2)`` and ``times (n,)``: the readings at ``arrivals[0] + k interval``
        for ``k = 1, 2, ...`` before the arrival at the goal (one due there within
        :data:`TIME_TOLERANCE_S` is the goal's) and not after ``until``, each at the cell
        whose centre is nearest along the path (the cell entered from the middle of a step on).
    """
    cells = np.asarray(path, dtype=np.int64).reshape(-1, 2)
    t = np.asarray(arrivals, dtype=np.float64)
    if len(cells) != len(t):
        raise InputDataError(f"{len(cells)} path cells but {len(t)} arrival times")
    if len(cells) < 2:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    last = min(float(t[-1]), float(until) + TIME_TOLERANCE_S)
    n = max(0, math.floor((last - float(t[0])) / interval) + 1)
    times = float(t[0]) + interval * np.arange(1, n + 1)
    times = times[(times < t[-1] - TIME_TOLERANCE_S) & (times <= float(until) + TIME_TOLERANCE_S)]
    seg = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    frac = (times - t[seg]) / (t[seg + 1] - t[seg])
    at = seg + (frac >= 0.5 - TIME_TOLERANCE_S)
    return cells[at], times


class Robot:
    """A point robot on a case's map: moves, dwells, senses; one clock.

    Args:
        case: the true scenario (map, fields, optional frames).
        start: starting cell ``(i, j)``; None draws one with
            :func:`random_start_cell` (connected to the source cell).
        rng: the robot's random generator or a seed.  Draw order: the start
            (when not given), the noise parameters (when not given), then the
            readings.
        speed: m/s.
        dwell: s per measurement.
        noise_model: the Table I ranges to draw the noise parameters from
            (default :class:`NoiseModel`; ``NoiseModel.noiseless()`` for exact readings).
        noise_params: fixed noise parameters instead of a draw.
        use_frames: read time-varying frames when the case has them.
        graph: the move graph (default: :func:`graph_for` the case's map, 8-connected).
        min_start_distance: for a random start, the least path length in m
            to the source.
        sample_rate_hz: readings per second of travel while driving (module docstring);
            None: readings only when :meth:`sense` is called.

    Attributes:
        cell: the current cell.
        clock: elapsed time in s.
        distance_m: distance travelled in m.
        noise_params: the episode's sensor noise parameters.
    """

    def __init__(
        self,
        case: Case,
        *,
        start: Sequence[int] | None = None,
        rng: np.random.Generator | int | None = None,
        speed: float = PROTOCOL.speed,
        dwell: float = PROTOCOL.dwell,
        noise_model: NoiseModel | None = None,
        noise_params: NoiseParams | None = None,
        use_frames: bool = True,
        graph: FreeSpaceGraph | None = None,
        min_start_distance: float = 0.0,
        sample_rate_hz: float | None = PROTOCOL.sample_rate_hz,
    ) -> None:
        if not (math.isfinite(speed) and speed > 0):
            raise InputDataError(f"speed must be a positive number of m/s, got {speed}")
        if not (math.isfinite(dwell) and dwell >= 0):
            raise InputDataError(f"dwell must be a non-negative number of seconds, got {dwell}")
        self.case = case
        self.graph = graph if graph is not None else graph_for(case.occupancy, case.resolution)
        if self.graph.shape != case.occupancy.shape:
            raise InputDataError(f"graph of a {self.graph.shape} map given for a {case.occupancy.shape} case")
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.speed = float(speed)
        self.dwell = float(dwell)
        self.sample_rate_hz = check_sample_rate(sample_rate_hz)
        self.use_frames = bool(use_frames)
        if start is None:
            start = random_start_cell(self.graph, self.rng, case.source_cell, min_start_distance)
        self.start: Cell = self.graph.check_cell(start, "start cell")
        if noise_params is None:
            noise_params = (noise_model or NoiseModel()).draw(self.rng, mean_free_concentration(case))
        self.noise_params: NoiseParams = noise_params
        self.cell: Cell = self.start
        self.clock = 0.0
        self.distance_m = 0.0
        self._cells: list[Cell] = [self.start]
        self._times: list[float] = [0.0]
        self._obs: list[Observations] = []

    # -- recorded state ----------------------------------------------------------------
    @property
    def trajectory_cells(self) -> np.ndarray:
        """``int64 (n, 2)``: every cell entered, in order, starting with the start cell."""
        return np.array(self._cells, dtype=np.int64).reshape(-1, 2)

    @property
    def trajectory_times(self) -> np.ndarray:
        """``float64 (n,)``: the arrival time (s) at each cell of :attr:`trajectory_cells`."""
        return np.array(self._times, dtype=np.float64)

    @property
    def observations(self) -> Observations:
        """All readings so far, in order."""
        if not self._obs:
            return Observations.empty()
        out = self._obs[0]
        for o in self._obs[1:]:
            out = out.concat(o)
        return out

    @property
    def n_readings(self) -> int:
        """The number of readings so far (at goals and on the way)."""
        return sum(len(o) for o in self._obs)

    def readings_since(self, n: int) -> Observations:
        """The readings after the first ``n``, in order (e.g. those since the last decision)."""
        out: list[Observations] = []
        seen = 0
        for o in self._obs:
            if seen + len(o) > n:
                out.append(o if seen >= n else o.take(np.arange(n - seen, len(o))))
            seen += len(o)
        if not out:
            return Observations.empty()
        first = out[0]
        for o in out[1:]:
            first = first.concat(o)
        return first

    @property
    def position(self) -> tuple[float, float]:
        """``(x, y)`` in m of the current cell's centre."""
        res = self.graph.resolution
        return ((self.cell[1] + 0.5) * res, (self.cell[0] + 0.5) * res)

    # -- actions -----------------------------------------------------------------------
    def wait(self, seconds: float, until: float | None = None) -> None:
        """Let ``seconds`` pass at the current cell (the clock stops at ``until`` when given)."""
        s = float(seconds)
        if not (math.isfinite(s) and s >= 0):
            raise InputDataError(f"cannot wait {seconds} s")
        self.clock += s
        if until is not None:
            self.clock = min(self.clock, max(float(until), self.clock - s))

    def move_to(self, goal: Sequence[int], until: float | None = None) -> bool:
        """Move along a shortest obstacle-free path to ``goal``.

        Every cell entered is appended to the trajectory with its arrival time.
        With ``until`` (a time in s), the robot stops when the clock reaches
        it: the distance covered until then counts (the last partial step
        included), the clock is set to ``until``, and :attr:`cell` stays the
        last cell fully reached.  With :attr:`sample_rate_hz`, the readings on the way
        (module docstring) are taken and kept in :attr:`observations`.

        Returns:
            True when the robot reached ``goal``.

        Raises:
            InputDataError: ``goal`` off the map, in a wall, or not reachable.
        """
        path = self.graph.path(self.cell, goal)
        res = self.graph.resolution
        steps = [
            res * (math.sqrt(2.0) if a[0] != b[0] and a[1] != b[1] else 1.0)
            for a, b in itertools.pairwise(path)
        ]
        arrivals = [self.clock]
        for step in steps:
            arrivals.append(arrivals[-1] + step / self.speed)
        if self.sample_rate_hz is not None:
            stop = math.inf if until is None else max(float(until), self.clock)
            cells, times = path_samples(np.array(path), np.array(arrivals), 1.0 / self.sample_rate_hz, stop)
            if len(times):
                self._obs.append(self._read(cells, times))
        for b, step, arrival in zip(path[1:], steps, arrivals[1:], strict=True):
            if until is not None and arrival > until:
                partial = max(0.0, float(until) - self.clock) * self.speed
                self.distance_m += partial
                self.clock = max(self.clock, float(until))
                return False
            self.clock = arrival
            self.distance_m += step
            self.cell = b
            self._cells.append(b)
            self._times.append(arrival)
        return True

    def sense(self) -> Observations:
        """Dwell :attr:`dwell` seconds at the current cell, then read gas and wind there.

        Returns:
            One reading (``Observations`` of length 1, ``times`` = the clock
            after the dwell, ``noise`` = :attr:`noise_params`).
        """
        self.clock += self.dwell
        obs = self._read(np.array([self.cell], dtype=np.int64), np.array([self.clock]))
        self._obs.append(obs)
        return obs

    def _read(self, cells: np.ndarray, times: np.ndarray) -> Observations:
        """Noisy readings at ``cells`` at ``times`` s (the frames at those times, when read)."""
        frames = self.use_frames and self.case.frames is not None
        obs = measure(self.case, cells, self.noise_params, self.rng, t=times if frames else None)
        if not frames:
            obs = Observations(obs.cells, obs.gas, obs.wind, np.asarray(times, dtype=np.float64), obs.noise)
        return obs
