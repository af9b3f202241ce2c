r"""PMFS (Ojeda et al. 2024): a gas hit map compared with filament simulations per source hypothesis.

Following MAPIRlab's public implementation (``PMFSLib``, ``Simulations``,
``MovingStatePMFS``), with the parameters of its public launch files (given
in cells of 0.25 m, the baseline note's cell size) converted to metres for
our 0.1 m grid.

1. **Hit map** (one update per reading, in order; the original updates up
   to ``maxUpdatesPerStop`` times per stop from a stream of readings, our
   robot has one reading per stop).  A reading is a hit if ``z >
   hit_threshold`` (0.1 ppm; or ``hit_threshold_fraction`` x the largest
   reading when that is set: the absolute value suits GADEN's release rates,
   not ours, and must be tuned on validation data).  In a window of
   ``window_m`` (0.5 m: 2 cells) around the robot, every free cell ``C`` in
   line of sight gets ``p = clamp(lerp(prior, v, K(C - R)), 0.001, 0.999)``
   with ``v = 0.6`` (hit) or ``0.1`` (miss), ``prior = 0.3`` and the
   anisotropic kernel ``K(o) = exp(-(o_par^2 / sigma_major^2 + o_perp^2 /
   sigma_minor^2) / 2)`` along the reading's wind (``sigma_major = s + k
   |w|``, ``sigma_minor = s / (1 + k |w| / s)``, ``s = 0.375 m``, ``k =
   0.375 m per m/s``: 1.5 cells and 1.5 cells per m/s).  The window values
   are propagated to the whole map along shortest obstacle-free paths: a
   cell at path distance ``d`` reached through window cell ``C`` gets
   ``K(d * (C - R) / |C - R|)`` (ties: the larger value).  Log-odds update
   ``l += logit(p) - logit(prior)``; confidence ``omega += g(d)``, ``conf =
   1 - exp(-omega / 1.0^2)``, with ``g`` the Gaussian of ``sigma_c = 0.25 m``
   scaled as the original's normalized pdf in 0.25 m cells (peak 0.40).
2. **Wind map** from the sparse wind readings.  PMFS asks a GMRF wind
   mapper (GMRF-wind).  :mod:`dgse.mapping`'s GW-GMRF computes gas and wind
   jointly with variances and is far too slow for a per-step call here
   (seconds to minutes on a 100 x 100 map), so this module uses its own
   wind-only GMRF: observation (``sigma 0.1``), smoothness between
   4-neighbour free cells (``0.825``) and a weak zero prior (``1000``), one
   sparse solve, i.e. an obstacle-aware harmonic interpolation of the wind
   readings.  Simplified: no mass-conservation or wall factors.
3. **Source hypotheses** on a quadtree: blocks of ``leaf_cells`` (12 cells,
   1.2 m; the original fuses leaves up to 5 cells of 0.25 m = 1.25 m) whose
   free cells form one 4-connected component (blocks cut by a wall are split
   first); each level's best ``refine_fraction`` (10 %) of the leaves are
   split in 4 (halves, rounded) and simulated again, down to single cells.
   A cell's likelihood is that of the finest leaf that covers it.
4. **Filament simulation** per hypothesis, in the wind map: 5 filaments per
   iteration released at random points of the leaf's free cells, moved by
   ``x += dt (w(cell) + N(0, noise^2 I))`` (``dt = 0.1 s``, ``noise = 0.5
   m/s``) in half-cell steps, stopping before a wall; a filament leaving the
   map is removed.  Warm-up (at ``2 dt``) until a filament leaves the map or
   ``max_warmup`` (500) iterations (at least ``min_warmup``, 0), then
   ``n_record`` (200) iterations: ``hitMap_s(c)`` = fraction of iterations
   with at least one filament in ``c``.  Without a layout the whole map edge
   is open (the original removes whatever leaves its map); with the layout
   (``layout=``/``case=``, openings only) filaments leave only through the
   inlets and outlets, as through the gaps of a GADEN map.  Each hypothesis
   has its own xorshift generator seeded from ``seed`` and its index, so
   results do not depend on the thread count (hypotheses run in parallel
   with numba's ``prange``).
5. **Likelihood** ``log L(s) = sum_c log(lerp(1, 1 - beta |p_hit(c) -
   hitMap_s(c)|, conf_c))`` over free cells, ``beta = 0.2`` (the baseline
   note's formula; the newest public code integrates over a discretized
   hit-frequency distribution instead).  Posterior over free cells:
   ``L`` normalized (no floor: it is as peaked as the product makes it).
   Known behaviour of this likelihood: it compares a hit *probability*
   (which saturates towards 0 or 1 where readings repeat, and drops to 0
   where hits are rarer than about half the readings, since a miss moves
   the log-odds more than a hit) with a hit *frequency*; hypotheses whose
   simulated plume is smaller (downstream, near an exit) are then favoured
   somewhat, as in the paper's observation that thresholding misrepresents
   the plume.

Planner (registry ``pmfs``): the open move set accumulates the free cells in
line of sight within ``move_radius_m`` (1.25 m: 5 cells) of every position
visited; the goal maximizes the exploration value ``sum_c (1 - conf_c)
exp(-|c - x| / 0.25 m)`` (over free cells within ``move_radius_m``; line of
sight not checked in this sum) during the first ``exploration_moves`` (5)
moves and with probability 0.05 afterwards, else ``Var_s[hitMap_s(x)] (1 -
conf_x)`` (variance over the first-level hypotheses weighted by their
posterior).  Stop when ``var x + var y`` of the posterior is below 1.5 m^2.
The original's estimate is the weighted mean of the top 5 % cells
(``info["estimate_top5_xy"]``); ``Belief.source_estimate`` is the common
probability-weighted mean.

Cost is dominated by the simulations (one per hypothesis, about 300 on a
100 x 100 map): seconds per estimate, as the paper's 7-9 s per step.
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numba as nb
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage

from dgse.belief.belief import Belief, probs_from_log
from dgse.belief.inputs import check_inputs
from dgse.belief.knowledge import Knowledge, KnowledgeUser
from dgse.errors import InputDataError
from dgse.localization.grid_dijkstra import expansions
from dgse.options import options_from
from dgse.planning.paths import Cell
from dgse.planning.planners import PlannerBase, SearchHistory
from dgse.sensing.sensors import Observations
from dgse.world.layout import Layout

__all__ = [
    "PMFSEstimator",
    "PMFSMaps",
    "PMFSParams",
    "PMFSPlanner",
    "hit_map",
    "hit_threshold",
    "hypothesis_log_likelihood",
    "make_pmfs",
    "simulate_hits",
    "wind_map",
]


# -- wind map -----------------------------------------------------------------------------
def wind_map(
    occupancy: np.ndarray,
    cells: np.ndarray,
    wind: np.ndarray,
    sigma_obs: float = 0.1,
    sigma_smooth: float = 0.825,
    sigma_prior: float = 1000.0,
) -> np.ndarray:
    """``(2, H, W)`` wind from sparse readings: a wind-only GMRF on the free cells (module docstring)."""
    occ = np.asarray(occupancy)
    free = occ == 0
    H, W = occ.shape
    idx = np.full((H, W), -1, np.int64)
    n = int(free.sum())
    idx[free] = np.arange(n)
    rows, cols = [], []
    for di, dj in ((0, 1), (1, 0)):
        a = free[: H - di, : W - dj] & free[di:, dj:]
        rows.append(idx[: H - di, : W - dj][a])
        cols.append(idx[di:, dj:][a])
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    ones = np.ones(r.size)
    adj = sp.coo_matrix((ones, (r, c)), shape=(n, n))
    adj = adj + adj.T
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    cc = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    k = idx[cc[:, 0], cc[:, 1]]
    obs_w = np.bincount(k, minlength=n).astype(np.float64)
    A = lap / sigma_smooth**2 + sp.diags(obs_w / sigma_obs**2 + 1.0 / sigma_prior**2)
    b = np.zeros((n, 2))
    np.add.at(b, k, np.asarray(wind, dtype=np.float64) / sigma_obs**2)
    x = spla.splu(A.tocsc()).solve(b)
    out = np.zeros((2, H, W))
    out[0][free] = x[:, 0]
    out[1][free] = x[:, 1]
    return out


# -- hit map ------------------------------------------------------------------------------------
@nb.njit(cache=True)
def _visible(free, i0, j0, i1, j1):  # pragma: no cover - numba
    """Line of sight between cell centres (sampled every quarter cell)."""
    di = i1 - i0
    dj = j1 - j0
    n = int(4 * max(abs(di), abs(dj))) + 1
    for k in range(n + 1):
        t = k / n
        i = math.floor(i0 + 0.5 + t * di)
        j = math.floor(j0 + 0.5 + t * dj)
        if not free[i, j]:
            return False
    return True


@nb.njit(cache=True)
def _logit(p):  # pragma: no cover - numba
    return math.log(p / (1.0 - p))


@nb.njit(cache=True)
def _falloff(vx, vy, ux, uy, s_major, s_minor, prior, value):  # pragma: no cover - numba
    """Log-odds of ``lerp(prior, value, K(v))`` clamped to [0.001, 0.999]; ``(ux, uy)``: wind direction."""
    a = vx * ux + vy * uy
    b = -vx * uy + vy * ux
    g = math.exp(-0.5 * (a * a / (s_major * s_major) + b * b / (s_minor * s_minor)))
    p = prior + (value - prior) * g
    p = min(max(p, 0.001), 0.999)
    return _logit(p)


@nb.njit(cache=True)
def _hit_update(free, ri, rj, res, window, ux, uy, s_major, s_minor, prior, value):  # pragma: no cover
    """One reading's log-odds map (``aux``, ``-inf`` = untouched) and path distance (m) from the robot."""
    H, W = free.shape
    dist = np.full((H, W), np.inf)
    aux = np.full((H, W), -np.inf)
    dirx = np.zeros((H, W))
    diry = np.zeros((H, W))
    done = np.zeros((H, W), dtype=np.bool_)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    dist[ri, rj] = 0.0
    aux[ri, rj] = _falloff(0.0, 0.0, ux, uy, s_major, s_minor, prior, value)
    done[ri, rj] = True
    for i in range(max(0, ri - window), min(H, ri + window + 1)):
        for j in range(max(0, rj - window), min(W, rj + window + 1)):
            if (i == ri and j == rj) or not free[i, j]:
                continue
            if not _visible(free, ri, rj, i, j):
                continue
            ox = (j - rj) * res
            oy = (i - ri) * res
            d = math.sqrt(ox * ox + oy * oy)
            dist[i, j] = d
            dirx[i, j] = ox / d
            diry[i, j] = oy / d
            aux[i, j] = _falloff(ox, oy, ux, uy, s_major, s_minor, prior, value)
            heapq.heappush(heap, (d, np.int64(i * W + j)))
    for i, j, ni, nj, nd in expansions(heap, done, free, res):
        nw = _falloff(dirx[i, j] * nd, diry[i, j] * nd, ux, uy, s_major, s_minor, prior, value)
        if nd < dist[ni, nj] - 1e-9:
            dist[ni, nj] = nd
            aux[ni, nj] = nw
            dirx[ni, nj] = dirx[i, j]
            diry[ni, nj] = diry[i, j]
            heapq.heappush(heap, (nd, np.int64(ni * W + nj)))
        elif abs(nd - dist[ni, nj]) <= 1e-9 and nw > aux[ni, nj]:
            aux[ni, nj] = nw
            dirx[ni, nj] = dirx[i, j]
            diry[ni, nj] = diry[i, j]
    return aux, dist


