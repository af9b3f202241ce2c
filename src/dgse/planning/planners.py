"""Planners: where the robot measures next, and when the search stops.

A :class:`Planner` is asked once per search step, after the estimator has
turned all readings so far into a :class:`~dgse.belief.belief.Belief`:

1. ``should_stop(belief, history)``: the planner's termination test (for
   :class:`UtilityPlanner` the paper's entropy test); True ends the search;
2. otherwise ``next_goal(belief, robot_cell, distances, history)``: the next
   cell to move to and measure at, or None to end the search (a planner with
   nothing left to do).

``distances`` is the ``(H, W)`` shortest obstacle-free path length in m from
the robot's cell (``inf`` on walls and unreachable cells);
:class:`SearchHistory` gives everything else (all readings, the trajectory,
the clock, the move graph for planners that need paths, and a random
generator for stochastic planners).  ``reset()`` is called at the start of
every episode.

Planners are registered by name (:func:`get_planner`, :func:`register_planner`;
lazy ``"module:function"`` factories allowed): ``"utility"`` is built in;
the baselines' planners (Infotaxis, PMFS, dual-mode) register themselves
the same way.

:class:`UtilityPlanner` is the paper's Sec. III-D planner (Algorithm 1):

``U_i = exp(-w_d dist_i) (w_w sigma_w,i^2 + w_c sigma_c,i^2 + w_s pi_s,i)``

with ``(w_d, w_w, w_c, w_s) = (0.1, 0.25, 2.0, 100.0)`` and the termination
``H(pi_s) <= eta log N`` (``eta = 0.65``, ``N`` = the belief's candidate
cells, i.e. the free cells of the map; the paper's "dimension of the source
posterior").  Its settings are two objects (:class:`UtilityWeights`,
:class:`StopRule`), each field settable by a dotted key (``-P stop.eta=0.75``);
the defaults are the paper's rule.  Decisions on what the paper leaves open:

* ``sigma_w^2 = var(u_x) + var(u_y)`` (the belief's ``wind_var`` summed over
  its two components), in (m/s)^2;
* ``sigma_c^2`` is the variance of ``log(1 + c)`` (the belief's
  ``log_conc_var``; DGSE-S's moment-matched ``sigma_c^2`` lives in that
  space, and in ppm^2 the term would swamp the others by orders of magnitude);
* of a belief whose variance also holds a model error that readings do not
  shrink (``dgse-phys``), only the part readings can reduce enters
  (:attr:`~dgse.belief.belief.Belief.wind_var_reducible`): a variance that
  stays however often the robot measures says nothing about where to measure;
* a belief without a wind or concentration variance (DGSE-O, most baselines)
  contributes 0 for that term;
* ``dist_i`` is the path length in metres (the paper does not give the unit);
* candidates are the free cells reachable from the robot, except the robot's
  own cell (moving nowhere would repeat the same measurement) and the cells
  where the robot has already measured;
  when that leaves nothing, measured cells are allowed again; when even that
  leaves nothing (a one-cell map), ``next_goal`` returns None;
* ties (utilities equal to a relative ``1e-12``): the nearest cell by path
  length, then the lowest row-major index;
* ``stop.min_observations`` (default 0, the paper's rule): the entropy test waits
  for that many readings.  A network trained on 5 to 300 readings (the
  paper's range, ``dgse.sensing.sensors.MIN_SENSORS``) has never seen fewer
  than 5, and the shipped DGSE-S can be confidently wrong after one
  (``benchmarks/training.py few-readings``).  ``dgse demo`` and the search benchmark
  pass ``MIN_SENSORS``.

:class:`Deadline` is a stop before the time limit and what such a stop declares, for
planners with a time budget (the information planner, :mod:`dgse.planning.information`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dgse.belief.belief import Belief
from dgse.errors import InputDataError, UnsupportedError
from dgse.options import Settings
from dgse.planning.paths import Cell, FreeSpaceGraph
from dgse.registry import Entry, Registry
from dgse.sensing.sensors import Observations

__all__ = [
    "Deadline",
    "Planner",
    "PlannerBase",
    "PlannerFactory",
    "SearchHistory",
    "StopRule",
    "UtilityPlanner",
    "UtilityWeights",
    "get_planner",
    "mass_within",
    "planner_names",
    "register_planner",
]


@dataclass
class SearchHistory:
    """What a planner may know about the search so far (updated by the search loop each step).

    Attributes:
        graph: the map's move graph (paths and distances between any cells).
        observations: all readings so far, in order (cells, gas, wind, times).
        trajectory: ``int64 (n, 2)`` every cell the robot entered, from the start.
        time_s: the robot's clock, s.
        distance_m: distance travelled so far, m.
        step: the number of readings so far (1 at the first decision; with readings on the
            way to the goals, :mod:`dgse.search.episode`, those count too).
        rng: the planner's random generator (seeded per episode).
        time_limit_s: the search's time limit, s (``inf``: none).
    """

    graph: FreeSpaceGraph
    observations: Observations = field(default_factory=Observations.empty)
    trajectory: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    time_s: float = 0.0
    distance_m: float = 0.0
    step: int = 0
    rng: np.random.Generator = field(default_factory=np.random.default_rng)
    time_limit_s: float = math.inf

    @property
    def measured(self) -> np.ndarray:
        """``bool (H, W)``: cells with at least one reading."""
        m = np.zeros(self.graph.shape, dtype=bool)
        c = self.observations.cells
        if len(c):
            m[c[:, 0], c[:, 1]] = True
        return m


@runtime_checkable
class Planner(Protocol):
    """Chooses the next measurement cell and decides when to stop.

    Attributes:
        name: the planner's name (as registered).
    """

    name: str

    def reset(self) -> None:
        """Forget any state of a previous episode (called before each episode)."""
        ...

    def should_stop(self, belief: Belief, history: SearchHistory) -> bool:
        """True when the search should end now with ``belief`` as the final belief."""
        ...

    def next_goal(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory
    ) -> Cell | None:
        """The next cell ``(i, j)`` to move to and measure at (free, reachable), or None to stop.

        Args:
            belief: the current belief (all readings so far).
            robot_cell: the robot's cell.
            distances: ``(H, W)`` path lengths in m from ``robot_cell`` (``inf`` = unreachable).
            history: the search so far.
        """
        ...

    def deadline_reached(self, history: SearchHistory) -> bool:
        """Whether a stop now is a deadline stop (the time budget is nearly spent), not a
        confident one; episodes end such a stop with reason ``"deadline"``."""
        ...

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The source ``(x, y)``, m, the search declares when it ends with ``belief``
        (``deadline``: at a deadline stop)."""
        ...

    def describe_stop(self) -> str:
        """The stop test in words, for a progress line ("stops when ...")."""
        ...


