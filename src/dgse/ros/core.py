"""The search on a robot, without ROS: maps, readings, decisions (the nodes are thin shells).

:class:`SearchCore` is what ``dgse ros run`` does with the messages it gets, as plain
Python (the node of :mod:`dgse.ros.nodes` only converts messages and publishes):

* **map**: an occupancy grid in the map frame (:class:`MapGrid`: cells, cell size,
  origin) becomes the method's occupancy (:func:`method_occupancy`: occupied where a cell
  is at least ``occupied_threshold``, unknown cells solid, resampled by a whole factor to
  the method's cell size, anything else refused with a message); the first map starts the
  search, one of another shape, cell size or origin restarts it with a warning;
* **pose**: the robot's position in the map frame gives its cell; it *arrives* at the
  goal when its cell is the goal's;
* **readings**: a gas reading (ppm) pairs with the latest wind reading (m/s, map frame);
  the pair's time is the older of the two. The search takes a reading once the robot has
  been at its goal for the dwell time (:attr:`SearchProtocol.dwell`): the first pair
  whose time is at least the arrival plus the dwell (a gas reading that comes before
  its wind waits for it). With a sample rate (``sample_rate_hz``, as ``dgse search``'s
  readings on the way), the pairs that come while the robot drives count too, one per
  ``1 / sample_rate_hz`` s at most, at the cell of the latest pose; they wait for the next
  goal's reading and go into the estimator with it (one estimate, one decision). Those are
  the gas readings stamped after the last reading taken and no later than the arrival at
  the goal, each at the cell of the latest pose and with the latest wind reading (no older
  than the sampling period) of its stamp: the messages of three topics can come in any
  order, so they are matched by their stamps once the goal's reading is taken. Readings
  at other times are not used;
* **decision**: the reading goes through :func:`dgse.search.episode.search_step` (the
  same estimator, stop test and planner as ``dgse search``), which gives the next goal or
  the stop and its reason (:data:`dgse.search.episode.REASONS`); a goal the navigation
  refuses (:meth:`SearchCore.goal_rejected`) is replaced by the planner's next choice
  without it.

Times are seconds on one clock (the ROS clock of the messages: sim time when the node
uses ``use_sim_time``); the search's clock starts at the first pose. Problems in the input
(a reading before any map, a pose off the map, a NaN reading, a map that changes) are
logged through ``log(level, message)`` and the core keeps going.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from dgse.belief.belief import Belief
from dgse.belief.estimator import StreamingEstimator
from dgse.belief.knowledge import DEFAULT_LEVEL, Knowledge, check_level
from dgse.errors import InputDataError
from dgse.files import json_safe
from dgse.planning.paths import Cell, FreeSpaceGraph, graph_for
from dgse.planning.planners import Planner, SearchHistory, get_planner
from dgse.presets import PROTOCOL, ResolvedMethod, resolve
from dgse.sensing.sensors import Observations

__all__ = [
    "Decision",
    "Log",
    "MapGrid",
    "MethodSetup",
    "SearchCore",
    "method_occupancy",
]

#: ``log(level, message)``: ``level`` is ``"info"``, ``"warning"`` or ``"error"``.
Log = Callable[[str, str], None]

#: A clock this far ahead of the latest pose's stamp is another clock (wall time beside a
#: simulation's stamps), s.
CLOCK_MISMATCH_S = 3600.0

#: Readings this much older than the arrival plus the dwell still count (clock rounding), s.
TIME_TOLERANCE_S = 1e-3


def _quiet(level: str, message: str) -> None:
    """The default log: nothing."""


@dataclass(frozen=True)
class MapGrid:
    """An occupancy grid in the map frame, as ``nav_msgs/OccupancyGrid`` holds it.

    Attributes:
        values: ``int (H, W)``, row ``i`` along y: -1 unknown, 0 free ... 100 occupied.
        resolution: cell size, m.
        origin: the map frame's ``(x, y)`` of the lower-left corner of cell ``(0, 0)``, m.
        frame_id: the map's frame.
    """

    values: np.ndarray
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)
    frame_id: str = "map"

    def __post_init__(self) -> None:
        v = np.asarray(self.values)
        if v.ndim != 2 or min(v.shape) < 1:
            raise InputDataError(f"the map must be a 2-D grid, got shape {v.shape}")
        res = float(self.resolution)
        if not (math.isfinite(res) and res > 0):
            raise InputDataError(f"the map's resolution must be a positive number of metres, got {res}")
        if not all(math.isfinite(float(c)) for c in self.origin):
            raise InputDataError(f"the map's origin must be finite, got {self.origin}")
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "resolution", res)
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))

    @classmethod
    def from_occupancy(
        cls, occupancy: np.ndarray, resolution: float, origin: tuple[float, float] = (0.0, 0.0), **kw: Any
    ) -> MapGrid:
        """A map of a DGSE occupancy (1 solid, 0 free): 100 and 0."""
        return cls(np.where(np.asarray(occupancy) != 0, 100, 0).astype(np.int8), resolution, origin, **kw)


def method_occupancy(
    grid: MapGrid,
    resolution: float | None = None,
    *,
    occupied_threshold: int = 50,
    unknown_solid: bool = True,
) -> tuple[np.ndarray, float]:
    """The occupancy ``uint8 (h, w)`` (1 solid) of ``grid`` at the method's cell size.

    Args:
        resolution: the method's cell size, m (None: the map's). A whole multiple of the
            map's merges blocks (solid where most of a block is, so a one-cell wall
            between free blocks does not close a door); a whole fraction splits cells.
        occupied_threshold: a cell is solid from this value on (0-100).
        unknown_solid: unknown cells (-1) are solid (else free).

    Raises:
        InputDataError: a cell size that is neither a whole multiple nor a whole fraction
            of the map's, or a map that does not divide into the blocks.
    """
    from dgse.world.grid import coarsen, refine_occupancy, refinement_factor

    v = grid.values
    solid = (v >= occupied_threshold) | ((v < 0) & unknown_solid)
    occ = solid.astype(np.uint8)
    if resolution is None or math.isclose(resolution, grid.resolution, rel_tol=1e-6):
        return occ, grid.resolution
    up = refinement_factor(resolution, grid.resolution)
    if up is not None:  # coarser cells: majority of each block
        H, W = occ.shape
        if H % up or W % up:
            occ = np.pad(occ, ((0, -H % up), (0, -W % up)), constant_values=1)
        return (coarsen(occ.astype(np.float64), up, "mean") > 0.5).astype(np.uint8), float(resolution)
    down = refinement_factor(grid.resolution, resolution)
    if down is not None:
        return refine_occupancy(occ, down), float(resolution)
    raise InputDataError(
        f"the map's cells of {grid.resolution:g} m cannot be resampled to the method's {resolution:g} m "
        "(give a resolution that is a whole multiple or fraction of the map's)"
    )


@dataclass(frozen=True)
class MethodSetup:
    """What a search runs: the method resolved at a knowledge level, and its seeds.

    Attributes:
        method: the resolved method (:func:`dgse.presets.resolve`).
        estimator_options: the estimator's keyword arguments (the campaign's seed included).
        knowledge_file: a case or layout file with what the user knows beyond the map
            (openings; a case's wind field at ``wind``); its grid must be the robot's map.
        resolution: the method's cell size, m (None: the map's).
        dwell: time at a goal before a reading counts, s.
        time_limit: the search's time limit, s.
        sample_rate_hz: readings per second taken on the way to a goal (module docstring);
            None: only the reading at each goal, as the paper's protocol.
        planner_seed: the planner's random stream (``dgse search``'s third stream of the
            trial's seed, :func:`dgse.search.episode.episode_streams`).
        connectivity: the move graph's (8 or 4).
    """

    method: ResolvedMethod
    estimator_options: Mapping[str, Any] = field(default_factory=dict)
    knowledge_file: Path | None = None
    resolution: float | None = None
    dwell: float = PROTOCOL.dwell
    time_limit: float = PROTOCOL.time_limit
    sample_rate_hz: float | None = PROTOCOL.sample_rate_hz
    planner_seed: np.random.Generator | np.random.SeedSequence | int | None = None
    connectivity: int = 8

    @classmethod
    def create(
        cls,
        method: str | None = None,
        knowledge: str = DEFAULT_LEVEL,
        *,
        seed: int = 0,
        case_name: str | None = None,
        trial: int = 0,
        estimator_options: Mapping[str, Any] | None = None,
        planner_options: Mapping[str, Any] | None = None,
        planner: str | None = None,
        **kw: Any,
    ) -> MethodSetup:
        """Resolve ``method`` (None: the default) as ``dgse search`` does, seeded like its trial
        ``trial`` of the case named ``case_name`` with ``--seed seed`` (no name: ``seed`` alone)."""
        from dgse.search.campaign import estimator_options as campaign_options
        from dgse.search.campaign import trial_seed
        from dgse.search.episode import episode_streams

        level = check_level(knowledge)
        run = resolve(method, level, search=True, planner=planner, planner_options=planner_options)
        est = campaign_options(
            run.estimator, seed=seed, options={**run.estimator_options, **(estimator_options or {})}
        )
        ss = trial_seed(seed, case_name, trial) if case_name else np.random.SeedSequence(seed)
        return cls(run, est, planner_seed=episode_streams(ss)[2], **kw)

    @classmethod
    def from_parameters(cls, p: Mapping[str, Any]) -> MethodSetup:
        """The setup named by the node's parameters (:data:`dgse.ros.nodes.RUN_PARAMETERS`'s
        ``method``, ``knowledge``, ``knowledge_file``, ``seed``, ``case_name``, ``trial``,
        ``resolution``, ``dwell``, ``time_limit``, ``sample_rate_hz``; empty strings and 0 mean
        unset)."""
        from dgse.search.robot import check_sample_rate

        return cls.create(
            p.get("method") or None,
            p.get("knowledge") or DEFAULT_LEVEL,
            seed=int(p.get("seed", 0)),
            case_name=p.get("case_name") or None,
            trial=int(p.get("trial", 0)),
            knowledge_file=Path(p["knowledge_file"]) if p.get("knowledge_file") else None,
            resolution=float(p.get("resolution") or 0.0) or None,
            dwell=float(p.get("dwell", PROTOCOL.dwell)),
            time_limit=float(p.get("time_limit", PROTOCOL.time_limit)),
            sample_rate_hz=check_sample_rate(float(p.get("sample_rate_hz") or 0.0) or None),
        )

    def knowledge(self, occupancy: np.ndarray, resolution: float) -> Knowledge:
        """What the estimator is told on this map at the method's level."""
        level = self.method.level
        if level == "map":
            return Knowledge("map", occupancy, resolution, name="robot map")
        if self.knowledge_file is None:
            raise InputDataError(f"knowledge level {level!r} needs a knowledge file (a case or layout file)")
        from dgse.world.layout_io import load_layout, npz_kind

        path = Path(self.knowledge_file)
        if npz_kind(path) == "case":
            from dgse.world.case import Case

            case = Case.load(path)
            layout, wind, v_in = case.layout, case.wind, case.inlet_velocity
        else:
            layout, wind, v_in = load_layout(path), None, None
        if layout.occupancy.shape != occupancy.shape:
            raise InputDataError(
                f"{path.name}: its grid is {layout.occupancy.shape[1]} x {layout.occupancy.shape[0]} cells, "
                f"the robot's map {occupancy.shape[1]} x {occupancy.shape[0]}"
            )
        if level == "openings":
            return Knowledge("openings", occupancy, resolution, layout.inlets, layout.outlets, name=path.stem)
        if wind is None:
            raise InputDataError(f"{path.name} is a layout file: knowledge level 'wind' needs a case file")
        wind = np.where(occupancy[None] != 0, 0.0, wind)
        return Knowledge(
            "wind", occupancy, resolution, layout.inlets, layout.outlets, wind, v_in, name=path.stem
        )


