r"""Infotaxis and Entrotaxis on any categorical source posterior.

The planner asks, for each candidate measurement cell ``x``, how the next
reading ``z`` there would change the current source posterior ``p(s)`` (the
estimator's ``Belief.source_probs``):

* **Infotaxis** (Vergassola et al. 2007): move to the ``x`` that minimizes the
  expected posterior entropy ``E_z[H(s | z, x)] = H(s, Z) - H(Z)``
  (equivalently maximizes the mutual information ``I(s; z)``);
* **Entrotaxis** (Hutchinson et al. 2018): move to the ``x`` whose predictive
  measurement distribution ``p(z | x) = sum_s p(s) p(z | s, x)`` has the
  largest entropy.

Observation models ``p(z | s, x)`` (a :class:`ResponseModel` gives the mean
reading at ``x`` for a source in every cell):

* ``model="auto"`` (default): the estimator's own model when its belief
  carries one in ``info["response_model"]`` (the adjoint estimator: the
  adjoint of the transport; the dual-mode particle filter: its obstacle-aware
  Gaussian plume), else Vergassola's model;
* ``"vergassola"``: the 2-D hit rate
  ``R(r | r0) = R / ln(lambda / a) exp((r - r0) . V / (2 D)) K0(|r - r0| / lambda)``,
  ``lambda = sqrt(D tau / (1 + V^2 tau / (4 D)))``, with ``|r - r0|`` the
  obstacle-aware path length (Dijkstra on the free cells; the advection
  factor uses the straight displacement) and ``V`` the mean wind of the
  belief (or of the wind readings so far); defaults for an indoor room:
  ``D = 0.1 m^2/s`` (eddy diffusivity), ``tau = 100 s``, ``a = 0.1 m`` (one
  cell), ``R = 1 hit/s``, ``dt = 1 s`` per measurement.

Hit models: ``"poisson"``: the number of hits ``h ~ Poisson(mean)`` (outcomes
``0 .. h_max - 1`` and ``>= h_max``), Vergassola's; ``"gaussian"``: the reading
``z ~ N(mean, sigma(mean)^2)`` (the model's Table I-like noise, negative
values clipped to 0), discretized into ``n_bins`` outcome bins spanning
``[0, max mean + 2 sigma]`` per candidate.  ``"auto"``: Poisson for a
hit-rate model, Gaussian for a concentration (ppm) model.

Practicalities (assumed, not in the papers): the posterior is restricted to
its most probable cells covering ``mass`` (99.9 %, at most ``max_sources``)
and renormalized; candidates are free cells reachable within ``radius_m``
of the robot (the original moves one step; our robot measures at any cell
it drives to), cells already measured excluded unless nothing else is left,
at most ``max_candidates`` of them drawn at random (the episode's planner
generator); ties go to the nearest cell.  The "source found" term of the
original (entropy 0 if ``x`` is the source) is left out: our search does not
end on reaching the source, the reading there informs through the model.
Termination: the normalized entropy test of the paper's planner,
``H(p) <= eta log N`` (``eta = 0.65``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from scipy import special

from dgse.belief.belief import Belief
from dgse.errors import InputDataError
from dgse.localization import graph_distances
from dgse.planning.paths import Cell, FreeSpaceGraph, graph_for
from dgse.planning.planners import PlannerBase, SearchHistory

__all__ = [
    "InfotaxisPlanner",
    "ObstacleGaussianModel",
    "ResponseModel",
    "VergassolaModel",
    "expected_entropy",
    "information_gain",
    "make_entrotaxis",
    "make_infotaxis",
    "outcome_probabilities",
    "select_candidates",
]


@runtime_checkable
class ResponseModel(Protocol):
    """Predicted readings at measurement cells for a source in every cell.

    Attributes:
        kind: ``"ppm"`` (a concentration; Gaussian hit model) or ``"counts"``
            (a hit count per measurement; Poisson hit model).
    """

    kind: str

    def mean_readings(self, cells: np.ndarray) -> np.ndarray:
        """``(k, H, W)``: the expected reading at ``cells[k]`` for a source in each map cell."""
        ...

    def reading_sigma(self, mean: np.ndarray) -> np.ndarray:
        """Standard deviation of a reading whose expected value is ``mean`` (Gaussian hit model)."""
        ...


@dataclass(eq=False)
class ObstacleGaussianModel:
    """``E[z at x | s] = Q(s) exp(-d_obs(x, s)^2 / (2 sigma_m^2))`` ppm (Kim et al.'s indoor model).

    Attributes:
        graph: the map's move graph (``d_obs`` = Dijkstra path length, m).
        q: peak concentration ``Q`` (ppm), a scalar or ``(H, W)`` per source cell.
        sigma_m: plume width, m.
        alpha: proportional noise, ``sigma(mu) = alpha mu + sigma_env``.
        sigma_env: noise floor, ppm.
    """

    graph: FreeSpaceGraph
    q: float | np.ndarray
    sigma_m: float
    alpha: float
    sigma_env: float
    kind: str = "ppm"

    def mean_readings(self, cells: np.ndarray) -> np.ndarray:
        d = graph_distances(self.graph, cells).reshape(-1, *self.graph.shape)
        with np.errstate(invalid="ignore"):
            g = np.where(np.isfinite(d), np.exp(-(d**2) / (2.0 * self.sigma_m**2)), 0.0)
        return g * np.asarray(self.q, dtype=np.float64)

    def reading_sigma(self, mean: np.ndarray) -> np.ndarray:
        return self.alpha * np.asarray(mean) + self.sigma_env

    def __repr__(self) -> str:
        return f"<ObstacleGaussianModel sigma_m={self.sigma_m:.3g}>"


@dataclass(eq=False)
class VergassolaModel:
    """Vergassola et al.'s 2-D hit rate with obstacle-aware distances (see the module docstring).

    Attributes:
        graph: the map's move graph.
        wind: mean wind ``(V_x, V_y)``, m/s.
        diffusivity: ``D``, m^2/s.
        lifetime_s: ``tau``, s.
        sensor_radius_m: ``a``, m.
        rate_hz: ``R``, hits/s at the source scale.
        dt_s: measurement duration, s (mean count = rate x dt).
    """

    graph: FreeSpaceGraph
    wind: tuple[float, float] = (0.0, 0.0)
    diffusivity: float = 0.1
    lifetime_s: float = 100.0
    sensor_radius_m: float = 0.1
    rate_hz: float = 1.0
    dt_s: float = 1.0
    kind: str = "counts"

    @property
    def correlation_length(self) -> float:
        """``lambda = sqrt(D tau / (1 + V^2 tau / (4 D)))``, m."""
        v2 = float(self.wind[0]) ** 2 + float(self.wind[1]) ** 2
        D, tau = self.diffusivity, self.lifetime_s
        return math.sqrt(D * tau / (1.0 + v2 * tau / (4.0 * D)))

    def mean_readings(self, cells: np.ndarray) -> np.ndarray:
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        H, W = self.graph.shape
        res = self.graph.resolution
        d = graph_distances(self.graph, c).reshape(-1, H, W)
        lam = self.correlation_length
        a = self.sensor_radius_m
        log_norm = math.log(self.rate_hz * self.dt_s) - math.log(math.log(max(lam / a, 1.01)))
        ys = (np.arange(H) + 0.5) * res
        xs = (np.arange(W) + 0.5) * res
        # displacement sensor - source, per candidate
        rx = (c[:, 1, None, None] + 0.5) * res - xs[None, None, :]
        ry = (c[:, 0, None, None] + 0.5) * res - ys[None, :, None]
        adv = (rx * self.wind[0] + ry * self.wind[1]) / (2.0 * self.diffusivity)
        dd = np.maximum(np.where(np.isfinite(d), d, 0.0), a)
        x = dd / lam
        logk0 = np.log(np.maximum(special.k0e(x), 1e-300)) - x
        out = np.exp(np.minimum(log_norm + adv + logk0, 50.0))
        return np.where(np.isfinite(d), out, 0.0)

    def reading_sigma(self, mean: np.ndarray) -> np.ndarray:
        return np.sqrt(np.maximum(np.asarray(mean), 1e-12))

    def __repr__(self) -> str:
        return f"<VergassolaModel V=({self.wind[0]:.2g}, {self.wind[1]:.2g})>"


# -- the information computation ----------------------------------------------------------------
def outcome_probabilities(
    mean: np.ndarray, hit: Literal["poisson", "gaussian"], sigma: np.ndarray | None = None, n_bins: int = 12
) -> np.ndarray:
    """``(C, B, K)`` probability of each discretized outcome at each candidate for each source.

    Args:
        mean: ``(C, K)`` expected readings (counts for Poisson, ppm for Gaussian).
        hit: the hit model.
        sigma: ``(C, K)`` reading standard deviations (Gaussian only).
        n_bins: outcome bins of the Gaussian model (Poisson: counts up to a data-driven cap).
    """
    mu = np.maximum(np.asarray(mean, dtype=np.float64), 0.0)
    if hit == "poisson":
        top = float(mu.max()) if mu.size else 0.0
        h_max = int(min(max(math.ceil(top + 4.0 * math.sqrt(top)) + 1, 2), 40))
        h = np.arange(h_max, dtype=np.float64)[None, :, None]
        pmf = special.pdtr(h, mu[:, None, :]) - np.concatenate(
            [np.zeros_like(mu[:, None, :]), special.pdtr(h[:, :-1], mu[:, None, :])], axis=1
        )
        tail = 1.0 - special.pdtr(h_max - 1, mu)[:, None, :]
        P = np.concatenate([pmf, tail], axis=1)
    elif hit == "gaussian":
        if sigma is None:
            raise InputDataError("the Gaussian hit model needs reading standard deviations")
        s = np.maximum(np.asarray(sigma, dtype=np.float64), 1e-12)
        B = max(int(n_bins), 2)
        ktop = np.argmax(mu, axis=1)
        rows = np.arange(mu.shape[0])
        top = mu[rows, ktop] + 2.0 * s[rows, ktop]
        frac = np.linspace(1.0 / (B - 1), 1.0, B - 1)
        inner = top[:, None] * frac[None, :]  # (C, B-1)
        edges = np.concatenate(
            [np.full((mu.shape[0], 1), -np.inf), inner, np.full((mu.shape[0], 1), np.inf)], axis=1
        )
        cdf = special.ndtr((edges[:, :, None] - mu[:, None, :]) / s[:, None, :])  # (C, B+1, K)
        P = np.diff(cdf, axis=1)
    else:
        raise InputDataError(f"unknown hit model {hit!r}; use 'poisson' or 'gaussian'")
    return np.clip(P, 0.0, 1.0)


def _xlogx(a: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a > 0, a * np.log(np.where(a > 0, a, 1.0)), 0.0)


def expected_entropy(prior: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(E_z[H(s | z)], H(z))`` per candidate, nats.

    Args:
        prior: ``(K,)`` source probabilities (sum 1).
        P: ``(C, B, K)`` outcome probabilities given each source.

    ``E[H(s | z)] = H(s, z) - H(z)`` with the joint ``J[b, k] = P[b, k] p_k``.
    """
    p = np.asarray(prior, dtype=np.float64)
    J = P * p[None, None, :]
    Pz = J.sum(axis=2)
    h_joint = -_xlogx(J).sum(axis=(1, 2))
    h_z = -_xlogx(Pz).sum(axis=1)
    return h_joint - h_z, h_z


def information_gain(
    probs: np.ndarray,
    model: ResponseModel,
    cells: np.ndarray,
    *,
    hit: Literal["auto", "poisson", "gaussian"] = "auto",
    mass: float = 0.999,
    max_sources: int = 1500,
    n_bins: int = 12,
) -> tuple[np.ndarray, np.ndarray]:
    """``(expected entropy reduction, predictive entropy)`` of a reading at each of ``cells``, nats.

    Args:
        probs: ``(H, W)`` categorical source posterior.
        model: predicts the mean reading at a cell for a source in each cell.
        cells: ``(C, 2)`` candidate measurement cells.
        hit: hit model (``"auto"``: Poisson for ``kind="counts"``, Gaussian for ``"ppm"``).
        mass: posterior mass kept (most probable cells), at most ``max_sources`` cells.
        n_bins: Gaussian outcome bins.
    """
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    if len(c) == 0:
        return np.zeros(0), np.zeros(0)
    p = np.asarray(probs, dtype=np.float64).reshape(-1)
    order = np.argsort(p)[::-1]
    k = int(np.searchsorted(np.cumsum(p[order]), mass * p.sum())) + 1
    keep = order[: max(1, min(k, int(max_sources)))]
    keep = keep[p[keep] > 0] if (p[keep] > 0).any() else keep[:1]
    pk = p[keep] / p[keep].sum()
    h0 = float(-_xlogx(pk).sum())
    mean = model.mean_readings(c).reshape(len(c), -1)[:, keep]
    hm = hit if hit != "auto" else ("poisson" if model.kind == "counts" else "gaussian")
    sigma = model.reading_sigma(mean) if hm == "gaussian" else None
    P = outcome_probabilities(mean, hm, sigma, n_bins)  # type: ignore[arg-type]
    eh, hz = expected_entropy(pk, P)
    return np.maximum(h0 - eh, 0.0), hz


def select_candidates(
    free: np.ndarray,
    distances: np.ndarray,
    robot_cell: Cell,
    radius_m: float,
    max_candidates: int,
    rng: np.random.Generator,
    measured: np.ndarray | None = None,
) -> np.ndarray:
    """``int64 (C, 2)`` reachable free cells within ``radius_m`` path length (robot cell excluded).

    Measured cells are left out unless nothing else is in reach; when nothing
    is within ``radius_m`` the radius doubles until something is.  At most
    ``max_candidates`` are drawn at random without replacement.
    """
    d = np.asarray(distances, dtype=np.float64)
    ok = free & np.isfinite(d)
    ok[int(robot_cell[0]), int(robot_cell[1])] = False
    if not ok.any():
        return np.zeros((0, 2), np.int64)
    if measured is not None and (ok & ~measured).any():
        ok &= ~measured
    r = float(radius_m)
    finite_max = float(d[ok].max())
    while True:
        sel = ok & (d <= r)
        if sel.any() or r > finite_max:
            break
        r *= 2.0
    cells = np.argwhere(sel)
    if len(cells) > max_candidates:
        cells = cells[np.sort(rng.choice(len(cells), size=int(max_candidates), replace=False))]
    return cells.astype(np.int64)


def mean_wind(belief: Belief, history: SearchHistory | None) -> tuple[float, float]:
    """The belief's mean wind over free cells, else the mean of the wind readings, else 0."""
    if belief.wind_mean is not None:
        w = belief.wind_mean[:, belief.free]
        return float(w[0].mean()), float(w[1].mean())
    if history is not None and len(history.observations):
        w = history.observations.wind.mean(axis=0)
        return float(w[0]), float(w[1])
    return 0.0, 0.0


# -- the planner ------------------------------------------------------------------------------
@dataclass
class InfotaxisPlanner(PlannerBase):
    """Infotaxis / Entrotaxis planner on any belief (see the module docstring).

    Args:
        criterion: ``"infotaxis"`` (min expected entropy) or ``"entrotaxis"`` (max predictive entropy).
        model: ``"auto"``, ``"belief"`` (the belief's ``info["response_model"]``, required), ``"vergassola"``.
        hit: ``"auto"``, ``"poisson"`` or ``"gaussian"``.
        radius_m: candidate cells within this path length of the robot, m.
        max_candidates: candidates evaluated per decision.
        max_sources, mass: posterior truncation.
        n_bins: Gaussian outcome bins.
        eta: stop when ``H(p) <= eta log N``.
        exclude_measured: skip cells already measured (unless nothing else is left).
        diffusivity, lifetime_s, sensor_radius_m, rate_hz, dt_s: Vergassola's model.
    """

    criterion: Literal["infotaxis", "entrotaxis"] = "infotaxis"
    model: Literal["auto", "belief", "vergassola"] = "auto"
    hit: Literal["auto", "poisson", "gaussian"] = "auto"
    radius_m: float = 1.0
    max_candidates: int = 48
    max_sources: int = 1500
    mass: float = 0.999
    n_bins: int = 12
    eta: float = 0.65
    exclude_measured: bool = True
    diffusivity: float = 0.1
    lifetime_s: float = 100.0
    sensor_radius_m: float = 0.1
    rate_hz: float = 1.0
    dt_s: float = 1.0
    name: str = field(default="infotaxis", init=False)
    last_scores: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.criterion not in ("infotaxis", "entrotaxis"):
            raise InputDataError(f"criterion must be 'infotaxis' or 'entrotaxis', got {self.criterion!r}")
        if self.model not in ("auto", "belief", "vergassola"):
            raise InputDataError(f"model must be 'auto', 'belief' or 'vergassola', got {self.model!r}")
        if self.hit not in ("auto", "poisson", "gaussian"):
            raise InputDataError(f"hit must be 'auto', 'poisson' or 'gaussian', got {self.hit!r}")
        if not (self.radius_m > 0 and int(self.max_candidates) >= 1):
            raise InputDataError("radius_m must be > 0 and max_candidates >= 1")
        if not (0.0 <= float(self.eta) <= 1.0):
            raise InputDataError(f"eta must lie in [0, 1], got {self.eta}")
        for k in ("diffusivity", "lifetime_s", "sensor_radius_m", "rate_hz", "dt_s"):
            if not float(getattr(self, k)) > 0:
                raise InputDataError(f"{k} must be > 0")
        self.name = self.criterion

    def reset(self) -> None:
        """Forget the last decision's scores."""
        self.last_scores = {}

    def should_stop(self, belief: Belief, history: SearchHistory | None = None) -> bool:
        """``H(p) <= eta log N`` (normalized entropy test)."""
        return belief.normalized_entropy() <= self.eta

    def response_model(self, belief: Belief, history: SearchHistory | None = None) -> ResponseModel:
        """The observation model used for ``belief`` (see ``model``)."""
        own = belief.info.get("response_model")
        if self.model in ("auto", "belief") and own is not None:
            if not isinstance(own, ResponseModel):
                raise InputDataError("belief.info['response_model'] is not a ResponseModel")
            return own
        if self.model == "belief":
            raise InputDataError(
                f"belief of {belief.method!r} carries no response model; use model='vergassola'"
            )
        graph = history.graph if history is not None else graph_for(belief.occupancy, belief.resolution)
        return VergassolaModel(
            graph,
            mean_wind(belief, history),
            self.diffusivity,
            self.lifetime_s,
            self.sensor_radius_m,
            self.rate_hz,
            self.dt_s,
        )

    def scores(self, belief: Belief, cells: np.ndarray, history: SearchHistory | None = None) -> np.ndarray:
        """Score of each candidate (higher is better): information gain or predictive entropy, nats."""
        model = self.response_model(belief, history)
        gain, hz = information_gain(
            belief.source_probs,
            model,
            cells,
            hit=self.hit,
            mass=self.mass,
            max_sources=self.max_sources,
            n_bins=self.n_bins,
        )
        return gain if self.criterion == "infotaxis" else hz

    def next_goal(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory | None = None
    ) -> Cell | None:
        """The candidate with the best score (ties: nearest, then lowest index), or None if none."""
        rng = history.rng if history is not None else np.random.default_rng(0)
        measured = history.measured if (history is not None and self.exclude_measured) else None
        cells = select_candidates(
            belief.free, distances, robot_cell, self.radius_m, int(self.max_candidates), rng, measured
        )
        if len(cells) == 0:
            return None
        s = self.scores(belief, cells, history)
        self.last_scores = {"cells": cells, "scores": s}
        return best_cell(cells, s, distances)


def best_cell(cells: np.ndarray, scores: np.ndarray, distances: np.ndarray) -> Cell:
    """The cell with the highest score; ties (relative ``1e-9``) to the nearest, then the lowest index."""
    s = np.asarray(scores, dtype=np.float64)
    top = float(s.max())
    ties = np.flatnonzero(s >= top - 1e-9 * max(abs(top), 1e-300))
    d = np.asarray(distances)[cells[ties, 0], cells[ties, 1]]
    W = np.asarray(distances).shape[1]
    flat = cells[ties, 0] * W + cells[ties, 1]
    k = ties[np.lexsort((flat, d))[0]]
    return (int(cells[k, 0]), int(cells[k, 1]))


def _planner_kwargs(kwargs: dict[str, object], what: str) -> dict[str, object]:
    allowed = {f.name for f in fields(InfotaxisPlanner) if f.init and f.name != "criterion"}
    bad = sorted(set(kwargs) - allowed)
    if bad:
        raise InputDataError(
            f"planner {what!r} does not take {', '.join(bad)}; options: {', '.join(sorted(allowed))}"
        )
    return kwargs


def make_infotaxis(**kwargs: object) -> InfotaxisPlanner:
    """Registry factory ``infotaxis``: :class:`InfotaxisPlanner` with ``criterion="infotaxis"``."""
    return InfotaxisPlanner(criterion="infotaxis", **_planner_kwargs(kwargs, "infotaxis"))  # type: ignore[arg-type]


def make_entrotaxis(**kwargs: object) -> InfotaxisPlanner:
    """Registry factory ``entrotaxis``: :class:`InfotaxisPlanner` with ``criterion="entrotaxis"``."""
    return InfotaxisPlanner(criterion="entrotaxis", **_planner_kwargs(kwargs, "entrotaxis"))  # type: ignore[arg-type]
