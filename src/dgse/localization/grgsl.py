r"""GrGSL (Ojeda et al. 2021): a grid posterior updated from local gas-hit and wind cues.

Following MAPIRlab's public implementation (``GrGSLLib::estimateProbabilitiesfromGasAndWind``):

* the posterior is categorical over the free cells reachable from where the
  search starts (cells not connected to it get probability 0);
* readings are processed one at a time in the given order (sorted by
  ``Observations.times`` when present).  Reading ``k`` at the robot cell
  ``R`` is a *hit* when ``z > hit_threshold`` (0.5 ppm) and its wind is
  *significant* when ``|w| > wind_threshold`` (0.1 m/s);
* a hit with significant wind weights each free cell ``C`` of a local window
  around ``R`` by a Gaussian (``sigma_hit = 1.0 rad``) in the angle between
  ``R - C`` and the wind direction: cells upwind of the robot get the most;
* any miss weights them by a Gaussian (``sigma_miss = 1.5 rad``) in the angle
  between ``R - C`` and ``R - P``, ``P`` the position of the last hit: cells
  in the direction of the last hit get the most (the code's
  ``atan2(P - R) + pi`` compared with the cell-to-robot angle; the robot's
  own cell gets the weight of the opposite direction, the lowest);
* a hit without significant wind changes nothing (unless ``use_diffusion``);
* the window's weights are flood-filled to the whole map along shortest
  obstacle-free paths (8-neighbour moves): every cell takes the weight of
  the window cell its shortest path from the robot leaves through (ties:
  the larger weight), so cells behind a wall inherit from the door side;
* the weights are normalized, optionally (``use_diffusion``, the code's
  ``useDiffusionTerm``, off by default) a normalized ``max(0.1,
  N(d; 0, sigma_d))`` in the path distance is added on hits, and the
  posterior is multiplied by them and normalized (in logs here).

**Start.**  GrGSL needs a first hit: the public implementation waits at its
start for gas (``WaitForGasState``) and the last-hit position starts there.
``start="first_hit"`` (default) ignores the readings before the first hit
and starts there; ``start="first_reading"`` is the stricter reading of the
paper's Table II note: the first reading (the robot's start) must be a hit,
else the method never starts.  Without a start the belief is the uniform
posterior over the free cells and ``info["started"] = False`` with the
reason in ``info["note"]``.

Grid: the original works on a coarse grid (a multiple of the map cell); here
the 0.1 m grid is used, the local window is ``window_m`` (1.0 m, i.e. the
original's +-2 cells of 0.5 m) and the window cells' initial path distances
are their Euclidean distances (the code gives every window cell 1 or
``sqrt(2)`` coarse cells).  GrGSL's own planner is not provided; use it with
``infotaxis`` (the original's planner is Infotaxis-like).
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numba as nb
import numpy as np

from dgse.belief.belief import Belief, probs_from_log, uniform_probs
from dgse.belief.inputs import check_inputs
from dgse.belief.knowledge import KnowledgeUser
from dgse.errors import InputDataError
from dgse.localization.grid_dijkstra import expansions
from dgse.sensing.sensors import Observations

__all__ = ["GrGSLEstimator", "grgsl_weights", "make_grgsl"]

_SQRT2 = math.sqrt(2.0)


@nb.njit(cache=True)
def _flood(free, ri, rj, w_robot, seed_i, seed_j, seed_d, seed_w):  # pragma: no cover - numba
    """Multi-source Dijkstra from the window cells; each cell inherits its path's window weight."""
    H, W = free.shape
    dist = np.full((H, W), np.inf)
    wgt = np.zeros((H, W))
    done = np.zeros((H, W), dtype=np.bool_)
    dist[ri, rj] = 0.0
    wgt[ri, rj] = w_robot
    done[ri, rj] = True  # the robot's cell is closed: it does not propagate
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for k in range(seed_i.size):
        i, j = seed_i[k], seed_j[k]
        dist[i, j] = seed_d[k]
        wgt[i, j] = seed_w[k]
        heapq.heappush(heap, (seed_d[k], np.int64(i * W + j)))
    for i, j, ni, nj, nd in expansions(heap, done, free, 1.0):
        if nd < dist[ni, nj] - 1e-9:
            dist[ni, nj] = nd
            wgt[ni, nj] = wgt[i, j]
            heapq.heappush(heap, (nd, np.int64(ni * W + nj)))
        elif abs(nd - dist[ni, nj]) <= 1e-9 and wgt[i, j] > wgt[ni, nj]:
            wgt[ni, nj] = wgt[i, j]
    return wgt, dist


