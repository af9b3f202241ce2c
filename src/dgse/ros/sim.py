"""A simulated robot for ``dgse ros sim``, without ROS: what it publishes, and when.

:class:`SimRobot` is :class:`dgse.search.robot.Robot` (the robot of ``dgse search``: moves
along free cells at its speed, dwells, reads the case's noisy gas and wind, steady fields
or filament frames) seeded as ``dgse search`` seeds a trial (:func:`~dgse.search.campaign.trial_seed`
of the case file's stem, then :func:`~dgse.search.episode.episode_streams`: the start and the
sensor noise). It turns each goal into timed events: a pose per cell entered, the readings
on the way when it samples while driving (``sample_rate_hz``, as ``dgse search``'s; each
after a pose of the cell it was read in), then one reading at the end of the dwell;
:meth:`SimRobot.due` hands them out as the simulated clock reaches them. The clock stands
still while the robot waits for a goal, so a search's computation time is not counted (as
``dgse search`` without ``--compute-time``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dgse.errors import InputDataError
from dgse.planning.paths import Cell, graph_for
from dgse.presets import PROTOCOL
from dgse.search.robot import Robot, random_start_cell
from dgse.world.case import Case

__all__ = ["SimEvent", "SimRobot"]


@dataclass(frozen=True)
class SimEvent:
    """Something the simulated robot publishes at ``time_s`` (s on its clock).

    Attributes:
        kind: ``"pose"`` (the robot entered ``cell``) or ``"reading"`` (``gas`` ppm and
            ``wind`` m/s read at ``cell``).
        at_goal: a reading at the end of a dwell (False: one on the way).
    """

    time_s: float
    kind: str
    cell: Cell
    gas: float = math.nan
    wind: tuple[float, float] = (math.nan, math.nan)
    at_goal: bool = True


class SimRobot:
    """The simulated robot on ``case`` (module docstring).

    Args:
        case: the scenario.
        seed, case_name, trial: the seed of ``dgse search --seed seed`` for trial ``trial`` of
            the case file named ``case_name`` (None: the case's name).
        start: the start cell (None: drawn as ``dgse search`` draws it).
        speed, dwell, time_limit, use_frames, min_start_distance, sample_rate_hz: as ``dgse
            search``'s options.
    """

    def __init__(
        self,
        case: Case,
        *,
        seed: int = 0,
        case_name: str | None = None,
        trial: int = 0,
        start: Sequence[int] | None = None,
        speed: float = PROTOCOL.speed,
        dwell: float = PROTOCOL.dwell,
        time_limit: float = PROTOCOL.time_limit,
        use_frames: bool = True,
        min_start_distance: float = PROTOCOL.min_start_distance,
        sample_rate_hz: float | None = PROTOCOL.sample_rate_hz,
    ) -> None:
        from dgse.search.campaign import trial_seed
        from dgse.search.episode import episode_streams

        if not (math.isfinite(time_limit) and time_limit > 0):
            raise InputDataError(f"the time limit must be a positive number of seconds, got {time_limit}")
        self.case = case
        self.time_limit = float(time_limit)
        start_rng, sensor_rng, _ = episode_streams(trial_seed(seed, case_name or case.name, trial))
        self.graph = graph_for(case.occupancy, case.resolution)
        if start is None:
            start = random_start_cell(self.graph, start_rng, case.source_cell, min_start_distance)
        self.robot = Robot(
            case,
            start=start,
            rng=sensor_rng,
            speed=speed,
            dwell=dwell,
            use_frames=use_frames,
            graph=self.graph,
            sample_rate_hz=sample_rate_hz,
        )
        self.events: deque[SimEvent] = deque([SimEvent(0.0, "pose", self.robot.cell)])
        self.last_reading: SimEvent | None = None
        self.idle = False
        self._clock = 0.0
        self._sense()

    @property
    def clock(self) -> float:
        """The time of the last event handed out, s (where the simulated clock stands)."""
        return self._clock

    def _sense(self) -> None:
        r = self.robot
        if r.clock + r.dwell > self.time_limit:
            self.idle = True  # no reading fits: the robot stays
            return
        obs = r.sense()
        self.events.append(SimEvent(r.clock, "reading", r.cell, float(obs.gas[0]), tuple(obs.wind[0])))
        self.idle = False

    def go_to(self, goal: Sequence[int]) -> bool:
        """Drive to ``goal`` and read there (the events of it are queued); False when the goal
        is refused (the robot is still busy, the time is up, or the goal is not a free
        reachable cell)."""
        if self.events or not self.idle:
            return False
        try:
            cell = self.graph.check_cell(goal, "goal")
            if not math.isfinite(self.graph.distance(self.robot.cell, cell)):
                raise InputDataError(f"goal {cell} cannot be reached from {self.robot.cell}")
        except InputDataError:
            return False
        if self.robot.clock >= self.time_limit:
            return False
        n, m = len(self.robot.trajectory_cells), self.robot.n_readings
        self.robot.move_to(cell, until=self.time_limit)
        cells, times = self.robot.trajectory_cells[n:], self.robot.trajectory_times[n:]
        events = [
            SimEvent(float(t), "pose", (int(c[0]), int(c[1]))) for c, t in zip(cells, times, strict=True)
        ]
        on_the_way = self.robot.readings_since(m)
        for k in range(len(on_the_way)):
            c = (int(on_the_way.cells[k, 0]), int(on_the_way.cells[k, 1]))
            t = float(on_the_way.times[k])
            # the pose of the reading's cell first (a path sample takes the nearest cell centre,
            # which the robot can reach half a step before it enters the cell)
            events.append(SimEvent(t, "pose", c))
            gas, wind = float(on_the_way.gas[k]), (float(on_the_way.wind[k, 0]), float(on_the_way.wind[k, 1]))
            events.append(SimEvent(t, "reading", c, gas, wind, at_goal=False))
        events.sort(key=lambda e: e.time_s)  # stable: a reading after the pose of its time
        self.events.extend(events)
        self._sense()
        return True

    def next_time(self) -> float | None:
        """The time of the next queued event (None: waiting for a goal)."""
        return self.events[0].time_s if self.events else None

    def due(self, until: float) -> list[SimEvent]:
        """The queued events up to time ``until`` s, in order (the clock moves to the last)."""
        out: list[SimEvent] = []
        while self.events and self.events[0].time_s <= until:
            e = self.events.popleft()
            self._clock = e.time_s
            if e.kind == "reading" and e.at_goal:
                self.last_reading = e
                self.idle = True
            out.append(e)
        return out

    def position(self, cell: Cell) -> tuple[float, float]:
        """The centre of ``cell`` on the case's grid, m."""
        res = self.case.resolution
        return ((cell[1] + 0.5) * res, (cell[0] + 0.5) * res)

    def trajectory(self) -> np.ndarray:
        """Every cell entered so far (queued events included)."""
        return self.robot.trajectory_cells