class PlannerBase:
    """What a planner without these rules does: no deadline stops, and the belief's posterior
    mean as the declared source.  Planners derive from it and override what they decide
    otherwise."""

    def reset(self) -> None:
        """Nothing to forget."""

    def deadline_reached(self, history: SearchHistory) -> bool:
        """Has no deadline stop."""
        return False

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The posterior mean (:meth:`~dgse.belief.belief.Belief.source_estimate`)."""
        return belief.source_estimate()

    def describe_stop(self) -> str:
        """The planner's own stop test, unnamed."""
        return "its own stop test passes"


def _radius_or_none(name: str, value: float | None) -> float | None:
    """A planner option that is None or a positive, finite number of m."""
    if value is None:
        return None
    r = float(value)
    if not (math.isfinite(r) and r > 0):
        raise InputDataError(f"{name} must be a positive number of m or None, got {r}")
    return r


def _count(name: str, value: int, least: int) -> int:
    """A planner option that is an integer ``>= least``."""
    if isinstance(value, bool) or int(value) != value:
        raise InputDataError(f"{name} must be an integer, got {value!r}")
    if value < least:
        raise InputDataError(f"{name} must be >= {least}, got {value}")
    return int(value)


def mass_within(probs: np.ndarray, resolution: float, radius_m: float) -> np.ndarray:
    """``float64 (H, W)``: the mass of ``probs`` within ``radius_m`` of each cell's centre (walls ignored)."""
    from scipy.signal import fftconvolve

    r = math.floor(radius_m / resolution + 1e-9)
    ii, jj = np.mgrid[-r : r + 1, -r : r + 1]
    disk = (np.hypot(ii, jj) * resolution <= radius_m + 1e-9).astype(np.float64)
    out = fftconvolve(np.asarray(probs, dtype=np.float64), disk, mode="same")
    return np.maximum(out, 0.0)