def _gauss(x: np.ndarray | float, sigma: float) -> np.ndarray:
    return np.exp(-0.5 * (np.asarray(x, dtype=np.float64) / sigma) ** 2) / (sigma * math.sqrt(2.0 * math.pi))


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(a), np.cos(a))


def grgsl_weights(
    free: np.ndarray,
    robot: tuple[int, int],
    ideal_angle: float,
    sigma: float,
    hit: bool,
    window: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``(weights (H, W), path distance in cells (H, W))`` of one GrGSL update before normalization.

    Args:
        free: ``bool (H, W)`` free cells.
        robot: the robot cell ``(i, j)``.
        ideal_angle: the direction (rad, ``atan2(dy, dx)``) that ``R - C`` should point
            along for a cell ``C`` to get the largest weight.
        sigma: the angular standard deviation, rad.
        hit: a hit (the robot's own cell gets ``N(0)``) or a miss (``N(pi)``).
        window: half-size of the local window, cells.
    """
    H, W = free.shape
    ri, rj = robot
    i0, i1 = max(0, ri - window), min(H - 1, ri + window)
    j0, j1 = max(0, rj - window), min(W - 1, rj + window)
    ii, jj = np.mgrid[i0 : i1 + 1, j0 : j1 + 1]
    ii, jj = ii.ravel(), jj.ravel()
    keep = free[ii, jj] & ~((ii == ri) & (jj == rj))
    ii, jj = ii[keep], jj[keep]
    ang = np.arctan2(ri - ii, rj - jj)  # direction of R - C
    w = _gauss(_wrap(ideal_angle - ang), sigma)
    d0 = np.hypot(ii - ri, jj - rj)
    w_robot = float(_gauss(0.0 if hit else math.pi, sigma))
    wgt, dist = _flood(
        np.ascontiguousarray(free), ri, rj, w_robot, ii.astype(np.int64), jj.astype(np.int64), d0, w
    )
    return wgt, dist


@dataclass(eq=False)
class GrGSLEstimator(KnowledgeUser):
    """GrGSL's sequential grid posterior (see the module docstring).

    Args:
        hit_threshold: a reading above this is a hit, ppm.
        wind_threshold: wind above this is significant, m/s.
        sigma_hit: angular spread of a hit update, rad.
        sigma_miss: angular spread of a miss update, rad.
        window_m: half-size of the local window, m.
        use_diffusion: add the distance-based diffusion term on hits.
        diffusion_sigma_m: its spread, m.
        start: ``"first_hit"`` or ``"first_reading"`` (module docstring).
    """

    hit_threshold: float = 0.5
    wind_threshold: float = 0.1
    sigma_hit: float = 1.0
    sigma_miss: float = 1.5
    window_m: float = 1.0
    use_diffusion: bool = False
    diffusion_sigma_m: float = 1.5
    start: Literal["first_hit", "first_reading"] = "first_hit"
    name: str = field(default="grgsl", init=False)

    def __post_init__(self) -> None:
        for k in ("sigma_hit", "sigma_miss", "window_m", "diffusion_sigma_m"):
            if not float(getattr(self, k)) > 0:
                raise InputDataError(f"{k} must be > 0")
        if not (self.hit_threshold >= 0 and self.wind_threshold >= 0):
            raise InputDataError("thresholds must be >= 0")
        if self.start not in ("first_hit", "first_reading"):
            raise InputDataError(f"start must be 'first_hit' or 'first_reading', got {self.start!r}")

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The GrGSL posterior after all readings (uniform, ``info["started"] = False``, before a hit).

        Raises:
            InputDataError: no readings, or a reading outside the map or in a wall.
        """
        t0 = time.perf_counter()
        occ, res, obs = check_inputs(occupancy, resolution, observations)
        order = np.arange(len(obs)) if obs.times is None else np.argsort(obs.times, kind="stable")
        cells, gas, wind = obs.cells[order], obs.gas[order], obs.wind[order]
        hits = gas > self.hit_threshold
        info: dict[str, Any] = {"method": self.name, "n_observations": len(obs), "n_hits": int(hits.sum())}
        if self.start == "first_reading":
            k0 = 0 if hits[0] else None
        else:
            k0 = int(np.argmax(hits)) if hits.any() else None
        if k0 is None:
            why = "the first reading (the start)" if self.start == "first_reading" else "any reading"
            info.update(
                started=False,
                note=f"GrGSL needs a first gas hit (> {self.hit_threshold} ppm) and {why} had none; "
                "the posterior is uniform",
            )
            info["seconds"] = time.perf_counter() - t0
            return Belief(occ, res, uniform_probs(occ), info=info)
        free = occ == 0
        window = max(1, round(self.window_m / res))
        last_hit = (int(cells[k0, 0]), int(cells[k0, 1]))
        # cells reachable from the start
        _, reach = grgsl_weights(free, last_hit, 0.0, 1.0, True, 1)
        logp = np.where(np.isfinite(reach) & free, 0.0, -np.inf)
        n_updates = 0
        for k in range(k0, len(cells)):
            R = (int(cells[k, 0]), int(cells[k, 1]))
            hit = bool(hits[k])
            speed = float(math.hypot(wind[k, 0], wind[k, 1]))
            significant = speed > self.wind_threshold
            if hit:
                last_hit = R
            advection = significant if hit else True
            diffusion = self.use_diffusion and hit
            if not advection and not diffusion:
                continue
            if hit:
                ideal = math.atan2(wind[k, 1], wind[k, 0])
                sigma = self.sigma_hit
            else:
                if R == last_hit:
                    continue  # no direction from the last hit
                ideal = math.atan2(R[0] - last_hit[0], R[1] - last_hit[1])
                sigma = self.sigma_miss
            wgt, dist = grgsl_weights(free, R, ideal, sigma, hit, window)
            aux = np.zeros_like(wgt)
            if advection:
                s = wgt[free].sum()
                if s > 0:
                    aux = wgt / s
            if diffusion:
                dm = np.where(np.isfinite(dist), dist * res, np.inf)
                dp = np.where(np.isfinite(dm), np.maximum(0.1, _gauss(dm, self.diffusion_sigma_m)), 0.0)
                dp[~free] = 0.0
                if dp.sum() > 0:
                    aux = aux + dp / dp.sum()
            with np.errstate(divide="ignore"):
                logp = logp + np.log(aux)
            top = logp[free].max()
            if not np.isfinite(top):
                raise InputDataError("GrGSL posterior collapsed (no reachable cell left)")
            logp = logp - top
            n_updates += 1
        probs = probs_from_log(logp, free)
        info.update(
            started=True, start_index=int(order[k0]), n_updates=n_updates, last_hit_cell=list(last_hit)
        )
        info["seconds"] = time.perf_counter() - t0
        return Belief(occ, res, probs, info=info)


def make_grgsl(**kwargs: Any) -> GrGSLEstimator:
    """Registry factory ``grgsl``."""
    return GrGSLEstimator(**kwargs)
