"""GW-GMRF: joint gas and wind mapping with a GMRF (Gongora et al. 2020).

State: per free cell the gas ``g`` (normalized by ``gas_scale``, as in
:mod:`dgse.mapping.gmrf`) and the wind ``[u_x, u_y]`` (m/s).  Factors
(``L = 1 / sigma^2``; gdm's values for 0.1 m cells):

=================  ===================================================  =======
factor             residual                                             sigma
=================  ===================================================  =======
gas observation    ``g_c - z / gas_scale``                              0.1
gas smoothness     ``g_a - g_b`` for neighbouring free cells            1.128
gas prior          ``g_k``                                              80
wind observation   ``u_c - w`` (each component)                         0.1
wind smoothness    ``u_a - u_b`` (each component, free neighbours)      0.825
mass conservation  ``-2 div u`` on every 2x2 block of cells, central    0.048
                   differences in cell units, wind 0 in solid cells
obstacles          ``u_y`` of a cell with a solid cell above or below,  0.22
                   ``u_x`` of one with a solid cell left or right
wind prior         ``u_k`` (each component)                             1000
gas-wind coupling  ``(grad g) . u``, upwind one-sided differences       0.12
=================  ===================================================  =======

The coupling makes the energy bilinear, so the estimate is Gauss-Newton from
zero, at most ``max_iter = 15`` steps, stopping when ``|dm|_inf < 1e-2`` (gdm's
schedule, no line search); the gas mean is then clipped at 0.  The variances
are the diagonal of the inverse Gauss-Newton Hessian at the final estimate (a
Laplace approximation): the gas variance is the gas block of ``H^-1`` (the
marginal, not gdm's inverse of the gas block of ``H``, which would be the
variance conditional on the wind), the wind variance its wind blocks; both by
the selected inverse of :class:`dgse.mapping.gmrf.SparseSPDFactor`.

Faithfulness notes / assumptions:

* Walls hold no variables: zero wind in solid cells is exact rather than the
  strong prior gdm uses; smoothness edges join free neighbours only.
* The map edge.  Our maps have no solid ring around them (physics spec: the
  outer boundary is the domain edge, with an inlet and an outlet the method
  is not told about).  By default (``closed_boundary=False``) the edge is
  therefore open: no obstacle or mass-conservation factor reaches across it,
  so flow may enter or leave anywhere on the edge.  ``closed_boundary=True``
  treats the outside as solid (as gdm's maps padded with obstacle cells do):
  then no net flow can cross the edge and a through-flow is forced into
  recirculation unless readings near the inlet and outlet override the soft
  factors.  Walls inside the map are always obstacles.
* Upwind differences: for ``u_x >= 0`` the x-gradient is ``g_c - g_left``,
  otherwise ``g_right - g_c`` (likewise in y), chosen from the current
  iterate and held fixed within a Gauss-Newton step; a term whose upwind
  neighbour is solid is dropped.  gdm's ``GMRF_Gas_Wind`` always uses the
  backward difference (the upwind one for positive wind); the spec asks for
  upstream weighting.  At the zero start both coincide.  The stencil switch
  where a wind component changes sign can make Gauss-Newton cycle: in one of
  three 100 x 100 test estimates the update settled at ``|dm|_inf = 0.12`` and
  the 15-step cap ended it (``info["converged"] = False``; gdm's backward
  differences also used all 15 steps there, with steps near 0.012); the
  accuracy of both variants was alike.
* gdm places the obstacle factor for a cell with walls on two sides as one
  residual ``u_x + u_y``; we use one residual per blocked component.
* Wind in m/s is not normalized; the gas is (the coupling's ``sigma 0.12`` is
  for gas in [0, 1] as in gdm).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from dgse.errors import InputDataError
from dgse.mapping import GasMap, positive
from dgse.mapping.gmrf import FreeGraph, GMRFEstimator, SparseSPDFactor, gmrf_info, gmrf_inputs
from dgse.sensing.sensors import Observations

__all__ = ["GWGMRF", "GWGMRFParams", "gwgmrf"]


@dataclass(frozen=True)
class GWGMRFParams:
    """GW-GMRF parameters (gdm's values for 0.1 m cells; gas sigmas in units of ``gas_scale``).

    Attributes:
        sigma_z, sigma_r, sigma_b: gas observation, smoothness and prior (as G-GMRF).
        sigma_wz: wind observation, m/s (0.1).
        sigma_wr: wind smoothness (0.825).
        sigma_wc: mass conservation (0.048).
        sigma_wo: zero normal wind next to obstacles (0.22).
        sigma_wb: weak wind prior (1000).
        sigma_gw: gas-wind coupling ``(grad g) . u`` (0.12).
        gas_scale: ppm per normalized gas unit; None: the largest reading.
        max_iter: Gauss-Newton steps at most (15).
        tol: stop when the largest update is below this (1e-2).
        closed_boundary: the map edge acts as a wall (default False, see the module docstring).
    """

    sigma_z: float = 0.1
    sigma_r: float = 1.128
    sigma_b: float = 80.0
    sigma_wz: float = 0.1
    sigma_wr: float = 0.825
    sigma_wc: float = 0.048
    sigma_wo: float = 0.22
    sigma_wb: float = 1000.0
    sigma_gw: float = 0.12
    gas_scale: float | None = None
    max_iter: int = 15
    tol: float = 1e-2
    closed_boundary: bool = False

    def __post_init__(self) -> None:
        for name in (
            "sigma_z",
            "sigma_r",
            "sigma_b",
            "sigma_wz",
            "sigma_wr",
            "sigma_wc",
            "sigma_wo",
            "sigma_wb",
            "sigma_gw",
            "tol",
        ):
            positive(name, getattr(self, name))
        if self.gas_scale is not None:
            positive("gas_scale", self.gas_scale)
        if int(self.max_iter) < 1:
            raise InputDataError(f"max_iter must be at least 1, got {self.max_iter}")


class _Rows:
    """Accumulates sparse residual rows ``sum coef * x[col] - target`` with a weight each."""

    def __init__(self) -> None:
        self.r: list[np.ndarray] = []
        self.c: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.target: list[np.ndarray] = []
        self.weight: list[np.ndarray] = []
        self.n = 0

    def add(
        self,
        cols: list[np.ndarray],
        coefs: list[np.ndarray | float],
        target: np.ndarray | float,
        weight: float,
        count: int,
    ) -> None:
        """``count`` rows; ``cols[t][k]`` (-1: absent) with ``coefs[t]`` is term ``t`` of row ``k``."""
        if count == 0:
            return
        rows = np.arange(self.n, self.n + count)
        for col, coef in zip(cols, coefs, strict=True):
            keep = col >= 0
            self.r.append(rows[keep])
            self.c.append(col[keep])
            self.v.append(np.broadcast_to(np.asarray(coef, dtype=np.float64), (count,))[keep])
        self.target.append(np.broadcast_to(np.asarray(target, dtype=np.float64), (count,)).copy())
        self.weight.append(np.full(count, weight))
        self.n += count

    def build(self, n_cols: int) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        A = sp.csr_matrix(
            (np.concatenate(self.v), (np.concatenate(self.r), np.concatenate(self.c))), shape=(self.n, n_cols)
        )
        return A, np.concatenate(self.target), np.concatenate(self.weight)


def _neighbours(graph: FreeGraph, closed: bool) -> dict[str, np.ndarray]:
    """Node of each free cell's neighbour (-1: solid or outside) and whether that side is a wall."""
    idx = graph.index
    H, W = idx.shape
    pad = np.pad(idx, 1, constant_values=-1)
    r, c = graph.rows + 1, graph.cols + 1
    out = {"left": pad[r, c - 1], "right": pad[r, c + 1], "down": pad[r - 1, c], "up": pad[r + 1, c]}
    inside = {
        "left": graph.cols > 0,
        "right": graph.cols < W - 1,
        "down": graph.rows > 0,
        "up": graph.rows < H - 1,
    }
    for k in ("left", "right", "down", "up"):
        # a wall on that side: a solid cell inside the map, or the map edge when closed
        out[f"wall_{k}"] = (out[k] < 0) & (inside[k] | closed)
    return out


def _linear_system(
    graph: FreeGraph, obs_nodes: np.ndarray, z: np.ndarray, wind: np.ndarray, p: GWGMRFParams
) -> tuple[sp.csr_matrix, np.ndarray]:
    """``A^T L A`` and ``A^T L c`` of every linear factor (all but the coupling)."""
    n = graph.n
    G, UX, UY = 0, n, 2 * n
    rows = _Rows()
    nodes = np.arange(n)
    m = obs_nodes.size
    a, b = graph.edge_a, graph.edge_b
    e = a.size
    # gas
    rows.add([G + obs_nodes], [1.0], z, p.sigma_z**-2, m)
    rows.add([G + a, G + b], [1.0, -1.0], 0.0, p.sigma_r**-2, e)
    rows.add([G + nodes], [1.0], 0.0, p.sigma_b**-2, n)
    # wind observations, smoothness, prior
    rows.add([UX + obs_nodes], [1.0], wind[:, 0], p.sigma_wz**-2, m)
    rows.add([UY + obs_nodes], [1.0], wind[:, 1], p.sigma_wz**-2, m)
    for off in (UX, UY):
        rows.add([off + a, off + b], [1.0, -1.0], 0.0, p.sigma_wr**-2, e)
        rows.add([off + nodes], [1.0], 0.0, p.sigma_wb**-2, n)
    # mass conservation on 2x2 blocks (top-left corner (i, j)); outside/solid cells carry no wind
    idx = graph.index
    H, W = idx.shape
    pad = np.pad(idx, 1, constant_values=-1)  # pad[i + 1, j + 1] = idx[i, j]
    lo = -1 if p.closed_boundary else 0
    hi_i = H if p.closed_boundary else H - 1
    hi_j = W if p.closed_boundary else W - 1
    gi, gj = np.meshgrid(np.arange(lo, hi_i), np.arange(lo, hi_j), indexing="ij")
    ii, jj = gi.ravel(), gj.ravel()
    c00, c10 = pad[ii + 1, jj + 1], pad[ii + 2, jj + 1]
    c01, c11 = pad[ii + 1, jj + 2], pad[ii + 2, jj + 2]
    keep = (c00 >= 0) | (c10 >= 0) | (c01 >= 0) | (c11 >= 0)
    c00, c10, c01, c11 = c00[keep], c10[keep], c01[keep], c11[keep]

    def shift(col: np.ndarray, off: int) -> np.ndarray:
        return np.where(col >= 0, col + off, -1)

    rows.add(
        [
            shift(c00, UY),
            shift(c10, UY),
            shift(c01, UY),
            shift(c11, UY),
            shift(c00, UX),
            shift(c10, UX),
            shift(c01, UX),
            shift(c11, UX),
        ],
        [1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, -1.0],
        0.0,
        p.sigma_wc**-2,
        int(c00.size),
    )
    # zero normal wind next to walls
    nb = _neighbours(graph, p.closed_boundary)
    blocked_y = nodes[nb["wall_down"] | nb["wall_up"]]
    blocked_x = nodes[nb["wall_left"] | nb["wall_right"]]
    rows.add([UY + blocked_y], [1.0], 0.0, p.sigma_wo**-2, blocked_y.size)
    rows.add([UX + blocked_x], [1.0], 0.0, p.sigma_wo**-2, blocked_x.size)
    A, c, w = rows.build(3 * n)
    AtL = A.T.multiply(w).tocsr()
    return (AtL @ A).tocsr(), AtL @ c


def _coupling(x: np.ndarray, n: int, nb: dict[str, np.ndarray]) -> tuple[sp.csr_matrix, np.ndarray]:
    """Jacobian (``n x 3n``) and residual of ``(grad g) . u`` with upwind differences at ``x``."""
    g, ux, uy = x[:n], x[n : 2 * n], x[2 * n :]
    k = np.arange(n)
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    grads = []
    for u, back, fwd in ((ux, nb["left"], nb["right"]), (uy, nb["down"], nb["up"])):
        pos = u >= 0
        nbr = np.where(pos, back, fwd)
        has = nbr >= 0
        safe = np.where(has, nbr, 0)
        # pos: g_c - g_nb ; neg: g_nb - g_c
        sign_c = np.where(pos, 1.0, -1.0)
        dg = np.where(has, sign_c * (g - g[safe]), 0.0)
        grads.append(dg)
        rows += [k[has], k[has]]
        cols += [k[has], nbr[has]]
        vals += [(sign_c * u)[has], (-sign_c * u)[has]]
    dgx, dgy = grads
    rows += [k, k]
    cols += [n + k, 2 * n + k]
    vals += [dgx, dgy]
    J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, 3 * n))
    return J, dgx * ux + dgy * uy


