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
posterior" could also be read as the network canvas, 100 x 100 cells with
walls and padding: ``entropy_cells=10000`` gives that reading).  Decisions on
what the paper leaves open:

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
* ``dist_i`` is in metres by default (the paper does not give the unit;
  ``distance_unit="cell"`` measures it in cell sides instead, i.e. ``dist / res``);
* candidates are the free cells reachable from the robot, except the robot's
  own cell (moving nowhere would repeat the same measurement) and the cells
  where the robot has already measured (``exclude_measured``, default on);
  when that leaves nothing, measured cells are allowed again; when even that
  leaves nothing (a one-cell map), ``next_goal`` returns None;
* ties (utilities equal to a relative ``1e-12``): the nearest cell by path
  length, then the lowest row-major index;
* ``confirm_radius_m`` (default None, the paper's rule): see the class; without it,
  searches with ``dgse-phys`` stopped confidently on spots nobody had measured at;
* ``min_observations`` (default 0, the paper's rule): the entropy test waits
  for that many readings.  A network trained on 5 to 300 readings (the
  paper's range, ``dgse.sensing.sensors.MIN_SENSORS``) has never seen fewer
  than 5, and the shipped DGSE-S can be confidently wrong after one
  (``benchmarks/few_readings.py``).  ``dgse demo`` and the search benchmark
  pass ``MIN_SENSORS``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from dgse.belief.belief import Belief
from dgse.errors import InputDataError, UnsupportedError
from dgse.planning.paths import Cell, FreeSpaceGraph
from dgse.registry import Entry, Registry
from dgse.sensing.sensors import Observations

__all__ = [
    "Planner",
    "PlannerBase",
    "PlannerFactory",
    "SearchHistory",
    "UtilityPlanner",
    "get_planner",
    "mass_around",
    "mass_near_mode",
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
        step: the number of measurements so far (1 at the first decision).
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

    def stop_held(self, history: SearchHistory) -> bool:
        """Whether the last :meth:`should_stop`, at this step, passed its stop test but held the
        stop (the search goes on; episodes record where that happened)."""
        ...

    def deadline_reached(self, history: SearchHistory) -> bool:
        """Whether a stop now is a deadline stop (the time budget is nearly spent), not a
        confident one; episodes end such a stop with reason ``"deadline"``."""
        ...

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The source ``(x, y)``, m, the search declares when it ends with ``belief``
        (``deadline``: at a deadline stop)."""
        ...


class PlannerBase:
    """What a planner without these rules does: no held stops, no deadline stops, and the
    belief's posterior mean as the declared source.  Planners derive from it and override
    what they decide otherwise."""

    def reset(self) -> None:
        """Nothing to forget."""

    def stop_held(self, history: SearchHistory) -> bool:
        """Never holds a stop."""
        return False

    def deadline_reached(self, history: SearchHistory) -> bool:
        """Has no deadline stop."""
        return False

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The posterior mean (:meth:`~dgse.belief.belief.Belief.source_estimate`)."""
        return belief.source_estimate()


def _radius_or_none(name: str, value: float | None) -> float | None:
    """A planner option that is None or a positive, finite number of m."""
    if value is None:
        return None
    r = float(value)
    if not (math.isfinite(r) and r > 0):
        raise InputDataError(f"{name} must be a positive number of m or None, got {r}")
    return r


def mass_near_mode(belief: Belief, radius_m: float) -> float:
    """Source posterior mass within ``radius_m`` of the posterior's mode (cell centres)."""
    return mass_around(belief.source_probs, belief.resolution, belief.most_likely_cell(), radius_m)


def mass_around(probs: np.ndarray, resolution: float, cell: tuple[int, int], radius_m: float) -> float:
    """The share of ``probs``'s mass within ``radius_m`` of cell ``cell``'s centre."""
    p = np.asarray(probs, dtype=np.float64)
    H, W = p.shape
    ii, jj = np.ogrid[0:H, 0:W]
    near = np.hypot(ii - cell[0], jj - cell[1]) * resolution <= radius_m + 1e-9
    return float(p[near].sum() / max(float(p.sum()), 1e-300))


def mass_within(probs: np.ndarray, resolution: float, radius_m: float) -> np.ndarray:
    """``float64 (H, W)``: the mass of ``probs`` within ``radius_m`` of each cell's centre (walls ignored)."""
    from scipy.signal import fftconvolve

    r = math.floor(radius_m / resolution + 1e-9)
    ii, jj = np.mgrid[-r : r + 1, -r : r + 1]
    disk = (np.hypot(ii, jj) * resolution <= radius_m + 1e-9).astype(np.float64)
    out = fftconvolve(np.asarray(probs, dtype=np.float64), disk, mode="same")
    return np.maximum(out, 0.0)


@dataclass
class UtilityPlanner(PlannerBase):
    """The paper's utility planner with entropy termination (see the module docstring).

    Args:
        w_d: distance discount per metre (per cell with ``distance_unit="cell"``).
        w_w: weight of the wind variance ``var(u_x) + var(u_y)``.
        w_c: weight of the log-concentration variance.
        w_s: weight of the source probability.
        eta: termination threshold in [0, 1]: stop when ``H(pi_s) <= eta log N``.
        distance_unit: ``"m"`` or ``"cell"``: the unit of ``dist_i``.
        exclude_measured: never choose a cell already measured (unless nothing else is left).
        entropy_cells: ``N`` of the termination test; None (default): the
            belief's free cells.
        min_observations: the termination test waits for this many readings
            (0: from the first, as the paper).
        confirm_radius_m: None (the paper's rule) or a radius, m: the search may stop only
            once ``confirm_readings`` readings were taken within this distance of the
            posterior's mode; while the entropy test passes without them, the next goal is
            the unmeasured cell nearest the mode.  A mode nobody has measured at is a guess
            from afar (clipped noise in clean air can make one); measured at, the estimator
            keeps it only if the readings there agree.
        confirm_readings: readings near the mode the stop needs (with ``confirm_radius_m``).
        confirm_sigmas: 0 (any reading counts) or a number: only readings above this many
            times the belief's noise floor (``belief.info["noise_floor_ppm"]``; a belief that
            states none: above 0 ppm) count towards ``confirm_readings``.  Clipped noise in
            clean air (zeros) can make a sharp posterior on a spot the plume of no candidate
            reaches; a source that nobody has smelt near is a guess.
        mass_radius_m: None (the entropy test) or a radius, m: the stop test becomes "the
            posterior holds at least ``mass_level`` within this distance of its mode"; with
            a calibrated posterior, that share of the stops lies within the radius of the
            source, whatever the map's size (the entropy test's meaning depends on it).
        mass_level: the posterior mass the stop needs within ``mass_radius_m``.
        source_radius_m: None (the paper's term ``w_s pi_s,i``) or a radius, m: the source
            term becomes ``w_s`` times the posterior mass within this distance of cell ``i``
            (:func:`mass_within`).  A reading tests the sources around it, not one cell: a
            posterior spread thinly over a whole room holds little per cell but much per
            disk, and the paper's term leaves such a room unvisited while the robot keeps
            measuring beside a mode it has already measured at.
        deadline_margin_s: None (the paper's rule: a search that runs out of time fails) or
            a margin, s: the search also stops, with its current estimate, once less than
            this is left of ``history.time_limit_s``.  A robot with a time budget declares
            its best guess before the budget ends; such a stop ends the episode with reason
            ``"deadline"``, not ``"converged"``, and benchmarks report it apart.  At most a
            tenth of the limit.
        revisit_radius_m: None (the paper's terms) or a radius, m: the wind and
            concentration variance terms of a cell are divided by ``1 + k``, ``k`` the
            cells already measured within this radius of it.  Where the model cannot fit
            the readings (a sharp plume edge that no flow hypothesis puts in the right
            place) the predicted variance stays high however often the robot measures
            there, and the paper's terms keep it measuring cell after cell along that
            edge; measured neighbourhoods lose that pull, the source term keeps its own.
        stop_readings: the stop test (entropy or mass) must pass at this many readings in a
            row, the posterior's mode staying within ``mass_radius_m`` (1 m without it) of
            where it first passed: a posterior that one or two readings have sharpened on a
            wrong spot is given the next reading to contradict it.  1: the paper's rule.
        max_wind_misfit: None (no such test) or a number: the stop is held while the belief
            states a ``wind_misfit`` above it (``belief.info["wind_misfit"]``: how much of the
            wind readings the best flow hypothesis leaves unexplained, see
            :func:`~dgse.posterior.mixture.relative_wind_misfit`; a belief that states none is
            not held).  A posterior drawn on a flow that does not explain the wind can be
            sharp and wrong; the search goes on (the deadline still ends it) until the
            estimator finds a flow that does.
        min_learned_mass: None (no such test) or a share in (0, 1]: the stop is also held while
            a second opinion on the source, ``belief.info["learned_source_probs"]`` (an
            ``(H, W)`` array, or a function of no arguments that returns one: DGSE-S's own source
            belief from the same readings, which ``dgse-phys`` attaches with
            ``learned_opinion=True``, asked only when the stop test passes), puts less than
            this within ``mass_radius_m`` (1 m without it) of the posterior's mode; a belief
            that states none is not held.  A physics posterior drawn on a wrong flow can be
            sure of a spot the network, which does not share that flow's error, sees no source
            near.
        deadline_estimate_radius_m: None (the belief's posterior mean, the paper's ``s_hat``)
            or a radius, m: at a deadline stop the search declares the centre of the free cell
            whose disk of this radius holds the most posterior mass
            (:meth:`declare`).  A search that never passed its stop test often ends
            with a posterior split between two places, whose mean lies between them.
        deadline_estimate: what that disk gives at a deadline stop: ``"disk"`` its centre,
            ``"local"`` the posterior mean within it (:func:`local_mean`).
    """

    w_d: float = 0.1
    w_w: float = 0.25
    w_c: float = 2.0
    w_s: float = 100.0
    eta: float = 0.65
    distance_unit: Literal["m", "cell"] = "m"
    exclude_measured: bool = True
    entropy_cells: int | None = None
    min_observations: int = 0
    confirm_radius_m: float | None = None
    confirm_readings: int = 2
    confirm_sigmas: float = 0.0
    mass_radius_m: float | None = None
    mass_level: float = 0.9
    source_radius_m: float | None = None
    deadline_margin_s: float | None = None
    revisit_radius_m: float | None = None
    stop_readings: int = 1
    max_wind_misfit: float | None = None
    min_learned_mass: float | None = None
    deadline_estimate_radius_m: float | None = None
    deadline_estimate: Literal["disk", "local"] = "disk"
    name: str = field(default="utility", init=False)
    _streak: list[tuple[int, int, int]] = field(default_factory=list, init=False, repr=False)
    _held_step: int | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        for k in ("w_d", "w_w", "w_c", "w_s"):
            v = float(getattr(self, k))
            if not (math.isfinite(v) and v >= 0):
                raise InputDataError(f"utility weight {k} must be finite and >= 0, got {v}")
            setattr(self, k, v)
        eta = float(self.eta)
        if not (0.0 <= eta <= 1.0):
            raise InputDataError(f"eta must lie in [0, 1], got {self.eta}")
        self.eta = eta
        if self.entropy_cells is not None and int(self.entropy_cells) < 1:
            raise InputDataError(f"entropy_cells must be >= 1, got {self.entropy_cells}")
        if isinstance(self.min_observations, bool) or int(self.min_observations) != self.min_observations:
            raise InputDataError(f"min_observations must be an integer, got {self.min_observations!r}")
        if self.min_observations < 0:
            raise InputDataError(f"min_observations must be >= 0, got {self.min_observations}")
        self.min_observations = int(self.min_observations)
        self.confirm_radius_m = _radius_or_none("confirm_radius_m", self.confirm_radius_m)
        if isinstance(self.confirm_readings, bool) or int(self.confirm_readings) != self.confirm_readings:
            raise InputDataError(f"confirm_readings must be an integer, got {self.confirm_readings!r}")
        if self.confirm_readings < 1:
            raise InputDataError(f"confirm_readings must be >= 1, got {self.confirm_readings}")
        self.confirm_readings = int(self.confirm_readings)
        sig = float(self.confirm_sigmas)
        if not (math.isfinite(sig) and sig >= 0):
            raise InputDataError(f"confirm_sigmas must be a finite number >= 0, got {self.confirm_sigmas!r}")
        self.confirm_sigmas = sig
        self.mass_radius_m = _radius_or_none("mass_radius_m", self.mass_radius_m)
        if not (0.0 < float(self.mass_level) <= 1.0):
            raise InputDataError(f"mass_level must lie in (0, 1], got {self.mass_level}")
        self.mass_level = float(self.mass_level)
        self.source_radius_m = _radius_or_none("source_radius_m", self.source_radius_m)
        self.revisit_radius_m = _radius_or_none("revisit_radius_m", self.revisit_radius_m)
        self.deadline_estimate_radius_m = _radius_or_none(
            "deadline_estimate_radius_m", self.deadline_estimate_radius_m
        )
        if self.deadline_estimate not in ("disk", "local"):
            raise InputDataError(
                f"deadline_estimate must be 'disk' or 'local', got {self.deadline_estimate!r}"
            )
        if isinstance(self.stop_readings, bool) or int(self.stop_readings) != self.stop_readings:
            raise InputDataError(f"stop_readings must be an integer, got {self.stop_readings!r}")
        if self.stop_readings < 1:
            raise InputDataError(f"stop_readings must be >= 1, got {self.stop_readings}")
        self.stop_readings = int(self.stop_readings)
        if self.max_wind_misfit is not None:
            mm = float(self.max_wind_misfit)
            if not (math.isfinite(mm) and mm > 0):
                raise InputDataError(
                    f"max_wind_misfit must be a number > 0 or None, got {self.max_wind_misfit!r}"
                )
            self.max_wind_misfit = mm
        if self.min_learned_mass is not None:
            ml = float(self.min_learned_mass)
            if not (0.0 < ml <= 1.0):
                raise InputDataError(
                    f"min_learned_mass must lie in (0, 1] or be None, got {self.min_learned_mass!r}"
                )
            self.min_learned_mass = ml
        if self.deadline_margin_s is not None:
            m = float(self.deadline_margin_s)
            if not (math.isfinite(m) and m >= 0):
                raise InputDataError(f"deadline_margin_s must be a number of s >= 0 or None, got {m}")
            self.deadline_margin_s = m
        if self.distance_unit not in ("m", "cell"):
            raise InputDataError(f"distance_unit must be 'm' or 'cell', got {self.distance_unit!r}")

    def reset(self) -> None:
        """Forget the stop test's run of passes (``stop_readings``)."""
        self._streak = []
        self._held_step = None

    def should_stop(self, belief: Belief, history: SearchHistory | None = None) -> bool:
        """``H(pi_s) <= eta log N`` (``N``: free cells or ``entropy_cells``); a one-cell map stops at once.

        Never before ``min_observations`` readings (``history`` None: no minimum).
        """
        self._held_step = None
        if history is not None and history.step < self.min_observations:
            return False
        if self.deadline_reached(history):
            return True
        if not self._passes_in_a_row(belief, history):
            return False
        if history is None or (
            self._unconfirmed_mode(belief, history) is None
            and not self._wind_unexplained(belief)
            and not self._learned_disagrees(belief)
        ):
            return True
        self._held_step = int(history.step)  # passed, held for confirmation, a flow or the network
        return False

    def _wind_unexplained(self, belief: Belief) -> bool:
        """The belief's ``wind_misfit`` exceeds ``max_wind_misfit`` (False when either is unset)."""
        v = belief.info.get("wind_misfit")
        if self.max_wind_misfit is None or not isinstance(v, int | float):
            return False
        return not (float(v) <= self.max_wind_misfit)

    def _learned_disagrees(self, belief: Belief) -> bool:
        """The belief's second opinion (``info["learned_source_probs"]``) puts less than
        ``min_learned_mass`` near the posterior's mode (False when either is unset)."""
        probs = belief.info.get("learned_source_probs")
        if self.min_learned_mass is None or probs is None:
            return False
        probs = np.asarray(probs() if callable(probs) else probs, dtype=np.float64)
        if probs.shape != belief.shape:
            raise InputDataError(
                f"info['learned_source_probs'] has shape {probs.shape}, the belief {belief.shape}"
            )
        near = mass_around(probs, belief.resolution, belief.most_likely_cell(), self._mode_radius_m)
        return not (near >= self.min_learned_mass)

    @property
    def _mode_radius_m(self) -> float:
        """The radius (m) that counts as "near the mode": ``mass_radius_m``, 1 m without it."""
        return 1.0 if self.mass_radius_m is None else self.mass_radius_m

    def _passes_in_a_row(self, belief: Belief, history: SearchHistory | None) -> bool:
        """The stop test has passed at the last ``stop_readings`` readings, the posterior's mode
        staying within ``mass_radius_m`` (1 m without it) of where it first passed."""
        passes = self._entropy_passes(belief)
        if self.stop_readings == 1 or history is None:
            return passes
        step = int(history.step)
        # asked again at the same step, or a new episode without reset(): forget those passes
        self._streak = [e for e in self._streak if e[0] < step]
        if not passes:
            self._streak = []
            return False
        i, j = belief.most_likely_cell()
        if self._streak:
            _, i0, j0 = self._streak[0]
            moved = math.hypot(i - i0, j - j0) * belief.resolution > self._mode_radius_m
            if moved or self._streak[-1][0] != step - 1:
                self._streak = []
        self._streak.append((step, i, j))
        return len(self._streak) >= self.stop_readings

    def deadline_reached(self, history: SearchHistory | None) -> bool:
        """True when ``deadline_margin_s`` is set and less than it is left of the time limit.

        The margin is at most a tenth of the limit, so that a short search is not ended
        at its first permitted reading.
        """
        if self.deadline_margin_s is None or history is None or not math.isfinite(history.time_limit_s):
            return False
        margin = min(self.deadline_margin_s, 0.1 * history.time_limit_s)
        return history.time_s + margin >= history.time_limit_s

    def _entropy_passes(self, belief: Belief) -> bool:
        """The stop test without its minimum and confirmation: entropy, or mass near the mode."""
        if self.mass_radius_m is not None:
            return mass_near_mode(belief, self.mass_radius_m) >= self.mass_level
        log_n = belief.max_entropy if self.entropy_cells is None else math.log(int(self.entropy_cells))
        return belief.entropy() <= self.eta * log_n

    def _unconfirmed_mode(self, belief: Belief, history: SearchHistory) -> tuple[int, int] | None:
        """The posterior's mode if fewer than ``confirm_readings`` readings lie near it, else None."""
        if self.confirm_radius_m is None:
            return None
        mode = belief.most_likely_cell()
        cells = history.observations.cells
        if len(cells):
            d = np.hypot(cells[:, 0] - mode[0], cells[:, 1] - mode[1]) * belief.resolution
            counts = d <= self.confirm_radius_m + 1e-9
            if self.confirm_sigmas > 0:
                counts &= np.asarray(history.observations.gas) > self.confirm_sigmas * _noise_floor(belief)
            if int(counts.sum()) >= self.confirm_readings:
                return None
        return mode

    def stop_held(self, history: SearchHistory | None) -> bool:
        """True when :meth:`should_stop`, asked at this step, passed its stop test but held the
        stop for the mode's confirmation (``confirm_radius_m``), a flow that explains the wind
        (``max_wind_misfit``) or the network's agreement (``min_learned_mass``): where the search
        would have stopped without them."""
        return history is not None and self._held_step == int(history.step)

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The posterior mean, except at a deadline stop with ``deadline_estimate_radius_m``:
        there the centre of the free cell whose disk of that radius holds the most posterior
        mass (:func:`disk_estimate`), or with ``deadline_estimate="local"`` the posterior mean
        within that disk (:func:`local_mean`)."""
        radius = self.deadline_estimate_radius_m
        if radius is None or not deadline:
            return belief.source_estimate()
        if self.deadline_estimate == "local":
            return local_mean(belief, radius)
        return disk_estimate(belief, radius)

    def utility(
        self, belief: Belief, distances: np.ndarray, history: SearchHistory | None = None
    ) -> np.ndarray:
        """``float64 (H, W)`` utility ``U_i``; ``-inf`` on walls and unreachable cells.

        ``history``: the readings so far (for ``revisit_radius_m``; None: none taken).
        """
        d = np.asarray(distances, dtype=np.float64)
        if d.shape != belief.shape:
            raise InputDataError(f"distances have shape {d.shape}, the belief {belief.shape}")
        if self.source_radius_m is None:
            gain = self.w_s * belief.source_probs
        else:
            gain = self.w_s * mass_within(belief.source_probs, belief.resolution, self.source_radius_m)
        fresh: float | np.ndarray = 1.0  # how new a cell's neighbourhood is (revisit_radius_m)
        measured = None if history is None else history.measured
        if self.revisit_radius_m is not None and measured is not None and measured.shape == belief.shape:
            near = mass_within(measured.astype(np.float64), belief.resolution, self.revisit_radius_m)
            fresh = 1.0 / (1.0 + np.rint(near))
        wind_var, conc_var = belief.wind_var_to_explore, belief.log_conc_var_to_explore
        if wind_var is not None and self.w_w:
            gain = gain + self.w_w * wind_var.sum(axis=0) * fresh
        if conc_var is not None and self.w_c:
            gain = gain + self.w_c * conc_var * fresh
        ok = np.isfinite(d) & belief.free
        scale = 1.0 / belief.resolution if self.distance_unit == "cell" else 1.0
        u = np.full(belief.shape, -np.inf)
        u[ok] = np.exp(-self.w_d * scale * d[ok]) * gain[ok]
        return u

    def next_goal(
        self,
        belief: Belief,
        robot_cell: Cell,
        distances: np.ndarray,
        history: SearchHistory | None = None,
    ) -> Cell | None:
        """``argmax_i U_i`` over the candidate cells (see the module docstring), or None if none.

        With ``confirm_radius_m``, while the entropy test passes but the mode is unconfirmed:
        the reachable unmeasured cell nearest the mode within that radius (the mode's own
        cell first), if there is one.
        """
        if history is not None and self.confirm_radius_m is not None and self._entropy_passes(belief):
            goal = self._confirming_goal(belief, robot_cell, distances, history)
            if goal is not None:
                return goal
        u = self.utility(belief, distances, history)
        i0, j0 = int(robot_cell[0]), int(robot_cell[1])
        u[i0, j0] = -np.inf
        if self.exclude_measured and history is not None:
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

    def _confirming_goal(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory
    ) -> Cell | None:
        mode = self._unconfirmed_mode(belief, history)
        if mode is None:
            return None
        H, W = belief.shape
        ii, jj = np.mgrid[0:H, 0:W]
        near = np.hypot(ii - mode[0], jj - mode[1]) * belief.resolution
        ok = (
            belief.free
            & np.isfinite(np.asarray(distances, dtype=np.float64))
            & (near <= self.confirm_radius_m + 1e-9)
            & ~history.measured
        )
        ok[int(robot_cell[0]), int(robot_cell[1])] = False
        if not ok.any():
            return None
        k = int(np.argmin(np.where(ok, near, np.inf)))
        return (k // W, k % W)


def _noise_floor(belief: Belief) -> float:
    """The belief's stated noise floor, ppm (``info["noise_floor_ppm"]``), else 0."""
    v = belief.info.get("noise_floor_ppm")
    if isinstance(v, int | float) and math.isfinite(v) and v > 0:
        return float(v)
    return 0.0


def disk_estimate(belief: Belief, radius_m: float) -> tuple[float, float]:
    """The centre ``(x, y)``, m, of the free cell whose disk of ``radius_m`` holds the most posterior mass."""
    mass = np.where(belief.free, mass_within(belief.source_probs, belief.resolution, radius_m), -np.inf)
    i, j = np.unravel_index(int(np.argmax(mass)), mass.shape)
    return belief.grid.center_of(int(i), int(j))


#: The disks of :func:`point_estimates` (m): the values ``deadline_estimate_radius_m`` is chosen among.
POINT_ESTIMATE_RADII = (0.5, 1.0, 2.0)


def local_mean(belief: Belief, radius_m: float) -> tuple[float, float]:
    """The posterior mean ``(x, y)``, m, of the cells within ``radius_m`` of :func:`disk_estimate`'s
    centre: the mean of the heaviest part of a split posterior.  (A sharp posterior fits in
    many disks, whose centres tie; the mean within one of them is the posterior's mean.)"""
    return _mean_within(belief, disk_estimate(belief, radius_m), radius_m)


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
    centre), ``disk<r>m`` (:func:`disk_estimate`) and ``local<r>m`` (:func:`local_mean`) for
    each of :data:`POINT_ESTIMATE_RADII`.  Every episode records their errors, so a deadline
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
    """A new planner ``name`` built with ``kwargs`` (e.g. ``get_planner("utility", eta=0.75)``).

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
