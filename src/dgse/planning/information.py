r"""A planner that measures where a reading would teach most about the source, per second.

For each candidate cell ``x`` the belief predicts the distribution of the gas reading
there (:meth:`~dgse.belief.belief.Belief.reading_predictive`, a mixture of clipped
Gaussians whose components name their source cells), and the planner scores the
mutual information between that reading and the source cell:

``I_x(z; s) = H(s) + H(z | x) - H(z, s | x)``

with the reading discretized into bins (the clipped zero exactly, then even bins up to
``max(mu + 3 sigma)`` of the cell's components, :meth:`ReadingMixture.bin_probabilities`;
binning only loses information, so the term is a lower bound that tightens with
``info.n_bins``).  Components of one source cell under several flow hypotheses are one
outcome of ``s``: a reading that only tells the hypotheses apart teaches nothing about
the source here.  A belief whose components name no source (DGSE-S) scores the
information about its own components (the concentration at ``x``); a belief with no
predictive at all scores the posterior mass within 1 m of ``x``.  The goal is

``argmax_x I_x / (d_x / speed + dwell)``

information per second of the move and the reading (``d_x`` the path length over the
free-space graph, :mod:`dgse.planning.paths`; speed and dwell the search protocol's,
:data:`dgse.presets.PROTOCOL`).  Candidates: the reachable free cells except the robot's
and those already measured (measured ones again when nothing else is left), at most
``info.max_candidates`` of them (the ``info.nearest`` nearest, the rest drawn with the
episode's generator); ties go to the nearest cell.

Stop (:class:`InformationStop`): once ``stop.min_observations`` readings are in, the search
stops when the posterior mass within ``stop.radius_m`` (the success radius of
:mod:`dgse.search.metrics`) of the point it would declare (:meth:`InformationPlanner.declare`)
reaches ``stop.level``: with a calibrated posterior that is the probability the search
succeeds if it stops now.  A :class:`~dgse.planning.planners.Deadline` (``deadline.margin_s``,
60 s by default) ends it before the time limit, declaring the posterior mean or, with
``deadline.estimate_radius_m``, the centre of the heaviest disk of that radius.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dgse.belief.belief import Belief
from dgse.belief.predictive import ReadingMixture
from dgse.errors import InputDataError
from dgse.options import Settings, check_whole
from dgse.planning.paths import Cell
from dgse.planning.planners import Deadline, PlannerBase, SearchHistory, mass_within

__all__ = [
    "InformationPlanner",
    "InformationStop",
    "InformationTerm",
    "mass_near_point",
    "reading_information",
]

#: Cells evaluated at once in :func:`reading_information` (bounds its ``(C, B, K)`` arrays).
_CELL_BLOCK = 64
#: The disk, m, of the score of a belief that predicts no readings.
_FALLBACK_RADIUS_M = 1.0


def _xlogx(a: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a > 0, a * np.log(np.where(a > 0, a, 1.0)), 0.0)


def reading_information(mixture: ReadingMixture, n_bins: int = 24, spread: float = 3.0) -> np.ndarray:
    """``(C,)`` the mutual information, nats, between the reading at each cell and the source.

    The source is the components' source cell (:attr:`ReadingMixture.sources`; each
    component on its own where they name none); the reading is binned as
    :meth:`ReadingMixture.bin_probabilities` (``n_bins``, ``spread``).
    """
    w = mixture.weights
    if mixture.sources is None:
        labels = np.arange(w.size)
    else:
        _, labels = np.unique(mixture.sources, return_inverse=True)
    U = int(labels.max()) + 1
    group = np.zeros((w.size, U))
    group[np.arange(w.size), labels] = 1.0
    ps = w @ group
    h_s = float(-_xlogx(ps).sum())
    out = np.empty(mixture.n_cells)
    for a in range(0, mixture.n_cells, _CELL_BLOCK):
        b = min(a + _CELL_BLOCK, mixture.n_cells)
        part = ReadingMixture(w, mixture.mean[a:b], mixture.sigma[a:b], mixture.sources)
        J = part.bin_probabilities(n_bins, spread) * w[None, None, :]  # (c, B+1, K)
        Js = J @ group  # (c, B+1, U): reading bin and source cell
        h_z = -_xlogx(J.sum(axis=2)).sum(axis=1)
        h_zs = -_xlogx(Js).sum(axis=(1, 2))
        out[a:b] = h_s + h_z - h_zs
    return np.maximum(out, 0.0)


def mass_near_point(belief: Belief, xy: tuple[float, float], radius_m: float) -> float:
    """The source posterior's mass on the cells whose centres lie within ``radius_m`` of ``xy`` (m)."""
    g = belief.grid
    near = np.hypot(g.x[None, :] - float(xy[0]), g.y[:, None] - float(xy[1])) <= radius_m + 1e-9
    return float(belief.source_probs[near].sum())


