"""Source localization baselines: posteriors over the source cell and their planners.

Estimators (each ``estimate(occupancy, resolution, observations) -> Belief``,
registry names in brackets, :data:`dgse.estimators.registry.ESTIMATORS`):

=========================  ===================================  ==========================================
method                     module                               posterior from
=========================  ===================================  ==========================================
Adjoint Bayesian           :mod:`.adjoint` (``adjoint``,        the discrete adjoint of the transport
                           ``adjoint-oracle``)                  operator, release rate and noise marginalized
Dual-mode (Kim 2025)       :mod:`.particle_filter`              particle filter, obstacle-aware Gaussian
                           (``dualmode``)                       plume model
PMFS (Ojeda 2024)          :mod:`.pmfs` (``pmfs``)              hit map + filament simulation per hypothesis
GrGSL (Ojeda 2021)         :mod:`.grgsl` (``grgsl``)            sequential upwind/last-hit direction cues
=========================  ===================================  ==========================================

Planners (``dgse.planning.planners`` protocol, same registry names unless said):
``infotaxis`` and ``entrotaxis`` (:mod:`.infotaxis`, on any categorical posterior),
``dualmode`` (:mod:`.particle_filter`), ``pmfs`` (:mod:`.pmfs`).

Conventions shared by every method here:

* Grid of the physics spec: cell ``(i, j)`` has its centre at ``x = (j + 0.5) res``,
  ``y = (i + 0.5) res``; wind ``[u_x, u_y]`` in m/s; gas readings in ppm.
* Inputs are checked by :func:`check_inputs`: no readings, a reading outside
  the map or in a wall, or non-finite readings raise
  :class:`~dgse.errors.InputDataError` (GrGSL alone accepts no hit and says so).
  Negative gas readings are clipped to 0.  Readings are used in the order
  given (the sequential methods: GrGSL, the particle filter, the PMFS hit map).
* The source posterior is over the free cells of the map (uniform prior).
* ``Belief.info`` holds ``method``, ``seconds`` and the method's diagnostics;
  planner-side data (arrays, models) sit under ``info["planner_data"]`` and
  ``info["response_model"]`` in objects with a short ``repr`` (JSON writers
  store only that ``repr``).

This module holds the small helpers the methods share (input checks, free-cell
Dijkstra from sensors, smoothing of a particle histogram).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse.csgraph import dijkstra

from dgse.errors import InputDataError
from dgse.planning.paths import FreeSpaceGraph, graph_for

__all__ = ["blur_probs", "free_graph", "graph_distances"]


def graph_distances(graph: FreeSpaceGraph, cells: np.ndarray) -> np.ndarray:
    """``float64 (k, H * W)`` shortest obstacle-free path lengths (m) from each cell of ``cells``.

    One multi-source call of :func:`scipy.sparse.csgraph.dijkstra` on the map's
    8-connected move graph (no corner cutting); ``inf`` on walls and unconnected cells.
    """
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    H, W = graph.shape
    out = np.full((len(c), H * W), np.inf)
    if len(c) == 0:
        return out
    nodes = graph.node_of[c[:, 0] * W + c[:, 1]]
    if (nodes < 0).any():
        raise InputDataError("a distance source cell lies in a wall")
    d = dijkstra(graph.matrix, directed=True, indices=nodes)
    out[:, graph.flat_of] = np.atleast_2d(d)
    return out


def blur_probs(weights: np.ndarray, occupancy: np.ndarray, sigma_cells: float, floor: float) -> np.ndarray:
    """A smoothed categorical map from cell weights (e.g. a particle histogram).

    ``(1 - floor) * K(weights) + floor * uniform`` over the free cells.  ``K``
    is a mass-conserving diffusion on the free cells (a lazy random walk to
    the 4 free neighbours, ``ceil(4 sigma^2)`` steps of probability 1/2, i.e.
    a Gaussian of about ``sigma_cells`` that does not cross walls).
    ``floor > 0`` keeps every free cell's probability positive (a finite
    cross-entropy at any true source).
    """
    occ = np.asarray(occupancy)
    free = occ == 0
    p = np.where(free, np.asarray(weights, dtype=np.float64), 0.0)
    p = np.maximum(p, 0.0)
    total = p.sum()
    u = free / free.sum()
    if not total > 0:
        return u
    p /= total
    steps = math.ceil(4.0 * sigma_cells**2) if sigma_cells > 0 else 0
    # a link per direction where both cells are free (moves into walls or off the map stay put)
    lo, hi, every = slice(0, -1), slice(1, None), slice(None)
    links: list[tuple[np.ndarray, tuple[slice, slice], tuple[slice, slice]]] = []
    for src, dst in (
        ((lo, every), (hi, every)),
        ((hi, every), (lo, every)),
        ((every, lo), (every, hi)),
        ((every, hi), (every, lo)),
    ):
        ok = np.zeros_like(free)
        ok[src] = free[src] & free[dst]
        links.append((ok, src, dst))
    for _ in range(steps):
        new = p.copy()
        for ok, src, dst in links:
            move = np.where(ok, 0.125 * p, 0.0)
            new -= move
            new[dst] += move[src]
        p = new
    return (1.0 - floor) * np.maximum(p, 0.0) + floor * u


def free_graph(occupancy: np.ndarray, resolution: float) -> FreeSpaceGraph:
    """The cached 8-connected :class:`FreeSpaceGraph` of a map."""
    return graph_for(occupancy, resolution, 8)
