"""GaBP+: the G-GMRF model solved by Gaussian belief propagation (Rhodes et al. 2023).

Model: the quadratic model of :mod:`dgse.mapping.gmrf` on the free-cell graph
(edges between 4-neighbouring free cells only, the "structurally aware" part),
written as a precision ``J`` and potential ``h``:
``J_ii = lambda_d + deg(i) lambda_p + lambda_o n_obs(i)``, ``J_ij = -lambda_p``
on edges, ``h_i = lambda_o sum z``.  Defaults (``callum-rhodes/gabp_mapping``):
``lambda_p = 0.5``, ``lambda_o = 10``, ``lambda_d = 1e-4``, residual threshold
``epsilon = 1e-4``.  With ``sigma = lambda^-1/2`` this is exactly G-GMRF's
model, so at convergence the means agree with :func:`dgse.mapping.gmrf.ggmrf`
(the model is walk-summable: ``J`` is a diagonally dominant M-matrix, so loopy
GaBP converges and its means are exact).

Messages (spec ``baselines.md``): marginal ``P_i = J_ii + sum_k P_ki``,
``P_i mu_i = h_i + sum_k P_ki mu_ki``; message ``i -> j``:
``P_ij = -J_ij^2 / (P_i - P_ji)``, ``mu_ij = (P_i mu_i - P_ji mu_ji) / J_ij``.
Schedule as the reference implementation: *wildfire* from each reading in
turn (a FIFO queue: a node sends to all its neighbours, and every neighbour
whose incoming message mean changed by more than ``epsilon`` is queued),
then *residual BP* (always the node with the largest residual sends next; a
priority queue) until no residual exceeds ``epsilon`` or ``max_messages``
messages have been sent (``info["converged"]`` says which).  The messages
and the reported beliefs are recomputed from all incoming messages at the end.

Faithfulness notes / assumptions:

* Batch use: the reference grows its graph lazily from the readings (cells
  that wildfire never reaches get no node and report 0); here the whole
  free-cell graph exists from the start and every free cell gets a belief.
  Messages start at 0 (the reference starts message precisions at
  ``lambda_p``); the fixed point is the same.
* Readings are normalized by ``gas_scale`` (default: the largest reading), as
  for the GMRFs, and results scaled back; the mean does not depend on it
  (linear model), the variance scales with ``gas_scale^2``.  The reference
  works on raw readings; its variance ``min(1 / P_i, 1)`` (capped at 1 as
  there) is therefore in normalized units here.  It is the loopy-BP marginal
  precision, known to be overconfident; the paper leaves GaBP+ out of the NLL
  (``info["nll_comparable"] = False``).
* No measurement ageing (``lambda_t``): all readings are simultaneous.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from dgse.errors import InputDataError
from dgse.mapping import GasMap, MappingEstimator, check_inputs, positive, resolve_params
from dgse.mapping.gmrf import FreeGraph, free_graph
from dgse.sensing.sensors import Observations

__all__ = ["GaBPParams", "GaBPPlus", "gabp", "gabp_solve"]


@dataclass(frozen=True)
class GaBPParams:
    """GaBP+ parameters (reference defaults).

    Attributes:
        lambda_p: smoothness precision between neighbouring free cells (0.5).
        lambda_o: observation precision, in normalized gas units (10).
        lambda_d: prior precision towards 0 (1e-4).
        epsilon: residual threshold on message means (1e-4, normalized units).
        max_messages: total message budget; None: ``2000 * number of directed edges``.
        wildfire_messages: budget of the wildfire phase within it (None: no separate cap);
            residual BP continues from where a capped wildfire stopped.
        gas_scale: ppm per normalized unit; None: the largest reading.
        var_cap: cap on the reported variance in normalized units (1, as the reference).
    """

    lambda_p: float = 0.5
    lambda_o: float = 10.0
    lambda_d: float = 1e-4
    epsilon: float = 1e-4
    max_messages: int | None = None
    wildfire_messages: int | None = None
    gas_scale: float | None = None
    var_cap: float = 1.0

    def __post_init__(self) -> None:
        for name in ("lambda_p", "lambda_o", "lambda_d", "epsilon", "var_cap"):
            positive(name, getattr(self, name))
        for name in ("max_messages", "wildfire_messages"):
            value = getattr(self, name)
            if value is not None and int(value) < 1:
                raise InputDataError(f"{name} must be at least 1, got {value}")
        if self.gas_scale is not None:
            positive("gas_scale", self.gas_scale)


# -- compiled core ---------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def _send(s, adj_ptr, adj, rev, jii, h, j_off, in_p, in_u, resid):  # pragma: no cover
    """Node ``s`` sends to all its neighbours; returns the number of messages."""
    p = jii[s]
    pu = h[s]
    for e in range(adj_ptr[s], adj_ptr[s + 1]):
        p += in_p[e]
        pu += in_p[e] * in_u[e]
    for e in range(adj_ptr[s], adj_ptr[s + 1]):
        k = adj[e]
        r = rev[e]
        new_p = -(j_off * j_off) / (p - in_p[e])
        new_u = (pu - in_p[e] * in_u[e]) / j_off
        d = abs(new_u - in_u[r])
        in_p[r] = new_p
        in_u[r] = new_u
        if d > resid[k]:
            resid[k] = d
    resid[s] = 0.0
    return adj_ptr[s + 1] - adj_ptr[s]


@numba.njit(cache=True, nogil=True)
def _heap_push(keys, vals, size, key, val):  # pragma: no cover
    i = size
    keys[i] = key
    vals[i] = val
    while i > 0:
        parent = (i - 1) // 2
        if keys[parent] >= keys[i]:
            break
        keys[parent], keys[i] = keys[i], keys[parent]
        vals[parent], vals[i] = vals[i], vals[parent]
        i = parent
    return size + 1


@numba.njit(cache=True, nogil=True)
def _heap_pop(keys, vals, size):  # pragma: no cover
    key = keys[0]
    val = vals[0]
    size -= 1
    keys[0] = keys[size]
    vals[0] = vals[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        big = left
        if left + 1 < size and keys[left + 1] > keys[left]:
            big = left + 1
        if keys[i] >= keys[big]:
            break
        keys[i], keys[big] = keys[big], keys[i]
        vals[i], vals[big] = vals[big], vals[i]
        i = big
    return key, val, size


@numba.njit(cache=True, nogil=True)
def _gabp_run(adj_ptr, adj, rev, jii, h, j_off, bombs, eps, max_messages, wild_messages):  # pragma: no cover
    n = jii.size
    in_p = np.zeros(adj.size)
    in_u = np.zeros(adj.size)
    resid = np.zeros(n)
    msgs_wild = 0
    msgs_resid = 0
    # wildfire from each reading in turn
    queue = np.empty(n, dtype=np.int64)
    inq = np.zeros(n, dtype=np.bool_)
    for b in range(bombs.size):
        head = 0
        count = 1
        queue[0] = bombs[b]
        inq[bombs[b]] = True
        while count > 0 and msgs_wild < wild_messages:
            s = queue[head]
            head = (head + 1) % n
            count -= 1
            inq[s] = False
            msgs_wild += _send(s, adj_ptr, adj, rev, jii, h, j_off, in_p, in_u, resid)
            for e in range(adj_ptr[s], adj_ptr[s + 1]):
                k = adj[e]
                if resid[k] > eps and not inq[k]:
                    queue[(head + count) % n] = k
                    count += 1
                    inq[k] = True
        for q in range(count):  # budget hit: leave the queue empty for the next bomb
            inq[queue[(head + q) % n]] = False
    # residual BP with a lazy max-heap
    cap = 8 * n + 16
    keys = np.empty(cap)
    vals = np.empty(cap, dtype=np.int64)
    size = 0
    for i in range(n):
        if resid[i] > eps:
            size = _heap_push(keys, vals, size, resid[i], i)
    budget = max_messages - msgs_wild
    rebuilds = 0
    converged = False
    while True:
        if size == 0:
            converged = True
            break
        key, s, size = _heap_pop(keys, vals, size)
        if key != resid[s]:
            continue  # stale entry
        if key <= eps:
            converged = True
            break
        if msgs_resid >= budget:
            break
        msgs_resid += _send(s, adj_ptr, adj, rev, jii, h, j_off, in_p, in_u, resid)
        for e in range(adj_ptr[s], adj_ptr[s + 1]):
            k = adj[e]
            if resid[k] > eps:
                if size + 1 > cap:  # compact: rebuild from the current residuals
                    rebuilds += 1
                    size = 0
                    for i in range(n):
                        if resid[i] > eps:
                            size = _heap_push(keys, vals, size, resid[i], i)
                    break
                size = _heap_push(keys, vals, size, resid[k], k)
    max_resid = 0.0
    for i in range(n):
        max_resid = max(max_resid, resid[i])
    # beliefs from all incoming messages
    mean = np.empty(n)
    prec = np.empty(n)
    for i in range(n):
        p = jii[i]
        pu = h[i]
        for e in range(adj_ptr[i], adj_ptr[i + 1]):
            p += in_p[e]
            pu += in_p[e] * in_u[e]
        prec[i] = p
        mean[i] = pu / p
    return mean, prec, msgs_wild, msgs_resid, converged, max_resid, rebuilds


def _adjacency(graph: FreeGraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR adjacency ``(ptr, nbr, rev)``; ``rev[e]`` is the slot of the reverse edge of slot ``e``."""
    n = graph.n
    src = np.concatenate([graph.edge_a, graph.edge_b])
    dst = np.concatenate([graph.edge_b, graph.edge_a])
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=ptr[1:])
    key = src * n + dst  # sorted
    rev = np.searchsorted(key, dst * n + src).astype(np.int64)
    return ptr, dst.astype(np.int64), rev


