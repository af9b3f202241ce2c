r"""The dual-mode planner's estimator (Kim et al. 2025): a particle filter, and its planner.

Estimator (registry ``dualmode``)
---------------------------------
State ``(x0, y0, Q)``: source position (m) and the peak concentration ``Q``
(ppm; the model's strength, not a release rate).  Dispersion model for
negligible airflow, obstacle-aware:

``R(x | x0, Q) = Q exp(-d_obs(x, x0)^2 / (2 sigma_m^2))``

with ``d_obs`` the shortest obstacle-free path length (Dijkstra on the free
cells, 8-connected, no corner cutting).  Distances are computed sensor-centric:
one Dijkstra from every sensor cell to every cell (cached per map and cell),
and a particle's distance to sensor ``i`` is that row at the particle's cell.

Sensor model, Gaussian as Table I: ``z ~ N(R, (alpha R + sigma_env)^2)``.
The robot does not know the Table I parameters; the filter uses their
expected values: ``alpha = 0.5`` (``alpha_g ~ U[0, 1]``) and ``sigma_env =
0.25 * mean(z)`` (``sigma_env ~ U[0, 0.5] * mean(c)``, the mean reading
standing for the mean concentration), floored at ``1 % of max(z)`` (and 1e-3
ppm) so a map of zero readings keeps a finite likelihood.

Prior: positions uniform over the free cells (uniform within a cell), ``log Q``
uniform on ``[log(0.5 max z), log(100 max z)]`` (empirical-Bayes range; ``Q``
is a peak value, so at least about the largest reading).  ``N = 1000``
particles.  Readings are assimilated one at a time in the given order;
after each, if ``ESS = 1 / sum w^2 < N / 2``: systematic resampling, then
``n_mcmc`` Metropolis-Hastings moves per particle (Gaussian random walk on
``(x0, y0, log Q)``, step 0.5 x the particle cloud's spread, at least one
cell, accepted on the likelihood of *all* readings so far: resample-move,
Gilks & Berzuini 2001).  Between calls with growing readings (a robot's
search), the filter continues from the previous state when the new readings
extend the old ones and change neither the ``Q`` prior range nor
``sigma_env`` (both derived from the readings) by more than a factor 2
(``incremental``); otherwise it restarts from the prior with ``seed``.

Posterior map (``source_probs``): the particle weights binned to cells,
smoothed by a diffusion on the free cells of about ``kde_sigma_cells`` (1
cell; it does not cross walls, :func:`dgse.localization.blur_probs`) and
mixed with a uniform floor ``floor`` (1e-3 of the mass), so the
cross-entropy at any true source is finite (at most ``log(N_free /
floor)``).  ``log_conc_mean``/``var``: the model's predictive field from the
``conc_components`` most probable particle cells (16, weight-renormalized),
lognormal moment-matched.  No wind.

Assumptions where the paper (via a third-party reimplementation) is silent:
``sigma_m = 1.0 m`` (tune on validation data), the noise values above, the
``Q`` prior, the MCMC step, the smoothing.

Planner (registry ``dualmode``)
-------------------------------
A simplified but honest version of the dual-mode search:

* **local mode** (RRT-Infotaxis in the paper: an RRT of 50 vertices, step
  0.7 m, depth 4, branch information discounted by 0.8 per level): here 50
  random reachable cells within ``4 x 0.7 = 2.8 m`` path length play the
  vertices; each is scored by the Infotaxis information gain of one reading
  there (:mod:`dgse.localization.infotaxis`, with the filter's own plume
  model and Gaussian noise), discounted by ``0.8^(ceil(d / 0.7) - 1)``.
  Simplified: no tree, no accumulation of information along a branch (each
  candidate is a single next measurement), the path to it is the shortest one;
* **global mode**: when the best local gain falls under an adaptive
  threshold, ``switch_ratio`` (0.5) x the mean of the best local gains so far
  in this episode, the robot goes to a frontier of the explored region (free
  cells adjacent to, but farther than ``explored_radius_m`` = 1 m from, every
  cell of the trajectory), chosen by information gain x ``exp(-d / 5 m)``.
  The paper's exact threshold rule is not given in the material we had;
  this is our choice;
* **termination**: the posterior position spread ``sqrt(var x + var y)``
  below ``stop_std_m`` (0.5 m).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numba as nb
import numpy as np
from scipy import ndimage

from dgse.belief.belief import Belief, log_moments_from_ppm, normalize_source_probs
from dgse.belief.inputs import check_inputs, map_key
from dgse.belief.knowledge import KnowledgeUser
from dgse.errors import InputDataError
from dgse.localization import blur_probs, free_graph, graph_distances
from dgse.localization.infotaxis import (
    InfotaxisPlanner,
    ObstacleGaussianModel,
    best_cell,
    select_candidates,
)
from dgse.planning.paths import Cell
from dgse.planning.planners import PlannerBase, SearchHistory
from dgse.sensing.sensors import Observations

__all__ = ["DualModePlanner", "ParticleFilterEstimator", "make_dualmode", "make_dualmode_planner"]

#: Sensor distance rows kept per map (one float per cell each).
MAX_CACHED_ROWS = 1024


@nb.njit(cache=True)
def _loglik(cell, logq, D, rows, z, alpha, senv, inv2s2):  # pragma: no cover - numba
    """Sum over readings ``k`` of ``log N(z_k; R, (alpha R + senv)^2)`` (constants dropped) per particle."""
    n = cell.size
    out = np.zeros(n)
    for p in range(n):
        c = cell[p]
        if c < 0:
            out[p] = -np.inf
            continue
        q = math.exp(logq[p])
        s = 0.0
        for k in range(rows.size):
            d = D[rows[k], c]
            mu = q * math.exp(-d * d * inv2s2) if d < np.inf else 0.0
            sig = alpha * mu + senv
            r = (z[k] - mu) / sig
            s += -0.5 * r * r - math.log(sig)
        out[p] = s
    return out


def _systematic(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling indices for normalized weights ``w``."""
    n = w.size
    u = (rng.random() + np.arange(n)) / n
    idx = np.searchsorted(np.cumsum(w), u)
    return np.minimum(idx, n - 1)