@dataclass(frozen=True)
class PMFSParams:
    """PMFS parameters in metres (launch values at 0.25 m cells, converted; see the module docstring).

    ``hit_threshold`` (ppm) or, when set, ``hit_threshold_fraction`` (of the
    largest reading) decides hits; ``leaf_cells`` is the first quadtree level's
    block side in cells; the rest are named as in the original.
    """

    hit_threshold: float = 0.1
    hit_threshold_fraction: float | None = None
    hit_prior: float = 0.3
    value_hit: float = 0.6
    value_miss: float = 0.1
    kernel_sigma_m: float = 0.375
    kernel_stretch_m: float = 0.375
    window_m: float = 0.5
    confidence_sigma_m: float = 0.25
    confidence_weight: float = 1.0
    launch_cell_m: float = 0.25
    dt: float = 0.1
    noise: float = 0.5
    beta: float = 0.2
    filaments_per_iteration: int = 5
    n_record: int = 200
    min_warmup: int = 0
    max_warmup: int = 500
    leaf_cells: int = 12
    refine_fraction: float = 0.1

    def __post_init__(self) -> None:
        for k in (
            "kernel_sigma_m",
            "window_m",
            "confidence_sigma_m",
            "confidence_weight",
            "dt",
            "launch_cell_m",
        ):
            if not float(getattr(self, k)) > 0:
                raise InputDataError(f"PMFS parameter {k} must be > 0")
        if not (0 < self.hit_prior < 1 and 0 <= self.beta <= 1 and 0 < self.refine_fraction <= 1):
            raise InputDataError("need 0 < hit_prior < 1, 0 <= beta <= 1, 0 < refine_fraction <= 1")
        if int(self.leaf_cells) < 1:
            raise InputDataError(f"leaf_cells must be >= 1, got {self.leaf_cells}")