def gabp_solve(
    graph: FreeGraph, obs_nodes: np.ndarray, z: np.ndarray, params: GaBPParams
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """GaBP+ on ``graph`` with readings ``z`` (normalized) at ``obs_nodes`` (in reading order).

    Returns the belief means, the belief precisions ``P_i`` (``(N,)``) and solver statistics.
    """
    n = graph.n
    ptr, adj, rev = _adjacency(graph)
    deg = np.diff(ptr).astype(np.float64)
    counts = np.bincount(obs_nodes, minlength=n).astype(np.float64)
    jii = params.lambda_d + params.lambda_p * deg + params.lambda_o * counts
    h = params.lambda_o * np.bincount(obs_nodes, weights=z, minlength=n)
    budget = int(params.max_messages) if params.max_messages is not None else 2000 * max(int(adj.size), 1)
    wild = budget if params.wildfire_messages is None else min(budget, int(params.wildfire_messages))
    mean, prec, mw, mr, conv, mres, rebuilds = _gabp_run(
        ptr, adj, rev, jii, h, -params.lambda_p, obs_nodes.astype(np.int64), params.epsilon, budget, wild
    )
    info = {
        "messages_wildfire": int(mw),
        "messages_residual": int(mr),
        "message_budget": budget,
        "converged": bool(conv),
        "max_residual": float(mres),
        "heap_rebuilds": int(rebuilds),
    }
    return mean, prec, info


def gabp(
    occupancy: np.ndarray,
    resolution: float,
    observations: Observations,
    params: GaBPParams | None = None,
) -> GasMap:
    """GaBP+ gas mean and loopy-BP variance (ppm) on the free cells.

    Args:
        occupancy, resolution, observations: the map and its readings
            (:func:`dgse.mapping.check_inputs`; the parameters are per cell, used as given;
            wildfire order = reading order).
        params: :class:`GaBPParams` (reference defaults when None).

    Raises:
        InputDataError: see :func:`dgse.mapping.check_inputs`.
    """
    t0 = time.perf_counter()
    p = params or GaBPParams()
    inp = check_inputs(occupancy, resolution, observations)
    scale = inp.gas_scale(p.gas_scale)
    graph = free_graph(inp.free)
    obs_nodes = graph.index[inp.cells[:, 0], inp.cells[:, 1]]
    mean, prec, sinfo = gabp_solve(graph, obs_nodes, inp.gas / scale, p)
    var = np.minimum(1.0 / prec, p.var_cap)
    info: dict[str, Any] = {
        "method": "gabp",
        "variance_kind": "loopy GaBP marginal variance (overconfident), capped",
        "nll_comparable": False,
        "obstacle_aware": True,
        "gas_scale": scale,
        "params": {
            "lambda_p": p.lambda_p,
            "lambda_o": p.lambda_o,
            "lambda_d": p.lambda_d,
            "epsilon": p.epsilon,
        },
        "n_free": graph.n,
        **sinfo,
        "map_seconds": time.perf_counter() - t0,
    }
    return GasMap(graph.scatter(mean * scale), graph.scatter(var * scale**2), info=info)


class GaBPPlus(MappingEstimator):
    """GaBP+ behind the Estimator protocol (registry name ``"gabp"``).

    Args:
        tuning: optional tuning file (or mapping) whose ``"gabp"`` entry overrides the defaults.
        **params: :class:`GaBPParams` fields, overriding defaults and tuning.
    """

    name = "gabp"

    def __init__(
        self, tuning: str | os.PathLike[str] | Mapping[str, Any] | None = None, **params: Any
    ) -> None:
        self.params: GaBPParams = resolve_params(GaBPParams, self.name, tuning, params)

    def map(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> GasMap:
        return gabp(occupancy, resolution, observations, self.params)