@dataclass(eq=False)
class _State:
    key: str
    seed: int | None
    cells: np.ndarray
    gas: np.ndarray
    x: np.ndarray
    y: np.ndarray
    logq: np.ndarray
    logw: np.ndarray
    rng: np.random.Generator
    q_range: tuple[float, float]
    senv: float
    n_resample: int = 0
    n_accept: int = 0
    n_proposed: int = 0


@dataclass(eq=False)
class ParticleFilterEstimator(KnowledgeUser):
    """Particle filter over ``(x0, y0, Q)`` with the obstacle-aware Gaussian model (module docstring).

    Args:
        n_particles: ``N``.
        sigma_m: plume width ``sigma_m``, m.
        alpha: proportional noise of the sensor model.
        sigma_env_fraction: ``sigma_env = sigma_env_fraction * mean(z)``.
        sigma_floor_fraction: ``sigma_env >= sigma_floor_fraction * max(z)`` (and >= 1e-3 ppm).
        q_range: ``Q`` prior range as multiples of ``max(z)`` (log-uniform).
        n_mcmc: Metropolis-Hastings moves after each resampling.
        ess_fraction: resample when ``ESS < ess_fraction * N``.
        kde_sigma_cells: smoothing of the posterior map, cells.
        floor: uniform mass mixed into the posterior map.
        conc_components: particle cells used for the concentration estimate.
        incremental: continue from the last state when readings only grow.
        seed: random seed (the evaluation sets a per-estimate seed).
    """

    n_particles: int = 1000
    sigma_m: float = 1.0
    alpha: float = 0.5
    sigma_env_fraction: float = 0.25
    sigma_floor_fraction: float = 0.01
    q_range: tuple[float, float] = (0.5, 100.0)
    n_mcmc: int = 2
    ess_fraction: float = 0.5
    kde_sigma_cells: float = 1.0
    floor: float = 1e-3
    conc_components: int = 16
    incremental: bool = True
    seed: int | None = 0
    name: str = field(default="dualmode", init=False)
    _dist: dict[str, dict[tuple[int, int], np.ndarray]] = field(default_factory=dict, init=False, repr=False)
    _state: _State | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if int(self.n_particles) < 10:
            raise InputDataError(f"n_particles must be >= 10, got {self.n_particles}")
        for k in ("sigma_m", "sigma_env_fraction", "sigma_floor_fraction"):
            if not float(getattr(self, k)) > 0:
                raise InputDataError(f"{k} must be > 0")
        if not (float(self.alpha) >= 0 and 0 < self.ess_fraction <= 1 and 0 <= self.floor < 1):
            raise InputDataError("need alpha >= 0, 0 < ess_fraction <= 1, 0 <= floor < 1")
        lo, hi = (float(v) for v in self.q_range)
        if not (0 < lo < hi):
            raise InputDataError(f"q_range must be 0 < low < high, got {self.q_range}")

    # -- distances ----------------------------------------------------------------------
    def _distance_rows(self, occ: np.ndarray, res: float, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(D (u, H*W), row of each reading)`` for the unique sensor cells (cached per map)."""
        key = map_key(occ, res)
        cache = self._dist.setdefault(key, {})
        if len(self._dist) > 4:
            for old in list(self._dist)[:-4]:
                del self._dist[old]
        keys = [(int(i), int(j)) for i, j in cells]
        new = sorted({k for k in keys if k not in cache})
        if new:
            d = graph_distances(free_graph(occ, res), np.array(new, dtype=np.int64))
            for k, row in zip(new, d, strict=True):
                cache[k] = row
        uniq = sorted(set(keys))
        pos = {k: n for n, k in enumerate(uniq)}
        D = np.stack([cache[k] for k in uniq])
        while len(cache) > MAX_CACHED_ROWS:  # oldest first
            del cache[next(iter(cache))]
        return D, np.array([pos[k] for k in keys], dtype=np.int64)

    # -- filter -------------------------------------------------------------------------
    def _cells_of(self, x: np.ndarray, y: np.ndarray, occ: np.ndarray, res: float) -> np.ndarray:
        H, W = occ.shape
        j = np.floor(x / res).astype(np.int64)
        i = np.floor(y / res).astype(np.int64)
        ok = (i >= 0) & (i < H) & (j >= 0) & (j < W)
        flat = np.where(ok, i * W + j, 0)
        ok &= occ.reshape(-1)[flat] == 0
        return np.where(ok, flat, -1)

    def _data_scales(self, obs: Observations) -> tuple[tuple[float, float], float]:
        """``((log Q low, log Q high), sigma_env)`` from the readings (module docstring)."""
        zmax = max(float(obs.gas.max()), 1e-3)
        lo, hi = (float(v) * zmax for v in self.q_range)
        senv = max(
            self.sigma_env_fraction * float(obs.gas.mean()),
            self.sigma_floor_fraction * float(obs.gas.max()),
            1e-3,
        )
        return (math.log(lo), math.log(hi)), senv

    def _init_state(self, key: str, occ: np.ndarray, res: float, obs: Observations) -> _State:
        rng = np.random.default_rng(self.seed)
        n = int(self.n_particles)
        free = np.flatnonzero(occ.reshape(-1) == 0)
        W = occ.shape[1]
        pick = free[rng.integers(free.size, size=n)]
        x = ((pick % W) + rng.random(n)) * res
        y = ((pick // W) + rng.random(n)) * res
        (lo, hi), senv = self._data_scales(obs)
        logq = rng.uniform(lo, hi, n)
        empty = np.zeros(0)
        return _State(
            key,
            self.seed,
            np.zeros((0, 2), np.int64),
            empty,
            x,
            y,
            logq,
            np.full(n, -math.log(n)),
            rng,
            (lo, hi),
            senv,
        )

    def _reuse(self, key: str, obs: Observations) -> _State | None:
        st = self._state
        if not self.incremental or st is None or st.key != key or st.seed != self.seed:
            return None
        k = len(st.gas)
        if len(obs) < k or not (
            np.array_equal(obs.cells[:k], st.cells) and np.array_equal(obs.gas[:k], st.gas)
        ):
            return None
        # the prior range of Q and the noise floor come from the readings: when the new
        # readings change them by more than a factor 2, start again from the prior
        (_, hi), senv = self._data_scales(obs)
        if abs(hi - st.q_range[1]) > math.log(2.0) or abs(math.log(senv / st.senv)) > math.log(2.0):
            return None
        return st

    def _run(self, st: _State, occ: np.ndarray, res: float, obs: Observations) -> None:
        D, rows = self._distance_rows(occ, res, obs.cells)
        z = obs.gas.astype(np.float64)
        inv2s2 = 1.0 / (2.0 * self.sigma_m**2)
        n = st.x.size
        lo, hi = st.q_range
        start = len(st.gas)
        for k in range(start, len(obs)):
            cell = self._cells_of(st.x, st.y, occ, res)
            st.logw = st.logw + _loglik(
                cell, st.logq, D, rows[k : k + 1], z[k : k + 1], self.alpha, st.senv, inv2s2
            )
            top = st.logw.max()
            w = np.exp(st.logw - top)
            w /= w.sum()
            st.logw = np.log(np.maximum(w, 1e-300))
            ess = 1.0 / float((w * w).sum())
            if ess >= self.ess_fraction * n:
                continue
            idx = _systematic(w, st.rng)
            st.x, st.y, st.logq = st.x[idx], st.y[idx], st.logq[idx]
            st.logw = np.full(n, -math.log(n))
            st.n_resample += 1
            cell = self._cells_of(st.x, st.y, occ, res)
            ll = _loglik(cell, st.logq, D, rows[: k + 1], z[: k + 1], self.alpha, st.senv, inv2s2)
            for _ in range(int(self.n_mcmc)):
                sx = max(0.5 * float(np.std(st.x)), res)
                sy = max(0.5 * float(np.std(st.y)), res)
                sq = max(0.5 * float(np.std(st.logq)), 0.02)
                x2 = st.x + st.rng.normal(0.0, sx, n)
                y2 = st.y + st.rng.normal(0.0, sy, n)
                q2 = st.logq + st.rng.normal(0.0, sq, n)
                c2 = self._cells_of(x2, y2, occ, res)
                c2 = np.where((q2 >= lo) & (q2 <= hi), c2, -1)
                ll2 = _loglik(c2, q2, D, rows[: k + 1], z[: k + 1], self.alpha, st.senv, inv2s2)
                acc = np.log(st.rng.random(n)) < (ll2 - ll)
                st.x = np.where(acc, x2, st.x)
                st.y = np.where(acc, y2, st.y)
                st.logq = np.where(acc, q2, st.logq)
                ll = np.where(acc, ll2, ll)
                st.n_accept += int(acc.sum())
                st.n_proposed += n
        st.cells = obs.cells.copy()
        st.gas = obs.gas.copy()

    # -- estimate ------------------------------------------------------------------------
    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The particle posterior as a categorical map (module docstring).

        Raises:
            InputDataError: no readings, or a reading outside the map or in a wall.
        """
        t0 = time.perf_counter()
        occ, res, obs = check_inputs(occupancy, resolution, observations)
        key = map_key(occ, res)
        st = self._reuse(key, obs)
        resumed = st is not None
        if st is None:
            st = self._init_state(key, occ, res, obs)
        self._run(st, occ, res, obs)
        self._state = st
        H, W = occ.shape
        w = np.exp(st.logw - st.logw.max())
        w /= w.sum()
        cell = self._cells_of(st.x, st.y, occ, res)
        ok = cell >= 0
        hist = np.bincount(cell[ok], weights=w[ok], minlength=H * W).reshape(H, W)
        probs = normalize_source_probs(blur_probs(hist, occ, self.kde_sigma_cells, self.floor), occ)
        # per-cell Q (weighted mean of log Q), global mean elsewhere
        logq_mean = float(w @ st.logq)
        sw = np.bincount(cell[ok], weights=w[ok], minlength=H * W)
        sq = np.bincount(cell[ok], weights=(w * st.logq)[ok], minlength=H * W)
        qmap = np.exp(np.where(sw > 0, sq / np.maximum(sw, 1e-300), logq_mean)).reshape(H, W)
        graph = free_graph(occ, res)
        model = ObstacleGaussianModel(graph, qmap, self.sigma_m, self.alpha, st.senv)
        # predictive concentration from the heaviest particle cells
        order = np.argsort(sw)[::-1][: max(1, int(self.conc_components))]
        order = order[sw[order] > 0]
        Wk = sw[order] / sw[order].sum()
        d = graph_distances(graph, np.stack([order // W, order % W], axis=1))
        with np.errstate(invalid="ignore"):
            g = np.where(np.isfinite(d), np.exp(-(d**2) / (2.0 * self.sigma_m**2)), 0.0)
        f = g * qmap.reshape(-1)[order][:, None]
        mean = Wk @ f
        var = np.maximum(Wk @ f**2 - mean**2, 0.0)
        mu, s2 = log_moments_from_ppm(
            np.where(occ == 0, mean.reshape(H, W), 0.0), np.where(occ == 0, var.reshape(H, W), 0.0)
        )
        xm, ym = float(w @ st.x), float(w @ st.y)
        spread = math.sqrt(float(w @ ((st.x - xm) ** 2 + (st.y - ym) ** 2)))
        info: dict[str, Any] = {
            "method": self.name,
            "n_observations": len(obs),
            "n_particles": int(st.x.size),
            "ess": 1.0 / float((w * w).sum()),
            "n_resample": st.n_resample,
            "mcmc_acceptance": st.n_accept / max(st.n_proposed, 1),
            "resumed": resumed,
            "particle_mean_xy": [xm, ym],
            "position_std_m": spread,
            "q_mean_ppm": math.exp(logq_mean),
            "sigma_m": self.sigma_m,
            "sigma_env_ppm": st.senv,
            "alpha": self.alpha,
            "response_model": model,
            "seed": self.seed,
            "conc_space": "ppm",  # ppm moments of a mixture, stored as lognormal moments
        }
        info["seconds"] = time.perf_counter() - t0
        return Belief(occ, res, probs, log_conc_mean=mu, log_conc_var=s2, info=info)


def make_dualmode(**kwargs: Any) -> ParticleFilterEstimator:
    """Registry factory of the estimator ``dualmode``."""
    return ParticleFilterEstimator(**kwargs)


# -- the planner ---------------------------------------------------------------------------------
def position_spread(belief: Belief) -> float:
    """``sqrt(var x + var y)`` of the source posterior, m."""
    return math.sqrt(belief.source_variance())


@dataclass
class DualModePlanner(PlannerBase):
    """Local information-gain search with a global frontier mode (module docstring).

    Args:
        local_radius_m: reach of the local mode (depth 4 x step 0.7 m), m.
        n_vertices: local candidates per decision (the RRT's 50 vertices).
        step_m: the RRT step, m (sets the depth of a candidate for the discount).
        discount: information discount per depth level.
        switch_ratio: global mode when the best local gain < ratio x mean of past best gains.
        explored_radius_m: cells within this distance of the trajectory count as explored, m.
        global_length_m: distance scale of the frontier choice, m.
        max_frontiers: frontier candidates per decision.
        stop_std_m: stop when the posterior position spread is below this, m.
        hit, n_bins, mass, max_sources: information-gain settings (:mod:`.infotaxis`).
    """

    local_radius_m: float = 2.8
    n_vertices: int = 50
    step_m: float = 0.7
    discount: float = 0.8
    switch_ratio: float = 0.5
    explored_radius_m: float = 1.0
    global_length_m: float = 5.0
    max_frontiers: int = 50
    stop_std_m: float = 0.5
    hit: Literal["auto", "poisson", "gaussian"] = "auto"
    n_bins: int = 12
    mass: float = 0.999
    max_sources: int = 1500
    name: str = field(default="dualmode", init=False)
    gains: list[float] = field(default_factory=list, init=False, repr=False)
    modes: list[str] = field(default_factory=list, init=False, repr=False)

    def __post_init__(self) -> None:
        for k in ("local_radius_m", "step_m", "explored_radius_m", "global_length_m", "stop_std_m"):
            if not float(getattr(self, k)) > 0:
                raise InputDataError(f"{k} must be > 0")
        if not (0 < self.discount <= 1 and self.switch_ratio >= 0 and self.n_vertices >= 1):
            raise InputDataError("need 0 < discount <= 1, switch_ratio >= 0, n_vertices >= 1")

    def reset(self) -> None:
        """Forget the gains and modes of the previous episode."""
        self.gains = []
        self.modes = []

    def should_stop(self, belief: Belief, history: SearchHistory | None = None) -> bool:
        """The posterior position spread is below ``stop_std_m``."""
        return position_spread(belief) < self.stop_std_m

    def _gains(self, belief: Belief, cells: np.ndarray, history: SearchHistory | None) -> np.ndarray:
        """Information gain of each cell of ``cells`` (nats): Infotaxis's score with these settings."""
        infotaxis = InfotaxisPlanner(
            hit=self.hit, max_sources=self.max_sources, mass=self.mass, n_bins=self.n_bins
        )
        return infotaxis.scores(belief, cells, history)

    def frontier(self, belief: Belief, distances: np.ndarray, history: SearchHistory | None) -> np.ndarray:
        """``bool (H, W)``: reachable free cells bordering the explored region (module docstring)."""
        free = belief.free
        visited = np.zeros(belief.shape, dtype=bool)
        if history is not None:
            t = history.trajectory
            if len(t):
                visited[t[:, 0], t[:, 1]] = True
            visited |= history.measured
        if not visited.any():
            return np.zeros(belief.shape, dtype=bool)
        dist = ndimage.distance_transform_edt(~visited) * belief.resolution
        explored = (dist <= self.explored_radius_m) & free
        ring = ndimage.binary_dilation(explored, structure=np.ones((3, 3), bool)) & free & ~explored
        return ring & np.isfinite(distances)

    def next_goal(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory | None = None
    ) -> Cell | None:
        """Local-mode or global-mode goal (module docstring), or None when nothing is reachable."""
        rng = history.rng if history is not None else np.random.default_rng(0)
        measured = history.measured if history is not None else None
        d = np.asarray(distances, dtype=np.float64)
        cells = select_candidates(
            belief.free, d, robot_cell, self.local_radius_m, int(self.n_vertices), rng, measured
        )
        if len(cells) == 0:
            return None
        g = self._gains(belief, cells, history)
        depth = np.maximum(np.ceil(d[cells[:, 0], cells[:, 1]] / self.step_m) - 1.0, 0.0)
        gl = g * self.discount**depth
        best_local = float(gl.max())
        threshold = self.switch_ratio * float(np.mean(self.gains)) if self.gains else -np.inf
        self.gains.append(best_local)
        if best_local < threshold:
            ring = self.frontier(belief, d, history)
            ring[int(robot_cell[0]), int(robot_cell[1])] = False
            fc = np.argwhere(ring)
            if len(fc):
                if len(fc) > self.max_frontiers:
                    fc = fc[np.sort(rng.choice(len(fc), size=int(self.max_frontiers), replace=False))]
                gf = self._gains(belief, fc, history) * np.exp(-d[fc[:, 0], fc[:, 1]] / self.global_length_m)
                self.modes.append("global")
                return best_cell(fc, gf, d)
        self.modes.append("local")
        return best_cell(cells, gl, d)


def make_dualmode_planner(**kwargs: Any) -> DualModePlanner:
    """Registry factory of the planner ``dualmode``."""
    return DualModePlanner(**kwargs)
