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

__all__ = ["Robot", "random_start_cell"]


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
        last cell fully reached.

        Returns:
            True when the robot reached ``goal``.

        Raises:
            InputDataError: ``goal`` off the map, in a wall, or not reachable.
        """
        path = self.graph.path(self.cell, goal)
        res = self.graph.resolution
        for a, b in itertools.pairwise(path):
            step = res * (math.sqrt(2.0) if a[0] != b[0] and a[1] != b[1] else 1.0)
            arrival = self.clock + step / self.speed
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
        cell = np.array([self.cell], dtype=np.int64)
        t = self.clock
        frames = self.use_frames and self.case.frames is not None
        obs = measure(self.case, cell, self.noise_params, self.rng, t=t if frames else None)
        if not frames:
            obs = Observations(obs.cells, obs.gas, obs.wind, np.array([t]), obs.noise)
        self._obs.append(obs)
        return obs