@dataclass(frozen=True)
class Decision:
    """What the search did with a reading (or a refused goal).

    Attributes:
        step: the number of readings taken so far.
        cell: where the reading was taken (method grid).
        time_s: the reading's time on the search's clock (0 at the first pose), s.
        gas, wind: the reading, ppm and m/s.
        belief: the belief after it.
        goal: the next cell, or None when the search ends.
        goal_xy: the goal's centre in the map frame, m.
        reason: why the search ends (:data:`dgse.search.episode.REASONS`), or None.
        declared_xy: the declared source in the map frame (when it ends; else the
            belief's mean), m.
        compute_s: the step's computation time (estimate, stop test, plan), s.
    """

    step: int
    cell: Cell
    time_s: float
    gas: float
    wind: tuple[float, float]
    belief: Belief
    goal: Cell | None
    goal_xy: tuple[float, float] | None
    reason: str | None
    declared_xy: tuple[float, float]
    compute_s: float

    def to_dict(self) -> dict[str, Any]:
        """The fields but the belief, and the belief's normalized entropy, JSON-able."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "belief"}
        out["entropy"] = self.belief.normalized_entropy()
        return json_safe(out)


class SearchCore:
    """A search fed by messages as they come (module docstring).

    Args:
        setup: the method and its settings.
        log: where problems and events go (default: nowhere).
        occupied_threshold, unknown_solid: how map values become walls (:func:`method_occupancy`).
        follow_goals: take the goals from :meth:`set_goal` (a recorded run) instead of the
            planner: the estimator alone runs on the readings (``dgse ros replay``).
    """

    def __init__(
        self,
        setup: MethodSetup,
        log: Log = _quiet,
        *,
        occupied_threshold: int = 50,
        unknown_solid: bool = True,
        follow_goals: bool = False,
    ) -> None:
        self.setup = setup
        self.log = log
        self.occupied_threshold = int(occupied_threshold)
        self.unknown_solid = bool(unknown_solid)
        self.follow_goals = bool(follow_goals)
        self.map: MapGrid | None = None
        self.restarts = 0
        self._clock_warned = False
        self._rng = np.random.default_rng(setup.planner_seed)
        self._reset_search()

    # -- state ---------------------------------------------------------------------------
    def _reset_search(self) -> None:
        self.occupancy: np.ndarray | None = None
        self.resolution = 0.0
        self.graph: FreeSpaceGraph | None = None
        self.stream: StreamingEstimator | None = None
        self.planner: Planner | None = None
        self.history: SearchHistory | None = None
        self.decisions: list[Decision] = []
        self.cell: Cell | None = None
        self.xy: tuple[float, float] | None = None
        self.target: Cell | None = None
        self.arrived_at: float | None = None
        self.entered_at: float | None = None
        self.t_start: float | None = None
        self.last_time: float | None = None
        self.distance_m = 0.0
        self.trajectory: list[Cell] = []
        self.wind: tuple[float, float, float] | None = None
        self.pending: tuple[float, float] | None = None
        # since the last reading taken, with readings on the way: gas (t, ppm), poses
        # (t, cell) with the one before, winds (t, u, v)
        self.gas_log: list[tuple[float, float]] = []
        self.pose_log: list[tuple[float, Cell]] = []
        self.wind_log: list[tuple[float, float, float]] = []
        self.rejected: list[Cell] = []
        self.latest_time = -math.inf
        self.reason: str | None = None
        self.declared_xy: tuple[float, float] | None = None

    @property
    def ready(self) -> bool:
        """A map is set and the search runs."""
        return self.stream is not None

    @property
    def stopped(self) -> bool:
        """The search has ended (:attr:`reason` says why)."""
        return self.reason is not None

    @property
    def belief(self) -> Belief | None:
        """The latest belief (None before the first reading)."""
        return self.decisions[-1].belief if self.decisions else None

    # -- frames --------------------------------------------------------------------------
    def cell_of(self, x: float, y: float) -> Cell | None:
        """The method-grid cell of map-frame point ``(x, y)`` m, or None off the map."""
        if self.map is None or self.occupancy is None:
            return None
        ox, oy = self.map.origin
        j = math.floor((x - ox) / self.resolution)
        i = math.floor((y - oy) / self.resolution)
        H, W = self.occupancy.shape
        return (i, j) if 0 <= i < H and 0 <= j < W else None

    def center_of(self, cell: Cell) -> tuple[float, float]:
        """The map-frame centre of method-grid cell ``(i, j)``, m."""
        assert self.map is not None
        ox, oy = self.map.origin
        return (ox + (cell[1] + 0.5) * self.resolution, oy + (cell[0] + 0.5) * self.resolution)

    def to_map_frame(self, xy: tuple[float, float]) -> tuple[float, float]:
        """A grid position (m from the grid's corner, as beliefs give them) in the map frame."""
        assert self.map is not None
        return (self.map.origin[0] + xy[0], self.map.origin[1] + xy[1])

    # -- inputs --------------------------------------------------------------------------
    def set_map(self, grid: MapGrid) -> bool:
        """Use ``grid`` (module docstring). Returns True when the search (re)started."""
        old = self.map
        if old is not None and (
            old.values.shape == grid.values.shape
            and math.isclose(old.resolution, grid.resolution)
            and np.allclose(old.origin, grid.origin)
        ):
            return False
        try:
            occ, res = method_occupancy(
                grid,
                self.setup.resolution,
                occupied_threshold=self.occupied_threshold,
                unknown_solid=self.unknown_solid,
            )
            if not (occ == 0).any():
                raise InputDataError("the map has no free cell")
            knowledge = self.setup.knowledge(occ, res)
            m = self.setup.method
            estimator = _make_estimator(m.estimator, self.setup.estimator_options)
            estimator.set_knowledge(knowledge)
            planner = get_planner(m.planner, **m.planner_options)
        except InputDataError as e:
            self.log("error", f"map refused: {e}")
            return False
        if old is not None:
            self.restarts += 1
            self.log(
                "warning",
                f"the map changed ({_size(old)} -> {_size(grid)}): the search starts again",
            )
        self._reset_search()
        self.map = grid
        self.occupancy, self.resolution = occ, res
        self.graph = graph_for(occ, res, self.setup.connectivity)
        planner.reset()
        self.planner = planner
        self.stream = StreamingEstimator(estimator, occ, res)
        self.history = SearchHistory(graph=self.graph, rng=self._rng, time_limit_s=self.setup.time_limit)
        H, W = occ.shape
        self.log("info", f"map: {W} x {H} cells of {res:g} m, origin {grid.origin}; method {m.method}")
        return True

    def set_pose(self, x: float, y: float, t: float) -> None:
        """The robot is at map-frame ``(x, y)`` m at time ``t`` s."""
        if not self.ready:
            self.log("warning", "pose before any map: ignored")
            return
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(t)):
            self.log("warning", f"a non-finite pose ({x}, {y}) at {t}: ignored")
            return
        cell = self.cell_of(x, y)
        if cell is None:
            self.log("warning", f"pose ({x:.2f}, {y:.2f}) m lies outside the map: ignored")
            return
        assert self.occupancy is not None
        if self.occupancy[cell]:
            self.log("warning", f"pose ({x:.2f}, {y:.2f}) m lies in a wall of the map: ignored")
            return
        self.latest_time = max(self.latest_time, t)
        if self.xy is not None:
            self.distance_m += math.hypot(x - self.xy[0], y - self.xy[1])
        self.xy = (x, y)
        if self.t_start is None:  # the search's clock starts at the first pose, its start
            self.t_start = t
            self.target = cell
        if cell != self.cell:
            if self.setup.sample_rate_hz is not None:
                self.pose_log.append((t, cell))
            self.trajectory.append(cell)
            self.cell = cell
            self.entered_at = t
            self.pending = None
            if cell != self.target:
                self.arrived_at = None
        if cell == self.target and self.arrived_at is None:
            self.arrived_at = t

    def set_wind(self, u: float, v: float, t: float) -> Decision | None:
        """A wind reading ``(u, v)`` m/s in the map frame at time ``t`` s: the decision it made
        with a gas reading that waited for it, if any."""
        if not (math.isfinite(u) and math.isfinite(v)):
            self.log("warning", f"a non-finite wind reading ({u}, {v}) m/s: ignored")
            return None
        self.wind = (float(u), float(v), float(t))
        if self.setup.sample_rate_hz is not None:
            self.wind_log.append((float(t), float(u), float(v)))
        if self.pending is None:
            return None
        ppm, t_gas = self.pending
        self.pending = None
        return self.add_gas(ppm, t_gas)

    def set_goal(self, x: float, y: float) -> None:
        """The goal the robot was sent to (``follow_goals``: a recorded run's goal message)."""
        cell = self.cell_of(x, y)
        if cell is None:
            self.log("warning", f"goal ({x:.2f}, {y:.2f}) m lies outside the map: ignored")
            return
        self.target = cell
        self.arrived_at = self.entered_at if cell == self.cell else None

    def add_gas(self, ppm: float, t: float) -> Decision | None:
        """A gas reading ``ppm`` at time ``t`` s: the decision it made, if the search took it."""
        if not math.isfinite(ppm):
            self.log("warning", f"a non-finite gas reading ({ppm}): ignored")
            return None
        if not self.ready:
            self.log("warning", "gas reading before any map: ignored")
            return None
        if self.stopped:
            return None
        if self.cell is None or self.t_start is None:
            self.log("warning", "gas reading before any pose: ignored")
            return None
        if self.setup.sample_rate_hz is not None:
            self.gas_log.append((float(t), float(ppm)))  # perhaps one on the way (module docstring)
        if self.target != self.cell or self.arrived_at is None:
            return None
        due = self.arrived_at + self.setup.dwell - TIME_TOLERANCE_S
        if t < due:
            return None
        if self.wind is None or self.wind[2] < due:  # its wind reading has not come yet
            if self.wind is None:
                self.log("warning", "gas reading before any wind reading: waiting for one")
            self.pending = (float(ppm), float(t))
            return None
        u, v, t_wind = self.wind
        t_read = min(float(t), t_wind)
        if self.last_time is not None and t_read <= self.last_time:
            return None
        return self._take(float(ppm), (u, v), t_read)

    def _on_the_way(self) -> list[tuple[Cell, float, tuple[float, float], float]]:
        """The readings on the way to the current goal (module docstring): ``(cell, ppm, wind,
        t)`` in time order, one per sampling period at most; the logs are emptied."""
        rate = self.setup.sample_rate_hz
        gas, poses, winds = sorted(self.gas_log), self.pose_log, sorted(self.wind_log)
        self.gas_log, self.wind_log = [], []
        self.pose_log = poses[-1:]
        if rate is None or self.arrived_at is None:
            return []
        period = 1.0 / rate
        out: list[tuple[Cell, float, tuple[float, float], float]] = []
        last = self.last_time
        for t, ppm in gas:
            if t > self.arrived_at + TIME_TOLERANCE_S:
                break
            if last is not None and t < last + period - TIME_TOLERANCE_S:
                continue
            at = [c for tp, c in poses if tp <= t + TIME_TOLERANCE_S]
            near = [w for w in winds if t - period <= w[0] <= t + TIME_TOLERANCE_S]
            if not at or not near:  # no pose or no wind reading of that moment
                continue
            _, u, v = near[-1]
            out.append((at[-1], ppm, (u, v), t))
            last = t
        return out

    def _take(self, ppm: float, wind: tuple[float, float], t: float) -> Decision:
        from dgse.search.episode import search_step

        assert self.stream and self.history is not None and self.planner and self.graph and self.cell
        assert self.t_start is not None
        clock = t - self.t_start
        taken = [*self._on_the_way(), (self.cell, ppm, wind, t)]
        reading = Observations(
            np.array([c for c, *_ in taken], np.int64).reshape(-1, 2),
            np.array([g for _, g, _, _ in taken], np.float64),
            np.array([w for *_, w, _ in taken], np.float64).reshape(-1, 2),
            np.array([tr - self.t_start for *_, tr in taken], np.float64),
        )
        h = self.history
        h.trajectory = np.array(self.trajectory, np.int64).reshape(-1, 2)
        h.time_s, h.distance_m, h.step = clock, self.distance_m, len(self.stream.observations) + len(taken)
        self.last_time = t
        self.rejected = []
        if self.follow_goals:
            t0 = time.perf_counter()
            self.stream.add(reading)
            h.observations = self.stream.observations
            belief = self.stream.belief
            return self._record(ppm, wind, clock, belief, None, None, time.perf_counter() - t0)
        step = search_step(self.stream, self.planner, self.graph, h, reading, self.cell)
        compute = step.compute_s
        return self._record(ppm, wind, clock, step.belief, step.goal, step.reason, compute)

    def _record(
        self,
        ppm: float,
        wind: tuple[float, float],
        clock: float,
        belief: Belief,
        goal: Cell | None,
        reason: str | None,
        compute: float,
    ) -> Decision:
        assert self.cell is not None and self.planner is not None
        if reason is not None:
            self.reason = reason
            declared = self.to_map_frame(self.planner.declare(belief, reason == "deadline"))
            self.declared_xy = declared
            self.log(
                "info",
                f"search ended ({reason}): source declared at ({declared[0]:.2f}, {declared[1]:.2f}) m",
            )
        else:
            declared = self.to_map_frame(belief.source_estimate())
        d = Decision(
            step=len(self.stream.observations),
            cell=self.cell,
            time_s=clock,
            gas=ppm,
            wind=wind,
            belief=belief,
            goal=goal,
            goal_xy=None if goal is None else self.center_of(goal),
            reason=reason,
            declared_xy=declared,
            compute_s=compute,
        )
        self.decisions.append(d)
        if goal is not None:
            self.target = goal
            self.arrived_at = self.last_time if goal == self.cell else None
        return d

    def goal_rejected(self) -> Decision | None:
        """The navigation refused the current goal: the planner's next choice without it."""
        if not self.decisions or self.stopped or self.follow_goals:
            return None
        last = self.decisions[-1]
        if last.goal is None:
            return None
        from dgse.search.episode import search_step

        assert self.stream and self.history is not None and self.planner and self.graph and self.cell
        self.rejected.append(last.goal)
        self.log("warning", f"goal {last.goal} refused by the navigation: choosing another")
        step = search_step(
            self.stream, self.planner, self.graph, self.history, Observations.empty(), self.cell,
            excluded=self.rejected,
        )  # fmt: skip
        reason = step.reason
        compute = step.compute_s
        self.decisions.pop()
        return self._record(last.gas, last.wind, last.time_s, step.belief, step.goal, reason, compute)

    def check_time(self, now: float) -> str | None:
        """End the search at the time limit (``now`` on the messages' clock); the reason if it ended."""
        if self.stopped or self.t_start is None:
            return None
        limit, dwell = self.setup.time_limit, self.setup.dwell
        if now - self.latest_time > CLOCK_MISMATCH_S:
            if not self._clock_warned:
                self._clock_warned = True
                self.log(
                    "warning",
                    "the clock is far ahead of the messages' stamps: with a simulation, use its clock "
                    "(use_sim_time, dgse ros run --sim-time); no time limit until then",
                )
            return None
        if self.arrived_at is not None and self.arrived_at - self.t_start + dwell <= limit:
            return None  # a reading that fits is on its way
        if now - self.t_start + dwell <= limit:
            return None
        self.reason = "time_limit"
        belief = self.belief
        if belief is not None:
            self.declared_xy = self.to_map_frame(belief.source_estimate())
        self.log("info", "search ended (time_limit)")
        return self.reason

    def status(self) -> dict[str, Any]:
        """What the status topic says: state, steps, the reason and the declared source."""
        state = "stopped" if self.stopped else "searching" if self.ready else "waiting for a map"
        last = self.decisions[-1] if self.decisions else None
        return {
            "state": state,
            "reason": self.reason,
            "steps": len(self.decisions),
            "restarts": self.restarts,
            "time_s": None if last is None else last.time_s,
            "normalized_entropy": None if last is None else last.belief.normalized_entropy(),
            "estimate_xy": None if last is None else list(last.declared_xy),
            "declared_xy": None if self.declared_xy is None else list(self.declared_xy),
            "goal": None if last is None or last.goal is None else list(last.goal_xy or ()),
            "method": self.setup.method.method,
        }


def _size(grid: MapGrid) -> str:
    H, W = grid.values.shape
    return f"{W} x {H} cells of {grid.resolution:g} m at {grid.origin}"


def _make_estimator(name: str, options: Mapping[str, Any]):
    from dgse.estimators.registry import get_estimator

    return get_estimator(name, **dict(options))