@dataclass(frozen=True)
class UtilityWeights(Settings):
    """The utility ``U_i = exp(-w_d dist_i) (w_w sigma_w,i^2 + w_c sigma_c,i^2 + w_s pi_s,i)``.

    Attributes:
        w_d: distance discount per metre of path.
        w_w: weight of the wind variance ``var(u_x) + var(u_y)``, (m/s)^-2.
        w_c: weight of the log-concentration variance.
        w_s: weight of the source term.
    """

    w_d: float = 0.1
    w_w: float = 0.25
    w_c: float = 2.0
    w_s: float = 100.0

    def __post_init__(self) -> None:
        for k in ("w_d", "w_w", "w_c", "w_s"):
            v = float(getattr(self, k))
            if not (math.isfinite(v) and v >= 0):
                raise InputDataError(f"weights.{k} must be finite and >= 0, got {v}")
            self._set(k, v)


@dataclass(frozen=True)
class StopRule(Settings):
    """When the search stops with its estimate: the entropy test ``H(pi_s) <= eta log N`` (``N``
    the belief's free cells).

    Attributes:
        eta: the entropy test's threshold in [0, 1].
        min_observations: the stop test waits for this many readings (0: from the first, as
            the paper).
    """

    eta: float = 0.65
    min_observations: int = 0

    def __post_init__(self) -> None:
        eta = float(self.eta)
        if not (0.0 <= eta <= 1.0):
            raise InputDataError(f"stop.eta must lie in [0, 1], got {self.eta}")
        self._set("eta", eta)
        self._set("min_observations", _count("stop.min_observations", self.min_observations, 0))