def gwgmrf(
    occupancy: np.ndarray,
    resolution: float,
    observations: Observations,
    params: GWGMRFParams | None = None,
    variance: str = "takahashi",
    n_samples: int = 200,
) -> GasMap:
    """GW-GMRF: gas mean/variance (ppm) and wind mean/variance (m/s) on the free cells.

    Args:
        occupancy, resolution, observations: the map and its readings, gas and wind
            (:func:`dgse.mapping.check_inputs`; the parameters are per cell, used as given).
        params: :class:`GWGMRFParams` (gdm defaults when None).
        variance, n_samples: the marginal variances' method, as in :func:`~dgse.mapping.gmrf.ggmrf`.

    Raises:
        InputDataError: as :func:`~dgse.mapping.gmrf.ggmrf`.
    """
    t0 = time.perf_counter()
    p = params or GWGMRFParams()
    inp, scale, graph, obs_nodes = gmrf_inputs(occupancy, resolution, observations, variance, p.gas_scale)
    n = graph.n
    H_lin, b_lin = _linear_system(graph, obs_nodes, inp.gas / scale, inp.wind, p)
    nb = _neighbours(graph, p.closed_boundary)
    l_gw = p.sigma_gw**-2
    x = np.zeros(3 * n)
    steps: list[float] = []
    converged = False
    for _ in range(int(p.max_iter)):
        J, r = _coupling(x, n, nb)
        Hm = H_lin + l_gw * (J.T @ J)
        grad = H_lin @ x - b_lin + l_gw * (J.T @ r)
        dx = -SparseSPDFactor(Hm).solve(grad)
        x += dx
        steps.append(float(np.abs(dx).max()))
        if steps[-1] < p.tol:
            converged = True
            break
    t_solve = time.perf_counter() - t0
    J, _ = _coupling(x, n, nb)
    fac = SparseSPDFactor(H_lin + l_gw * (J.T @ J))
    var, vinfo = fac.inverse_diagonal(variance, n_samples)
    var = np.maximum(var, 0.0)
    gas = np.maximum(x[:n], 0.0) * scale
    wind_mean = np.stack([graph.scatter(x[n : 2 * n]), graph.scatter(x[2 * n :])])
    wind_var = np.stack([graph.scatter(var[n : 2 * n]), graph.scatter(var[2 * n :])])
    info = gmrf_info(
        "gwgmrf",
        "marginal variance, gas block of the inverse Gauss-Newton Hessian",
        scale,
        {k: getattr(p, k) for k in GWGMRFParams.__dataclass_fields__},
        {"iterations": len(steps), "converged": converged, "step_inf_norms": steps, "n_free": n},
        (t0, t_solve),
        vinfo,
    )
    return GasMap(graph.scatter(gas), graph.scatter(var[:n] * scale**2), wind_mean, wind_var, info)


class GWGMRF(GMRFEstimator):
    """GW-GMRF behind the Estimator protocol (registry name ``"gwgmrf"``); gives gas and wind.

    Arguments as :class:`~dgse.mapping.gmrf.GMRFEstimator` (``params``: :class:`GWGMRFParams`).
    """

    name = "gwgmrf"
    params_class = GWGMRFParams
    solve = staticmethod(gwgmrf)
