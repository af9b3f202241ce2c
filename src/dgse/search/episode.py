"""One active search episode: the paper's Algorithm 1 for any estimator and planner.

:func:`run_episode` repeats, from a start cell,

1. **sense**: dwell and read gas and wind at the robot's cell (:meth:`Robot.sense`);
2. **estimate**: the estimator turns *all* readings so far into a belief
   (:class:`~dgse.belief.estimator.StreamingEstimator`);
3. **terminate?** ``planner.should_stop(belief, history)`` (the entropy test
   for the utility planner) ends the search;
4. **plan**: ``planner.next_goal(...)`` picks the next cell (None ends the search);
5. **move** there along the shortest obstacle-free path,

until the planner stops it or the clock reaches ``time_limit``.  A
measurement is started only if its dwell ends within the limit.  When
time runs out during a move, the robot stops where it is at the limit.

Readings on the way (``sample_rate_hz``, off by default: the paper's protocol reads only at
the goals): the robot also reads every ``1 / sample_rate_hz`` seconds of travel while it
drives to a goal (:class:`~dgse.search.robot.Robot`: at the cell it is in then, at that
time, with the same noise and frames; sampling takes no time).  The planner still decides
only at the goals: at each goal, after the dwell reading, the readings of the drive and the
goal's go into the estimator together (one estimate), then the stop test and the next goal
(one :func:`search_step`).  So a *step* is one estimate and one decision, as without them;
:attr:`StepRecord.n_readings` says how many readings it added, and the planner's
``history.step`` counts readings (``stop.min_observations`` waits for that many readings,
on the way or at goals).  Readings of a drive the time limit cuts short are used by no
estimate (the search ended before it could decide again).

The result (:class:`EpisodeResult`) holds the final estimate, the belief's
probability-weighted mean source position (paper Sec. III-D) of the last
belief (at the timeout for failed searches; the centroid of the free cells
when not even one measurement fitted), the search time (the clock at the
end; ``time_limit`` after a timeout), the travelled distance, and per step
(:class:`StepRecord`) the robot cell, time, readings, entropy, estimate,
error, the computation time split into preprocessing / inference / planning
and, with ``record=True``, the belief maps for :mod:`dgse.viz.search`
(source posterior, wind mean, ``log(1 + c)`` mean), float32, block-averaged
to at most ``record_max_cells`` cells.

Signs of life: ``on_step`` (:data:`StepCallback`) gets every step's
:class:`StepRecord` as soon as it is made (step index, the simulated clock at
the reading ``time_s``, the normalized entropy, the current error, ...), e.g.
to show them while a long episode runs; an exception it raises (e.g.
``KeyboardInterrupt``) ends the episode.

Computation time split: *preprocessing* is the loop's own handling of the
readings (checking and appending them) plus, if the estimator reports it in
``belief.info["timings"]["preprocessing"]`` (s), its input preparation;
*inference* is the rest of the ``estimate`` call; *planning* is the
termination test, the Dijkstra distances from the robot and ``next_goal``.

Random streams: the episode's seed (``rng``: an int, a ``SeedSequence`` or a
``Generator``) is split into three independent streams: the start cell, the
sensor noise (parameters and readings), and the planner's generator.  So the
start depends only on the seed (equal for every method), and a stochastic
planner does not change the readings of a deterministic one.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dgse.belief.belief import Belief
from dgse.belief.estimator import Estimator, StreamingEstimator
from dgse.belief.knowledge import DEFAULT_LEVEL, Knowledge
from dgse.errors import InputDataError
from dgse.planning.paths import Cell, FreeSpaceGraph, graph_for
from dgse.planning.planners import (
    Planner,
    SearchHistory,
    point_estimates,
)
from dgse.presets import PROTOCOL
from dgse.search.robot import Robot, check_sample_rate, random_start_cell
from dgse.sensing.noise import NoiseModel, NoiseParams
from dgse.sensing.sensors import Observations
from dgse.world.case import Case

__all__ = [
    "REASONS",
    "EpisodeResult",
    "StepCallback",
    "StepDecision",
    "StepRecord",
    "episode_streams",
    "run_episode",
    "search_step",
]

#: Why an episode ended: the planner's termination test, its deadline (``deadline.margin_s``),
#: ``next_goal`` returned None, the time limit.
REASONS = ("converged", "deadline", "planner_stop", "time_limit")


@dataclass(eq=False)
class StepRecord:
    """One search step: a measurement at a goal, the belief after it, the decision.

    Attributes:
        step: 1-based step index ``k`` (one per measurement location: one estimate and one
            decision).
        cell: ``(i, j)`` where the robot measured.
        time_s: time of the goal's reading (end of the dwell), s.
        gas: the goal's gas reading, ppm.
        wind: the goal's wind reading ``(u_x, u_y)``, m/s.
        entropy: ``H(pi_s)`` of the belief, nats.
        normalized_entropy: ``H(pi_s) / log N``.
        estimate_xy: the belief's probability-weighted mean source position, m.
        error_m: distance from ``estimate_xy`` to the true source, m.
        preprocessing_s, inference_s, planning_s: computation time of this step, s.
        goal: the chosen next cell, or None (the search ended at this step).
        n_readings: the readings this step's estimate added: the goal's, and with readings on
            the way (``sample_rate_hz``) those of the drive to it.
        source_probs: recorded source posterior ``float32 (h, w)`` (or None).
        wind_mean: recorded wind mean ``float32 (2, h, w)`` (or None).
        log_conc_mean: recorded ``log(1 + c)`` mean ``float32 (h, w)`` (or None).
    """

    step: int
    cell: Cell
    time_s: float
    gas: float
    wind: tuple[float, float]
    entropy: float
    normalized_entropy: float
    estimate_xy: tuple[float, float]
    error_m: float
    preprocessing_s: float = 0.0
    inference_s: float = 0.0
    planning_s: float = 0.0
    goal: Cell | None = None
    n_readings: int = 1
    source_probs: np.ndarray | None = field(default=None, repr=False)
    wind_mean: np.ndarray | None = field(default=None, repr=False)
    log_conc_mean: np.ndarray | None = field(default=None, repr=False)

    @property
    def compute_s(self) -> float:
        """One-step computation time: preprocessing + inference + planning, s."""
        return self.preprocessing_s + self.inference_s + self.planning_s

    def to_dict(self) -> dict[str, Any]:
        """The scalar fields as JSON-able values (no maps)."""
        return {
            "step": self.step,
            "cell": list(self.cell),
            "time_s": self.time_s,
            "gas": self.gas,
            "wind": list(self.wind),
            "entropy": self.entropy,
            "normalized_entropy": self.normalized_entropy,
            "estimate_xy": list(self.estimate_xy),
            "error_m": self.error_m,
            "preprocessing_s": self.preprocessing_s,
            "inference_s": self.inference_s,
            "planning_s": self.planning_s,
            "compute_s": self.compute_s,
            "goal": None if self.goal is None else list(self.goal),
            "n_readings": self.n_readings,
        }


#: ``on_step(record)``: called after every step of :func:`run_episode` (signs of life).
StepCallback = Callable[[StepRecord], None]


@dataclass(eq=False)
class EpisodeResult:
    """The outcome of one search (see :mod:`dgse.search.metrics` for the paper's metrics).

    Attributes:
        case_name: the case's name.
        method: the estimator's name.
        planner: the planner's name.
        source_xy: the true source ``(x, y)``, m.
        source_cell: the true source cell.
        start_cell: the robot's start cell.
        estimate_xy: the final estimate ``(x, y)``, m: the belief's posterior mean, or what
            the planner declares at a deadline stop (:meth:`~dgse.planning.planners.Planner.declare`).
        error_m: localization error of the final estimate, m.
        reason: one of :data:`REASONS`.
        search_time_s: the clock when the search ended (``time_limit_s`` after a timeout), s.
        distance_m: travelled distance, m.
        shortest_path_m: shortest obstacle-free path from the start to the source cell, m.
        time_limit_s: the time limit, s.
        steps: the per-step records.
        trajectory_cells: ``int64 (n, 2)`` every cell entered, from the start.
        trajectory_times: ``float64 (n,)`` arrival times, s.
        record_factor: block size of the recorded maps (1: full resolution).
        resolution: the map's cell size, m.
        settings: the episode's settings (speed, dwell, flags, noise parameters, and
            ``sample_rate_hz`` when the robot read on the way).
        readings: every reading the estimates used, in order (the goals' and those on the way).
        end_errors_m: the error, m, of each point estimate of the final belief
            (:func:`~dgse.planning.planners.point_estimates`: mean, mode, disks), whatever the
            episode declared; empty when it ended before any reading.
    """

    case_name: str
    method: str
    planner: str
    source_xy: tuple[float, float]
    source_cell: Cell
    start_cell: Cell
    estimate_xy: tuple[float, float]
    error_m: float
    reason: str
    search_time_s: float
    distance_m: float
    shortest_path_m: float
    time_limit_s: float = PROTOCOL.time_limit
    steps: list[StepRecord] = field(default_factory=list)
    trajectory_cells: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64), repr=False)
    trajectory_times: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    record_factor: int = 1
    resolution: float = 0.1
    settings: dict[str, Any] = field(default_factory=dict)
    end_errors_m: dict[str, float] = field(default_factory=dict)
    readings: Observations = field(default_factory=Observations.empty, repr=False)

    def __post_init__(self) -> None:
        if self.reason not in REASONS:
            raise InputDataError(f"episode end reason must be one of {REASONS}, got {self.reason!r}")

    @property
    def terminated(self) -> bool:
        """True when the method ended the search itself (not by the time limit)."""
        return self.reason != "time_limit"

    @property
    def n_steps(self) -> int:
        """Number of search steps: measurement locations, each one estimate and one decision."""
        return len(self.steps)

    @property
    def n_readings(self) -> int:
        """Number of readings the estimates used (:attr:`n_steps` without readings on the way)."""
        return sum(s.n_readings for s in self.steps)

    @property
    def measurement_cells(self) -> np.ndarray:
        """``int64 (k, 2)`` the cells measured, in order."""
        return np.array([s.cell for s in self.steps], dtype=np.int64).reshape(-1, 2)

    @property
    def recorded(self) -> bool:
        """True when the steps carry belief maps (``record=True``)."""
        return bool(self.steps) and self.steps[0].source_probs is not None

    def to_dict(self, steps: bool = False) -> dict[str, Any]:
        """A JSON-able summary (with the scalar step records when ``steps``)."""
        out: dict[str, Any] = {
            "case": self.case_name,
            "method": self.method,
            "planner": self.planner,
            "source_xy": list(self.source_xy),
            "source_cell": list(self.source_cell),
            "start_cell": list(self.start_cell),
            "estimate_xy": list(self.estimate_xy),
            "error_m": self.error_m,
            "reason": self.reason,
            "terminated": self.terminated,
            "search_time_s": self.search_time_s,
            "distance_m": self.distance_m,
            "shortest_path_m": self.shortest_path_m if math.isfinite(self.shortest_path_m) else None,
            "time_limit_s": self.time_limit_s,
            "n_steps": self.n_steps,
            "n_readings": self.n_readings,
            "end_errors_m": self.end_errors_m,
            "settings": self.settings,
        }
        if steps:
            out["steps"] = [s.to_dict() for s in self.steps]
        return out


def episode_streams(
    rng: np.random.Generator | np.random.SeedSequence | int | None,
) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """The three independent generators of an episode: start cell, sensor noise, planner."""
    if isinstance(rng, np.random.Generator):
        a, b, c = rng.spawn(3)
        return a, b, c
    ss = rng if isinstance(rng, np.random.SeedSequence) else np.random.SeedSequence(rng)
    a, b, c = (np.random.default_rng(s) for s in ss.spawn(3))
    return a, b, c


def _block_reduce(a: np.ndarray, f: int, how: str) -> np.ndarray:
    """Block mean (``how="mean"``) or sum of the last two axes over ``f x f`` blocks (edges padded)."""
    if f == 1:
        return a.astype(np.float32, copy=True)
    H, W = a.shape[-2:]
    h, w = -(-H // f), -(-W // f)
    pad = [(0, 0)] * (a.ndim - 2) + [(0, h * f - H), (0, w * f - W)]
    p = np.pad(a.astype(np.float64), pad, constant_values=np.nan)
    p = p.reshape(*a.shape[:-2], h, f, w, f)
    r = np.nansum(p, axis=(-3, -1)) if how == "sum" else np.nanmean(p, axis=(-3, -1))
    return r.astype(np.float32)


def _record_factor(shape: tuple[int, int], max_cells: int) -> int:
    f = 1
    while math.ceil(shape[0] / f) * math.ceil(shape[1] / f) > max_cells:
        f += 1
    return f


def _estimator_name(estimator: Estimator, belief: Belief | None) -> str:
    if belief is not None and belief.method != "unknown":
        return belief.method
    return estimator.name


def _free_centroid(case: Case) -> tuple[float, float]:
    i, j = np.nonzero(case.free)
    res = case.resolution
    return (float((j + 0.5).mean() * res), float((i + 0.5).mean() * res))


@dataclass(eq=False)
class StepDecision:
    """What one search step decided (:func:`search_step`).

    Attributes:
        belief: the belief given every reading so far.
        stop: the planner's stop test passed (the search ends here).
        goal: the next cell, or None (stopped, or the planner has no goal: the search ends).
        reason: why the search ends at this step (:data:`REASONS`: ``"converged"``,
            ``"deadline"``, ``"planner_stop"``), or None when it goes on to ``goal``.
        preprocessing_s, inference_s, planning_s: the step's computation time split, s.
    """

    belief: Belief
    stop: bool
    goal: Cell | None
    reason: str | None
    preprocessing_s: float
    inference_s: float
    planning_s: float

    @property
    def compute_s(self) -> float:
        """The step's computation time: preprocessing + inference + planning, s."""
        return self.preprocessing_s + self.inference_s + self.planning_s


def search_step(
    stream: StreamingEstimator,
    planner: Planner,
    graph: FreeSpaceGraph,
    history: SearchHistory,
    reading: Observations,
    robot_cell: Cell,
    *,
    excluded: Sequence[Cell] = (),
) -> StepDecision:
    """One step of the search loop after a reading: estimate, stop test, next goal.

    The loop that owns the robot (:func:`run_episode`, the ROS node of :mod:`dgse.ros`) sets
    ``history``'s trajectory, clock, distance and step count first; this adds ``reading``
    to ``stream``, sets ``history.observations`` and asks ``planner``.

    Args:
        reading: the new readings: one, or those since the last decision (the readings on
            the way to the goal, then the goal's), all estimated at once.
        excluded: cells the goal may not be (e.g. goals a navigation stack refused): they
            count as unreachable for the planner.
    """
    t0 = time.perf_counter()
    stream.add(reading)
    t1 = time.perf_counter()
    belief = stream.belief
    t2 = time.perf_counter()
    pre, inf = t1 - t0, t2 - t1
    timings = belief.info.get("timings")
    if isinstance(timings, dict) and isinstance(timings.get("preprocessing"), int | float):
        extra = min(max(float(timings["preprocessing"]), 0.0), inf)
        pre, inf = pre + extra, inf - extra
    history.observations = stream.observations

    t3 = time.perf_counter()
    stop = bool(planner.should_stop(belief, history))
    goal: Cell | None = None
    if not stop:
        distances = graph.distances_from(robot_cell)
        if len(excluded):
            distances = distances.copy()
            for i, j in excluded:
                distances[i, j] = np.inf
        raw = planner.next_goal(belief, robot_cell, distances, history)
        goal = None if raw is None else graph.check_cell(raw, f"goal of planner {planner.name!r}")
    reason: str | None = None
    if stop:
        reason = "deadline" if planner.deadline_reached(history) else "converged"
    elif goal is None:
        reason = "planner_stop"
    plan = time.perf_counter() - t3
    return StepDecision(belief, stop, goal, reason, pre, inf, plan)


def run_episode(
    case: Case,
    estimator: Estimator,
    planner: Planner,
    *,
    start: Sequence[int] | None = None,
    rng: np.random.Generator | np.random.SeedSequence | int | None = None,
    speed: float = PROTOCOL.speed,
    dwell: float = PROTOCOL.dwell,
    time_limit: float = PROTOCOL.time_limit,
    include_compute_time: bool = False,
    record: bool = True,
    use_frames: bool = True,
    noise_model: NoiseModel | None = None,
    noise_params: NoiseParams | None = None,
    min_start_distance: float = 0.0,
    connectivity: int = 8,
    record_max_cells: int = 10_000,
    on_step: StepCallback | None = None,
    knowledge: str = DEFAULT_LEVEL,
    sample_rate_hz: float | None = PROTOCOL.sample_rate_hz,
) -> EpisodeResult:
    """Run one active search on ``case`` (see the module docstring).

    Args:
        case: the true scenario.
        estimator: any :class:`~dgse.belief.estimator.Estimator`.
        planner: any :class:`~dgse.planning.planners.Planner` (``reset()`` is called first).
        start: the start cell; None draws one (connected to the source, at
            least ``min_start_distance`` m from it by path).
        rng: the episode's seed or generator (see the module docstring).
        speed: robot speed, m/s.
        dwell: time per measurement, s (> 0).
        time_limit: s.
        include_compute_time: add each step's measured computation time to the clock.
        record: keep the belief maps per step (for the animation).
        use_frames: read the case's time-varying frames when it has them.
        noise_model: Table I ranges of the noise parameters (default :class:`NoiseModel`).
        noise_params: fixed noise parameters instead of a draw (e.g. ``NoiseParams.zero()``).
        min_start_distance: see ``start``.
        connectivity: 8 or 4 (:class:`~dgse.planning.paths.FreeSpaceGraph`).
        record_max_cells: recorded maps are block-averaged (the posterior
            block-summed) to at most this many cells.
        on_step: called with every step's record right after the step's
            decision (before the move); see :data:`StepCallback`.
        knowledge: what the estimator is told about ``case`` besides its readings
            (:mod:`dgse.belief.knowledge`: ``"map"``, ``"openings"``, ``"wind"``).
        sample_rate_hz: readings per second of travel on the way to each goal, estimated
            with the goal's reading, the planner deciding at the goal (module docstring);
            None: readings only at the goals (the paper's protocol).

    Returns:
        The :class:`EpisodeResult`.

    Raises:
        InputDataError: a bad time limit, dwell, ``record_max_cells`` or ``sample_rate_hz``.
        UnsupportedError: a knowledge level the estimator does not work at.
    """
    estimator.set_knowledge(Knowledge.from_case(case, knowledge))
    time_limit = float(time_limit)
    if not (math.isfinite(time_limit) and time_limit > 0):
        raise InputDataError(f"time limit must be a positive number of seconds, got {time_limit}")
    if not (math.isfinite(dwell) and dwell > 0):  # with no dwell a planner staying put would loop forever
        raise InputDataError(f"dwell must be a positive number of seconds, got {dwell}")
    if record_max_cells < 1:
        raise InputDataError(f"record_max_cells must be >= 1, got {record_max_cells}")
    sample_rate_hz = check_sample_rate(sample_rate_hz)
    start_rng, sensor_rng, planner_rng = episode_streams(rng)
    graph = graph_for(case.occupancy, case.resolution, connectivity)
    source_cell = case.source_cell
    if start is None:
        start = random_start_cell(graph, start_rng, source_cell, min_start_distance)
    robot = Robot(
        case,
        start=start,
        rng=sensor_rng,
        speed=speed,
        dwell=dwell,
        noise_model=noise_model,
        noise_params=noise_params,
        use_frames=use_frames,
        graph=graph,
        sample_rate_hz=sample_rate_hz,
    )
    planner.reset()
    stream = StreamingEstimator(estimator, case.occupancy, case.resolution)
    history = SearchHistory(graph=graph, rng=planner_rng, time_limit_s=time_limit)
    source_xy = (float(case.source[0]), float(case.source[1]))
    factor = _record_factor(graph.shape, int(record_max_cells))
    steps: list[StepRecord] = []
    belief: Belief | None = None
    reason = "time_limit"

    used = 0  # the robot's readings the estimates have had
    while robot.clock + robot.dwell <= time_limit:
        obs = robot.sense()
        new = robot.readings_since(used) if sample_rate_hz is not None else obs
        used += len(new)
        history.trajectory = robot.trajectory_cells
        history.time_s = robot.clock
        history.distance_m = robot.distance_m
        history.step = used
        decision = search_step(stream, planner, graph, history, new, robot.cell)
        belief, goal = decision.belief, decision.goal

        est = belief.source_estimate()
        rec = StepRecord(
            step=len(steps) + 1,
            cell=robot.cell,
            time_s=float(obs.times[0]) if obs.times is not None else robot.clock,
            gas=float(obs.gas[0]),
            wind=(float(obs.wind[0, 0]), float(obs.wind[0, 1])),
            entropy=belief.entropy(),
            normalized_entropy=belief.normalized_entropy(),
            estimate_xy=est,
            error_m=math.hypot(est[0] - source_xy[0], est[1] - source_xy[1]),
            preprocessing_s=decision.preprocessing_s,
            inference_s=decision.inference_s,
            planning_s=decision.planning_s,
            goal=goal,
            n_readings=len(new),
        )
        if record:
            rec.source_probs = _block_reduce(belief.source_probs, factor, "sum")
            if belief.wind_mean is not None:
                rec.wind_mean = _block_reduce(belief.wind_mean, factor, "mean")
            if belief.log_conc_mean is not None:
                rec.log_conc_mean = _block_reduce(belief.log_conc_mean, factor, "mean")
        steps.append(rec)
        if on_step is not None:
            on_step(rec)

        if include_compute_time:
            robot.wait(rec.compute_s, until=time_limit)
        if decision.reason is not None:
            reason = decision.reason
            break
        if robot.clock >= time_limit or goal is None:
            break
        robot.move_to(goal, until=time_limit)

    if reason == "time_limit":
        search_time = time_limit
    else:
        search_time = robot.clock
    end_errors: dict[str, float] = {}
    if belief is None:
        estimate = _free_centroid(case)
    else:
        estimate = planner.declare(belief, reason == "deadline")
        for name, (x, y) in point_estimates(belief).items():
            end_errors[name] = math.hypot(x - source_xy[0], y - source_xy[1])
    return EpisodeResult(
        case_name=case.name,
        method=_estimator_name(estimator, belief),
        planner=planner.name,
        source_xy=source_xy,
        source_cell=source_cell,
        start_cell=robot.start,
        estimate_xy=estimate,
        error_m=math.hypot(estimate[0] - source_xy[0], estimate[1] - source_xy[1]),
        reason=reason,
        search_time_s=float(search_time),
        distance_m=float(robot.distance_m),
        shortest_path_m=graph.distance(robot.start, source_cell),
        time_limit_s=time_limit,
        steps=steps,
        trajectory_cells=robot.trajectory_cells,
        trajectory_times=robot.trajectory_times,
        record_factor=factor,
        resolution=case.resolution,
        settings={
            "speed": robot.speed,
            "dwell": robot.dwell,
            "include_compute_time": bool(include_compute_time),
            "use_frames": bool(use_frames and case.frames is not None),
            "connectivity": graph.connectivity,
            "noise": robot.noise_params.to_dict(),
            **({} if sample_rate_hz is None else {"sample_rate_hz": sample_rate_hz}),
        },
        end_errors_m=end_errors,
        readings=stream.observations,
    )