@dataclass
class UtilityPlanner(PlannerBase):
    """The paper's utility planner with entropy termination (see the module docstring).

    Args:
        weights: the utility's weights (:class:`UtilityWeights`).
        stop: the stop test (:class:`StopRule`).

    Every field of these can be set by a dotted key (``get_planner("utility",
    **{"stop.eta": 0.75})``, ``-P stop.eta=0.75``).  A search it plans ends at its stop test
    or the time limit (no deadline stop) and declares the posterior mean.
    """

    weights: UtilityWeights = UtilityWeights()
    stop: StopRule = StopRule()
    name: str = field(default="utility", init=False)

    def __post_init__(self) -> None:
        for key, cls in (("weights", UtilityWeights), ("stop", StopRule)):
            if not isinstance(getattr(self, key), cls):
                raise InputDataError(f"{key} must be a {cls.__name__}, got {getattr(self, key)!r}")

    def should_stop(self, belief: Belief, history: SearchHistory | None = None) -> bool:
        """The entropy test ``H(pi_s) <= eta log N`` (``N`` the free cells); a one-cell map stops
        at once.  Never before ``stop.min_observations`` readings (``history`` None: no minimum).
        """
        if history is not None and history.step < self.stop.min_observations:
            return False
        return belief.entropy() <= self.stop.eta * belief.max_entropy

    def describe_stop(self) -> str:
        """The entropy test's threshold."""
        return f"the entropy is at most {self.stop.eta:g} of log N"

    def utility(self, belief: Belief, distances: np.ndarray) -> np.ndarray:
        """``float64 (H, W)`` utility ``U_i``; ``-inf`` on walls and unreachable cells."""
        uw = self.weights
        d = np.asarray(distances, dtype=np.float64)
        if d.shape != belief.shape:
            raise InputDataError(f"distances have shape {d.shape}, the belief {belief.shape}")
        gain = uw.w_s * belief.source_probs
        wind_var, conc_var = belief.wind_var_to_explore, belief.log_conc_var_to_explore
        if wind_var is not None and uw.w_w:
            gain = gain + uw.w_w * wind_var.sum(axis=0)
        if conc_var is not None and uw.w_c:
            gain = gain + uw.w_c * conc_var
        ok = np.isfinite(d) & belief.free
        u = np.full(belief.shape, -np.inf)
        u[ok] = np.exp(-uw.w_d * d[ok]) * gain[ok]
        return u

    def next_goal(
        self,
        belief: Belief,
        robot_cell: Cell,
        distances: np.ndarray,
        history: SearchHistory | None = None,
    ) -> Cell | None:
        """``argmax_i U_i`` over the candidate cells (see the module docstring), or None if none."""
        u = self.utility(belief, distances)
        i0, j0 = int(robot_cell[0]), int(robot_cell[1])
        u[i0, j0] = -np.inf
        if history is not None:
            measured = history.measured
            if measured.shape == u.shape:
                masked = np.where(measured, -np.inf, u)
                if np.isfinite(masked).any():
                    u = masked
        finite = np.isfinite(u)
        if not finite.any():
            return None
        best = u[finite].max()
        ties = np.flatnonzero(finite & (u >= best - 1e-12 * abs(best)))
        if ties.size > 1:
            d = np.asarray(distances, dtype=np.float64).reshape(-1)[ties]
            ties = ties[np.lexsort((ties, d))]
        k = int(ties[0])
        W = u.shape[1]
        return (k // W, k % W)


@dataclass(frozen=True)
class Deadline(Settings):
    """A search with a time budget that declares its best guess before the budget ends.

    Attributes:
        margin_s: None (the paper's rule: a search that runs out of time fails) or a margin,
            s: the search also stops, with its current estimate, once less than this is left
            of ``history.time_limit_s`` (at most a tenth of the limit).  Such a stop ends the
            episode with reason ``"deadline"``, not ``"converged"``, and benchmarks report it
            apart.
        estimate_radius_m: None (the belief's posterior mean, the paper's ``s_hat``) or a
            radius, m: at a deadline stop the search declares the centre of the free cell
            whose disk of this radius holds the most posterior mass (:meth:`declare`).
            A search that never passed its stop test often ends with a posterior split
            between two places, whose mean lies between them.
    """

    margin_s: float | None = None
    estimate_radius_m: float | None = None

    def __post_init__(self) -> None:
        if self.margin_s is not None:
            m = float(self.margin_s)
            if not (math.isfinite(m) and m >= 0):
                raise InputDataError(f"deadline.margin_s must be a number of s >= 0 or None, got {m}")
            self._set("margin_s", m)
        self._set("estimate_radius_m", _radius_or_none("deadline.estimate_radius_m", self.estimate_radius_m))

    def reached(self, history: SearchHistory | None) -> bool:
        """True when ``margin_s`` is set and less than it is left of ``history``'s time limit.

        The margin is at most a tenth of the limit, so that a short search is not ended
        at its first permitted reading.
        """
        if self.margin_s is None or history is None or not math.isfinite(history.time_limit_s):
            return False
        margin = min(self.margin_s, 0.1 * history.time_limit_s)
        return history.time_s + margin >= history.time_limit_s

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The posterior mean, except at a deadline stop with ``estimate_radius_m``: there the
        centre of the free cell whose disk of that radius holds the most posterior mass
        (:func:`disk_estimate`)."""
        if self.estimate_radius_m is None or not deadline:
            return belief.source_estimate()
        return disk_estimate(belief, self.estimate_radius_m)


def disk_estimate(belief: Belief, radius_m: float) -> tuple[float, float]:
    """The centre ``(x, y)``, m, of the free cell whose disk of ``radius_m`` holds the most posterior mass."""
    mass = np.where(belief.free, mass_within(belief.source_probs, belief.resolution, radius_m), -np.inf)
    i, j = np.unravel_index(int(np.argmax(mass)), mass.shape)
    return belief.grid.center_of(int(i), int(j))


#: The disks of :func:`point_estimates` (m): the values ``deadline.estimate_radius_m`` is chosen among.
POINT_ESTIMATE_RADII = (0.5, 1.0, 2.0)


def _mean_within(belief: Belief, centre: tuple[float, float], radius_m: float) -> tuple[float, float]:
    """The posterior mean of the free cells within ``radius_m`` of ``centre`` (``centre`` where
    they hold no mass)."""
    grid = belief.grid
    near = np.hypot(grid.x[None, :] - centre[0], grid.y[:, None] - centre[1]) <= radius_m + 1e-9
    p = np.where(near & belief.free, belief.source_probs, 0.0)
    total = float(p.sum())
    if total <= 0.0:
        return centre
    return float((p.sum(axis=0) * grid.x).sum() / total), float((p.sum(axis=1) * grid.y).sum() / total)


def point_estimates(belief: Belief) -> dict[str, tuple[float, float]]:
    """The source ``(x, y)``, m, that each way of reading ``belief`` declares: ``mean`` (the
    posterior mean, what a search declares by default), ``mode`` (the most probable cell's
    centre), ``disk<r>m`` (:func:`disk_estimate`) and ``local<r>m`` (the posterior mean within
    that disk: the mean of the heaviest part of a split posterior) for each of
    :data:`POINT_ESTIMATE_RADII`.  Every episode records their errors, so a deadline
    rule can be chosen from one run."""
    out = {"mean": belief.source_estimate(), "mode": belief.grid.center_of(*belief.most_likely_cell())}
    for r in POINT_ESTIMATE_RADII:
        out[f"disk{r:g}m"] = disk_estimate(belief, r)
        out[f"local{r:g}m"] = _mean_within(belief, out[f"disk{r:g}m"], r)
    return out


# -- registry -------------------------------------------------------------------------
PlannerFactory = Callable[..., Planner]

#: Every planner: the paper's utility planner and the baselines' own (:mod:`dgse.localization`);
#: packages add theirs through the ``dgse.planners`` entry-point group (:mod:`dgse.registry`).
PLANNERS: Registry[Planner] = Registry(
    "planner",
    [
        Entry("utility", UtilityPlanner),
        Entry("info", "dgse.planning.information:InformationPlanner", label="information planner"),
        Entry("infotaxis", "dgse.localization.infotaxis:make_infotaxis"),
        Entry("entrotaxis", "dgse.localization.infotaxis:make_entrotaxis"),
        Entry("dualmode", "dgse.localization.particle_filter:DualModePlanner"),
        Entry("pmfs", "dgse.localization.pmfs:PMFSPlanner"),
    ],
    group="dgse.planners",
)


def register_planner(name: str, factory: PlannerFactory | str, *, replace: bool = False, **meta: Any) -> None:
    """Register ``factory`` (a callable ``factory(**kwargs) -> Planner`` or a lazy
    ``"module:function"``) under ``name`` (:meth:`dgse.registry.Registry.register`)."""
    PLANNERS.register(name, factory, replace=replace, **meta)


def planner_names() -> list[str]:
    """The registered planner names, sorted (plugins included)."""
    return PLANNERS.names()


def get_planner(name: str, **kwargs: Any) -> Planner:
    """A new planner ``name`` built with ``kwargs`` (e.g. ``get_planner("utility", **{"stop.eta": 0.75})``).

    Raises:
        UnsupportedError: an unknown name (the message lists the known ones) or
            a planner whose module cannot be imported here.
        InputDataError: keyword arguments the planner does not take.
    """
    planner = PLANNERS.create(name, **kwargs)
    if not isinstance(planner, Planner):
        raise UnsupportedError(
            f"planner {name!r} does not implement the Planner protocol (derive it from "
            "dgse.planning.planners.PlannerBase and give it should_stop() and next_goal())"
        )
    return planner