def _positive(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputDataError(f"{name} must be a positive number, got {value!r}")
    return v


@dataclass(frozen=True)
class InformationTerm(Settings):
    """How a candidate's information per second is scored.

    Attributes:
        speed_m_s: the robot's speed, m/s (the search protocol's, :data:`dgse.presets.PROTOCOL`).
        dwell_s: the time of one reading, s (the protocol's).
        n_bins: reading bins above the clipped zero (:func:`reading_information`).
        spread: the bins reach up to the largest ``mean + spread * sigma`` of the cell's components.
        max_candidates: at most this many candidate cells per decision: the ``nearest`` ones
            by path length, the others drawn at random.
        nearest: how many of the candidates are the cells nearest the robot.
    """

    speed_m_s: float = 0.5
    dwell_s: float = 3.0
    n_bins: int = 16
    spread: float = 3.0
    max_candidates: int = 300
    nearest: int = 100

    def __post_init__(self) -> None:
        self._set("speed_m_s", _positive("info.speed_m_s", self.speed_m_s))
        dwell = float(self.dwell_s)
        if not (math.isfinite(dwell) and dwell >= 0):
            raise InputDataError(f"info.dwell_s must be a number of s >= 0, got {self.dwell_s!r}")
        self._set("dwell_s", dwell)
        self._set("n_bins", check_whole("info.n_bins", self.n_bins, 1))
        self._set("spread", _positive("info.spread", self.spread))
        self._set("max_candidates", check_whole("info.max_candidates", self.max_candidates, 1))
        self._set("nearest", check_whole("info.nearest", self.nearest, 0))


@dataclass(frozen=True)
class InformationStop(Settings):
    """The stop on the success criterion: enough posterior mass near the declared point.

    Attributes:
        radius_m: the radius, m (the success radius of :mod:`dgse.search.metrics`).
        level: the mass within ``radius_m`` of the declared point the stop needs, (0, 1].
        min_observations: the stop waits for this many readings.
    """

    radius_m: float = 2.0
    level: float = 0.95
    min_observations: int = 5

    def __post_init__(self) -> None:
        self._set("radius_m", _positive("stop.radius_m", self.radius_m))
        if not (0.0 < float(self.level) <= 1.0):
            raise InputDataError(f"stop.level must lie in (0, 1], got {self.level!r}")
        self._set("level", float(self.level))
        self._set("min_observations", check_whole("stop.min_observations", self.min_observations, 0))


@dataclass
class InformationPlanner(PlannerBase):
    """Information about the source per second of travel and dwell (module docstring).

    Args:
        info: the information term and the candidates (:class:`InformationTerm`).
        stop: the stop on the mass near the declared point (:class:`InformationStop`).
        deadline: the stop before the time limit and what it declares
            (:class:`~dgse.planning.planners.Deadline`).

    Every field of these can be set by a dotted key (``-P stop.level=0.9``).
    """

    info: InformationTerm = InformationTerm()
    stop: InformationStop = InformationStop()
    deadline: Deadline = Deadline(margin_s=60.0)
    name: str = field(default="info", init=False)
    last_scores: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        for key, cls in (("info", InformationTerm), ("stop", InformationStop), ("deadline", Deadline)):
            if not isinstance(getattr(self, key), cls):
                raise InputDataError(f"{key} must be a {cls.__name__}, got {getattr(self, key)!r}")

    def reset(self) -> None:
        """Forget the last decision's scores."""
        self.last_scores = {}

    def deadline_reached(self, history: SearchHistory | None) -> bool:
        """Less than ``deadline.margin_s`` (at most a tenth of the limit) left of the time limit."""
        return self.deadline.reached(history)

    def declare(self, belief: Belief, deadline: bool) -> tuple[float, float]:
        """The posterior mean; at a deadline stop with ``deadline.estimate_radius_m`` the centre
        of the heaviest disk of that radius (:meth:`~dgse.planning.planners.Deadline.declare`)."""
        return self.deadline.declare(belief, deadline)

    def describe_stop(self) -> str:
        """The share of the posterior the stop needs near the declared point, and the radius."""
        st = self.stop
        return f"{st.level:.0%} of the source posterior lies within {st.radius_m:g} m of its mean"

    def stop_mass(self, belief: Belief) -> float:
        """The posterior mass within ``stop.radius_m`` of the point a stop now declares."""
        return mass_near_point(belief, self.declare(belief, False), self.stop.radius_m)

    def should_stop(self, belief: Belief, history: SearchHistory | None = None) -> bool:
        """:meth:`stop_mass` reaches ``stop.level`` (not before ``stop.min_observations``
        readings), or the deadline is reached."""
        if history is not None and history.step < self.stop.min_observations:
            return False
        if self.deadline_reached(history):
            return True
        return self.stop_mass(belief) >= self.stop.level

    def information(self, belief: Belief, cells: np.ndarray) -> np.ndarray:
        """``(C,)`` what a reading at each of ``cells`` would teach about the source, nats
        (the posterior mass within 1 m for a belief that predicts no readings)."""
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        if len(c) == 0:
            return np.zeros(0)
        mixture = belief.reading_predictive(c)
        if mixture is None:
            return mass_within(belief.source_probs, belief.resolution, _FALLBACK_RADIUS_M)[c[:, 0], c[:, 1]]
        return reading_information(mixture, self.info.n_bins, self.info.spread)

    def scores(self, belief: Belief, cells: np.ndarray, distances: np.ndarray) -> np.ndarray:
        """``(C,)`` information per second: :meth:`information` over ``d / speed + dwell``."""
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        d = np.asarray(distances, dtype=np.float64)[c[:, 0], c[:, 1]]
        seconds = d / self.info.speed_m_s + self.info.dwell_s
        return self.information(belief, c) / np.maximum(seconds, 1e-9)

    def candidates(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory | None
    ) -> np.ndarray:
        """``(C, 2)`` the cells scored: reachable, free, not the robot's, unmeasured where any is
        left, at most ``info.max_candidates`` (the ``info.nearest`` nearest, the rest drawn with
        the episode's generator), in row-major order."""
        d = np.asarray(distances, dtype=np.float64)
        if d.shape != belief.shape:
            raise InputDataError(f"distances have shape {d.shape}, the belief {belief.shape}")
        ok = belief.free & np.isfinite(d)
        ok[int(robot_cell[0]), int(robot_cell[1])] = False
        if history is not None:
            fresh = ok & ~history.measured
            if fresh.any():
                ok = fresh
        cells = np.argwhere(ok).astype(np.int64)
        n = self.info.max_candidates
        if len(cells) > n:
            # the cells nearest the robot first (the cheapest readings), the rest drawn at random
            near = np.argsort(d[cells[:, 0], cells[:, 1]], kind="stable")
            k = min(self.info.nearest, n)
            rng = history.rng if history is not None else np.random.default_rng(0)
            rest = near[k:][rng.choice(len(cells) - k, size=n - k, replace=False)]
            cells = cells[np.sort(np.concatenate([near[:k], rest]))]
        return cells

    def next_goal(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory | None = None
    ) -> Cell | None:
        """The candidate with the most information per second (ties: nearest, then the lowest
        row-major index), or None where no cell is left."""
        cells = self.candidates(belief, robot_cell, distances, history)
        if len(cells) == 0:
            return None
        s = self.scores(belief, cells, distances)
        self.last_scores = {"cells": cells, "scores": s}
        top = float(s.max())
        ties = np.flatnonzero(s >= top - 1e-9 * max(abs(top), 1e-300))
        d = np.asarray(distances, dtype=np.float64)[cells[ties, 0], cells[ties, 1]]
        flat = cells[ties, 0] * belief.shape[1] + cells[ties, 1]
        k = int(ties[np.lexsort((flat, d))[0]])
        return (int(cells[k, 0]), int(cells[k, 1]))