def hit_threshold(gas: np.ndarray, params: PMFSParams) -> float:
    """The hit threshold, ppm: ``hit_threshold``, or ``hit_threshold_fraction * max(gas)`` if set."""
    if params.hit_threshold_fraction is None:
        return float(params.hit_threshold)
    return float(params.hit_threshold_fraction) * float(np.max(gas, initial=0.0))


def hypothesis_log_likelihood(
    phit: np.ndarray, confidence: np.ndarray, hit_map_s: np.ndarray, beta: float, free: np.ndarray
) -> float:
    """``log L(s) = sum_c log(lerp(1, 1 - beta |p_hit(c) - hitMap_s(c)|, conf_c))`` over free cells."""
    d = np.abs(phit - hit_map_s)[free]
    return float(np.log1p(-confidence[free] * beta * d).sum())


def hit_map(
    occupancy: np.ndarray, resolution: float, observations: Observations, params: PMFSParams | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(p_hit (H, W), confidence (H, W))`` after all readings, in order (module docstring, step 1)."""
    p = params or PMFSParams()
    occ = np.asarray(occupancy)
    free = np.ascontiguousarray(occ == 0)
    res = float(resolution)
    threshold = hit_threshold(observations.gas, p)
    lo_prior = math.log(p.hit_prior / (1.0 - p.hit_prior))
    logodds = np.full(occ.shape, lo_prior)
    omega = np.zeros(occ.shape)
    window = max(1, round(p.window_m / res))
    s = p.kernel_sigma_m
    peak = 1.0 / ((p.confidence_sigma_m / p.launch_cell_m) * math.sqrt(2.0 * math.pi))
    for (i, j), z, w in zip(observations.cells, observations.gas, observations.wind, strict=True):
        speed = float(math.hypot(w[0], w[1]))
        ux, uy = (float(w[0]) / speed, float(w[1]) / speed) if speed > 0 else (1.0, 0.0)
        s_major = s + p.kernel_stretch_m * speed
        s_minor = s / (1.0 + p.kernel_stretch_m * speed / s)
        value = p.value_hit if z > threshold else p.value_miss
        aux, dist = _hit_update(
            free, int(i), int(j), res, window, ux, uy, s_major, s_minor, p.hit_prior, value
        )
        touched = np.isfinite(aux)
        logodds[touched] += aux[touched] - lo_prior
        dd = np.where(np.isfinite(dist), dist, np.inf)
        omega += peak * np.exp(-0.5 * (dd / p.confidence_sigma_m) ** 2)
    conf = 1.0 - np.exp(-omega / p.confidence_weight**2)
    phit = 1.0 / (1.0 + np.exp(-logodds))
    phit[~free] = 0.0
    conf[~free] = 0.0
    return phit, conf


# -- filament simulation ------------------------------------------------------------------------
@nb.njit(cache=True)
def _move(px, py, ex, ey, free, open_mask, edges_open, res):  # pragma: no cover - numba
    """PMFS's moveAlongPath: half-cell steps towards ``(ex, ey)``, stopping before a wall; the new point."""
    H, W = free.shape
    vx = ex - px
    vy = ey - py
    dist = math.sqrt(vx * vx + vy * vy)
    if dist <= 0.0:
        return px, py
    step = min(dist, 0.5 * res)
    n = int(dist / step)
    sx = vx / dist * step
    sy = vy / dist * step
    x = px
    y = py
    for _ in range(n):
        nx = x + sx
        ny = y + sy
        j = math.floor(nx / res)
        i = math.floor(ny / res)
        if i < 0 or i >= H or j < 0 or j >= W:
            ci = min(max(math.floor(y / res), 0), H - 1)
            cj = min(max(math.floor(x / res), 0), W - 1)
            if edges_open or open_mask[ci, cj]:
                return nx, ny  # leaves the map
            return x, y
        if not free[i, j]:
            return x, y
        x = nx
        y = ny
    je = math.floor(ex / res)
    ie = math.floor(ey / res)
    if 0 <= ie < H and 0 <= je < W and free[ie, je]:
        return ex, ey
    return x, y


@nb.njit(cache=True)
def _rand(state):  # pragma: no cover - numba
    """Uniform in [0, 1) from a xorshift64* generator (``state``: uint64 array of one)."""
    x = state[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    state[0] = x
    return float((x * np.uint64(2685821657736338717)) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True)
def _randn(state):  # pragma: no cover - numba
    """Standard normal (Box-Muller, one of the pair)."""
    u = _rand(state)
    v = _rand(state)
    return math.sqrt(-2.0 * math.log(1.0 - u)) * math.cos(2.0 * math.pi * v)


@nb.njit(cache=True)
def _release(rel, res, state):  # pragma: no cover - numba
    k = min(int(_rand(state) * rel.shape[0]), rel.shape[0] - 1)
    return (rel[k, 1] + _rand(state)) * res, (rel[k, 0] + _rand(state)) * res


@nb.njit(cache=True)
def _release_many(fx, fy, act, last, n_per, rel, res, state):  # pragma: no cover - numba
    """Release ``n_per`` filaments into the slots from ``last`` on; returns the slots in use."""
    for _ in range(n_per):
        fx[last], fy[last] = _release(rel, res, state)
        act[last] = True
        last += 1
    return last


@nb.njit(cache=True)
def _advect(
    f, fx, fy, wx, wy, step, noise, free, open_mask, edges_open, res, state
):  # pragma: no cover - numba
    """Move filament ``f`` for ``step`` s by its cell's wind plus noise; False once it left the map."""
    j = math.floor(fx[f] / res)
    i = math.floor(fy[f] / res)
    vx = wx[i, j] + noise * _randn(state)
    vy = wy[i, j] + noise * _randn(state)
    fx[f], fy[f] = _move(fx[f], fy[f], fx[f] + step * vx, fy[f] + step * vy, free, open_mask, edges_open, res)
    j = math.floor(fx[f] / res)
    i = math.floor(fy[f] / res)
    return 0 <= i < free.shape[0] and 0 <= j < free.shape[1]


@nb.njit(cache=True)
def _simulate_one(world, rel, sim, seed):  # pragma: no cover - numba
    """Hit frequencies ``(H, W)`` of one source hypothesis (release cells ``rel`` (k, 2)) in
    ``world`` (:func:`_prepare`) with the settings ``sim`` (:func:`_settings`)."""
    free, open_mask, edges_open, wx, wy = world
    res, dt, noise, n_per, min_warm, max_warm, n_rec = sim
    state = np.empty(1, dtype=np.uint64)
    state[0] = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(0x632BE59BD9B4E019)
    if state[0] == 0:
        state[0] = np.uint64(1)
    H, W = free.shape
    cap = (max_warm + n_rec) * n_per
    fx = np.zeros(cap)
    fy = np.zeros(cap)
    act = np.zeros(cap, dtype=np.bool_)
    last = 0
    stable = False
    it = 0
    while it < min_warm or ((not stable) and it < max_warm):
        last = _release_many(fx, fy, act, last, n_per, rel, res, state)
        for f in range(last):
            if act[f] and not _advect(
                f, fx, fy, wx, wy, 2.0 * dt, noise, free, open_mask, edges_open, res, state
            ):
                act[f] = False
                stable = True
                break
        it += 1
    hits = np.zeros((H, W))
    updated = np.zeros((H, W), dtype=np.int64)
    for t in range(1, n_rec + 1):
        last = _release_many(fx, fy, act, last, n_per, rel, res, state)
        for f in range(last):
            if not act[f]:
                continue
            j = math.floor(fx[f] / res)
            i = math.floor(fy[f] / res)
            if updated[i, j] < t:
                hits[i, j] += 1.0
                updated[i, j] = t
            if not _advect(f, fx, fy, wx, wy, dt, noise, free, open_mask, edges_open, res, state):
                act[f] = False
    return hits / n_rec


@nb.njit(cache=True, parallel=True)
def _simulate_many(
    world, rel, starts, counts, sim, seeds, fidx, ph, cf, beta, keep_maps
):  # pragma: no cover - numba
    """``log L`` of many hypotheses (release cells ``rel[starts[k]:starts[k] + counts[k]]``), in parallel.

    Returns ``(scores (n,), hit maps on the free cells (n, n_free) or (0, n_free))``.
    """
    n = starts.size
    scores = np.zeros(n)
    maps = np.zeros((n if keep_maps else 0, fidx.size), dtype=np.float32)
    W = world[0].shape[1]
    for k in nb.prange(n):
        hm = _simulate_one(world, rel[starts[k] : starts[k] + counts[k]], sim, seeds[k])
        s = 0.0
        for m in range(fidx.size):
            h = hm[fidx[m] // W, fidx[m] % W]
            s += math.log1p(-cf[m] * beta * abs(ph[m] - h))
            if keep_maps:
                maps[k, m] = h
        scores[k] = s
    return scores, maps


def _prepare(occupancy: np.ndarray, wind: np.ndarray, open_mask: np.ndarray | None) -> tuple[Any, ...]:
    """The world of the filament kernels: free cells, open boundary cells, whether every edge is
    open (no ``open_mask``), and the wind's x and y components, as contiguous arrays."""
    free = np.ascontiguousarray(np.asarray(occupancy) == 0)
    om = np.zeros(free.shape, dtype=np.bool_) if open_mask is None else np.ascontiguousarray(open_mask, bool)
    w = np.asarray(wind, dtype=np.float64)
    return free, om, open_mask is None, np.ascontiguousarray(w[0]), np.ascontiguousarray(w[1])


def _settings(p: PMFSParams, resolution: float) -> tuple[float, float, float, int, int, int, int]:
    """The simulation settings of the filament kernels: cell size, time step, wind noise,
    filaments per iteration, least and most warm-up iterations, recorded iterations."""
    return (
        float(resolution),
        p.dt,
        p.noise,
        int(p.filaments_per_iteration),
        int(p.min_warmup),
        int(p.max_warmup),
        int(p.n_record),
    )


def simulate_hits(
    occupancy: np.ndarray,
    resolution: float,
    wind: np.ndarray,
    release_cells: np.ndarray,
    params: PMFSParams | None = None,
    open_mask: np.ndarray | None = None,
    seed: int = 0,
) -> np.ndarray:
    """``hitMap_s (H, W)``: fraction of recorded iterations with a filament in each cell (module doc, step 4).

    Args:
        occupancy: ``(H, W)`` map.
        resolution: cell size, m.
        wind: ``(2, H, W)`` wind map, m/s.
        release_cells: ``(k, 2)`` free cells of the hypothesis (release uniform over them).
        params: PMFS parameters.
        open_mask: ``bool (H, W)`` boundary cells open to the outside (openings); None: every edge is open.
        seed: random seed.
    """
    p = params or PMFSParams()
    world = _prepare(occupancy, wind, open_mask)
    free = world[0]
    rel = np.ascontiguousarray(np.asarray(release_cells, dtype=np.int64).reshape(-1, 2))
    if len(rel) == 0 or not free[rel[:, 0], rel[:, 1]].all():
        raise InputDataError("release cells must be free cells (at least one)")
    return _simulate_one(world, rel, _settings(p, resolution), int(seed))


# -- quadtree ---------------------------------------------------------------------------------------
#: A quadtree leaf: ``(row, col, height, width)`` in cells.
Leaf = tuple[int, int, int, int]


def _split(leaf: Leaf, free: np.ndarray) -> list[Leaf]:
    """The children of a leaf (halves along each side longer than one cell) that hold free cells."""
    i, j, h, w = leaf
    rows = [(i, h // 2), (i + h // 2, h - h // 2)] if h > 1 else [(i, h)]
    cols = [(j, w // 2), (j + w // 2, w - w // 2)] if w > 1 else [(j, w)]
    if len(rows) == 1 and len(cols) == 1:
        return []
    return [(a, b, ha, wb) for a, ha in rows for b, wb in cols if free[a : a + ha, b : b + wb].any()]


def _initial_leaves(free: np.ndarray, size: int) -> list[Leaf]:
    """Blocks of ``size`` whose free cells are one 4-connected component (blocks cut by walls split)."""
    H, W = free.shape
    stack: list[Leaf] = [
        (i, j, min(size, H - i), min(size, W - j))
        for i in range(0, H, size)
        for j in range(0, W, size)
        if free[i : i + size, j : j + size].any()
    ]
    leaves = []
    while stack:
        leaf = stack.pop()
        i, j, h, w = leaf
        blk = free[i : i + h, j : j + w]
        if (h > 1 or w > 1) and not blk.all():
            _, n = ndimage.label(blk)
            if n > 1:
                stack.extend(_split(leaf, free))
                continue
        leaves.append(leaf)
    leaves.sort()
    return leaves


def _release_cells(free: np.ndarray, leaf: Leaf) -> np.ndarray:
    i, j, h, w = leaf
    c = np.argwhere(free[i : i + h, j : j + w])
    return (c + np.array([i, j])).astype(np.int64)


# -- the estimator ------------------------------------------------------------------------------
@dataclass(eq=False)
class PMFSMaps:
    """PMFS's maps for its planner (``Belief.info["planner_data"]``).

    Attributes:
        hit_prob: ``(H, W)`` hit probability ``p_hit``.
        confidence: ``(H, W)`` confidence of the hit map.
        hit_variance: ``(H, W)`` ``Var_s[hitMap_s(c)]`` over the first-level hypotheses.
    """

    hit_prob: np.ndarray
    confidence: np.ndarray
    hit_variance: np.ndarray

    def __repr__(self) -> str:
        return f"<PMFSMaps {self.hit_prob.shape[0]}x{self.hit_prob.shape[1]}>"


def _open_mask(layout: Layout) -> np.ndarray:
    return layout.opening_mask("inlet") | layout.opening_mask("outlet")


@dataclass(eq=False)
class PMFSEstimator(KnowledgeUser):
    """PMFS's source posterior (module docstring).

    Works at every knowledge level: with the openings known (``openings``, or
    ``wind`` with openings) filaments leave through them only; at ``map``
    every map edge is open.

    Args:
        params: :class:`PMFSParams` (launch values converted to metres).
        layout: the layout whose openings let filaments out (None: every map edge is
            open); set from the knowledge by :meth:`set_knowledge`.
        seed: base seed of the simulations (hypothesis ``k`` uses ``seed + k``).
    """

    params: PMFSParams = field(default_factory=PMFSParams)
    layout: Layout | None = None
    seed: int | None = 0
    name: str = field(default="pmfs", init=False)

    def __post_init__(self) -> None:
        if isinstance(self.params, dict):
            self.params = PMFSParams(**self.params)

    def _use_knowledge(self, knowledge: Knowledge) -> None:
        self.layout = knowledge.layout if knowledge.has_openings else None

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The PMFS posterior over free cells.

        Raises:
            InputDataError: no readings, or a reading outside the map or in a wall.
        """
        t0 = time.perf_counter()
        occ, res, obs = check_inputs(occupancy, resolution, observations)
        p = self.params
        free = occ == 0
        open_mask = None
        if self.layout is not None:
            if self.layout.occupancy.shape != occ.shape or not np.array_equal(
                self.layout.occupancy != 0, occ != 0
            ):
                raise InputDataError("pmfs: the layout given differs from the map passed to estimate()")
            open_mask = _open_mask(self.layout)
        phit, conf = hit_map(occ, res, obs, p)
        wind = wind_map(occ, obs.cells, obs.wind)
        t_pre = time.perf_counter() - t0
        base_seed = 0 if self.seed is None else int(self.seed)
        fidx = np.flatnonzero(free.reshape(-1))
        ph = phit.reshape(-1)[fidx]
        cf = conf.reshape(-1)[fidx]
        n_sims = 0
        world = _prepare(occ, wind, open_mask)
        sim = _settings(p, res)

        def run(leaves: list[Leaf], keep_maps: bool) -> tuple[np.ndarray, np.ndarray]:
            nonlocal n_sims
            rels = [_release_cells(free, leaf) for leaf in leaves]
            counts = np.array([len(r) for r in rels], dtype=np.int64)
            starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
            seeds = base_seed + n_sims + np.arange(len(leaves), dtype=np.int64)
            n_sims += len(leaves)
            rel = np.ascontiguousarray(np.concatenate(rels))
            return _simulate_many(world, rel, starts, counts, sim, seeds, fidx, ph, cf, p.beta, keep_maps)

        leaves = _initial_leaves(free, int(p.leaf_cells))
        logl = np.full(occ.shape, -np.inf)
        scores, maps = run(leaves, True)
        # variance of the hit maps over the first level, weighted by their posterior
        wl = np.exp(scores - scores.max())
        wl /= wl.sum()
        mean_h = wl @ maps
        var_h = np.zeros(occ.shape)
        var_h.reshape(-1)[fidx] = np.maximum(wl @ (maps.astype(np.float64) ** 2) - mean_h**2, 0.0)
        del maps
        level = 0
        while True:
            for (i, j, h, w), sc in zip(leaves, scores, strict=True):
                blk = logl[i : i + h, j : j + w]
                blk[free[i : i + h, j : j + w]] = sc
            order = np.argsort(scores)[::-1]
            n_ref = math.ceil(p.refine_fraction * len(leaves))
            children = [c for k in order[:n_ref] for c in _split(leaves[k], free)]
            if not children:
                break
            leaves = children
            scores, _ = run(leaves, False)
            level += 1
        probs = probs_from_log(logl, free)
        # the original's estimate: weighted mean of the top 5 % cells
        pf = probs.reshape(-1)[fidx]
        top = np.argsort(pf)[::-1][: max(1, math.ceil(0.05 * fidx.size))]
        W = occ.shape[1]
        tw = pf[top] / max(pf[top].sum(), 1e-300)
        est_xy = [float(tw @ ((fidx[top] % W) + 0.5)) * res, float(tw @ ((fidx[top] // W) + 0.5)) * res]
        info: dict[str, Any] = {
            "method": self.name,
            "n_observations": len(obs),
            "n_hits": int((obs.gas > hit_threshold(obs.gas, p)).sum()),
            "hit_threshold_ppm": hit_threshold(obs.gas, p),
            "n_simulations": n_sims,
            "n_levels": level + 1,
            "estimate_top5_xy": est_xy,
            "edges": "open everywhere" if open_mask is None else "openings of the layout",
            "planner_data": PMFSMaps(phit, conf, var_h),
            "timings": {"preprocessing": t_pre},
        }
        info["seconds"] = time.perf_counter() - t0
        return Belief(occ, res, probs, wind_mean=wind, info=info)


@options_from(PMFSEstimator)
def make_pmfs(**kwargs: Any) -> PMFSEstimator:
    """Registry factory ``pmfs``; ``params`` may be a dict of :class:`PMFSParams` fields."""
    return PMFSEstimator(**kwargs)


# -- the planner ----------------------------------------------------------------------------------
@dataclass
class PMFSPlanner(PlannerBase):
    """PMFS's movement strategy (module docstring).

    Args:
        move_radius_m: cells within this distance (line of sight) of visited positions join the move set, m.
        exploration_moves: moves that use the exploration value.
        exploration_probability: chance of an exploration move afterwards.
        distance_scale_m: ``exp(-d / scale)`` in the exploration value (one 0.25 m cell), m.
        stop_variance_m2: stop when ``var x + var y`` of the posterior is below this.
    """

    move_radius_m: float = 1.25
    exploration_moves: int = 5
    exploration_probability: float = 0.05
    distance_scale_m: float = 0.25
    stop_variance_m2: float = 1.5
    name: str = field(default="pmfs", init=False)
    _open: np.ndarray | None = field(default=None, init=False, repr=False)
    _moves: int = field(default=0, init=False, repr=False)

    def reset(self) -> None:
        """Forget the move set and the move count."""
        self._open = None
        self._moves = 0

    def should_stop(self, belief: Belief, history: SearchHistory | None = None) -> bool:
        """``var x + var y < stop_variance_m2``."""
        return belief.source_variance() < self.stop_variance_m2

    def _visible_disc(self, free: np.ndarray, cell: Cell, res: float) -> np.ndarray:
        H, W = free.shape
        r = max(1, round(self.move_radius_m / res))
        out = np.zeros((H, W), dtype=bool)
        ci, cj = int(cell[0]), int(cell[1])
        fr = np.ascontiguousarray(free)
        for i in range(max(0, ci - r), min(H, ci + r + 1)):
            for j in range(max(0, cj - r), min(W, cj + r + 1)):
                if free[i, j] and (i - ci) ** 2 + (j - cj) ** 2 <= r * r and _visible(fr, ci, cj, i, j):
                    out[i, j] = True
        return out

    def exploration_value(self, belief: Belief, conf: np.ndarray) -> np.ndarray:
        """Per cell ``x``: ``sum (1 - conf_c) exp(-|c - x| / scale)``, free ``c`` within ``move_radius_m``."""
        res = belief.resolution
        r = max(1, round(self.move_radius_m / res))
        yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
        d = np.hypot(yy, xx) * res
        k = np.where(d <= self.move_radius_m, np.exp(-d / self.distance_scale_m), 0.0)
        u = np.where(belief.free, 1.0 - conf, 0.0)
        return ndimage.convolve(u, k, mode="constant")

    def next_goal(
        self, belief: Belief, robot_cell: Cell, distances: np.ndarray, history: SearchHistory | None = None
    ) -> Cell | None:
        """The best cell of the open move set (module docstring), or None if it is empty."""
        maps = belief.info.get("planner_data")
        if not isinstance(maps, PMFSMaps):
            raise InputDataError(
                "the pmfs planner needs a belief of the pmfs estimator (info['planner_data'])"
            )
        free = belief.free
        if self._open is None or self._open.shape != free.shape:
            self._open = np.zeros(free.shape, dtype=bool)
        self._open |= self._visible_disc(free, robot_cell, belief.resolution)
        cand = self._open & np.isfinite(np.asarray(distances)) & free
        cand[int(robot_cell[0]), int(robot_cell[1])] = False
        cells = np.argwhere(cand)
        if len(cells) == 0:
            return None
        rng = history.rng if history is not None else np.random.default_rng(0)
        explore = self._moves < self.exploration_moves or rng.random() < self.exploration_probability
        if explore:
            score = self.exploration_value(belief, maps.confidence)[cells[:, 0], cells[:, 1]]
        else:
            score = (maps.hit_variance * (1.0 - maps.confidence))[cells[:, 0], cells[:, 1]]
        self._moves += 1
        from dgse.localization.infotaxis import best_cell

        return best_cell(cells, score, np.asarray(distances))
