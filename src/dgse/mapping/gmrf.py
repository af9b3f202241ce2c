"""G-GMRF gas distribution mapping (Monroy et al. 2016) and the sparse variance machinery.

Model (spec ``baselines.md``): one Gaussian variable ``m_k`` per *free* cell and
the energy

``E(m) = sum_edges L_r (m_a - m_b)^2 + sum_obs L_o (z_i - m_c(i))^2 + sum_k L_0 m_k^2``

(``L = 1 / sigma^2``; each factor a Gaussian of standard deviation ``sigma``,
i.e. the density is ``exp(-E / 2)``), whose precision is
``H = L_r Lap + L_o diag(n_obs) + L_0 I`` and mean ``H^-1 L_o sum_obs z``.
Edges join 4-neighbouring free cells only, so walls and the map edge cut the
graph (gdm's connectivity test of two adjacent cells reduces to this on a
grid without coarsening).  gdm's values for 0.1 m cells: ``sigma_z = 0.1``,
``sigma_r = 1.128``, ``sigma_b = 80``.  Readings are simultaneous (no
time-dependent observation variance, gdm's ``gtk``).

Gas scale.  gdm works on readings normalized by ``max_gas_concentration``
(its default 1, i.e. readings in [0, 1]); equivalently its sigmas scale with
the concentration.  We normalize by ``gas_scale`` (default: the largest
reading of the estimate), solve, and scale back: the mean is independent of
the choice, the variance scales with ``gas_scale^2``.  Without this, the
published ``sigma_z = 0.1`` would mean 0.1 ppm, far below the sensor noise of
ppm-valued readings.

Posterior variance ``diag(H^-1)`` (:class:`SparseSPDFactor`):

* ``"takahashi"`` (default): the selected inverse.  SciPy has no sparse
  Cholesky, so we factor ``H`` with SuperLU (:func:`scipy.sparse.linalg.splu`)
  in symmetric mode (minimum-degree ordering on ``A + A^T``, diagonal pivots
  only), which for an SPD matrix yields ``P H P^T = L D L^T`` (checked: equal
  row and column permutations, unit-diagonal ``L``, positive ``D``).  The
  Takahashi recursion ``Z = D^-1 L^-1 + (I - L^T) Z`` then gives ``H^-1`` on
  the sparsity pattern of ``L`` (compiled with numba).  SuperLU drops factor
  entries that cancel to exactly zero, so its pattern is not always closed
  under the recursion (it happened for GW-GMRF's matrices); the recursion
  therefore runs on the symbolic Cholesky pattern of the same ordering
  (elimination tree, computed here) with SuperLU's values placed on it.
  Exact up to rounding (checked against dense inverses in the tests); cost
  about ``sum_j |col_j|^2`` over the factor's columns: 0.05 s for G-GMRF and
  1.5 s for GW-GMRF's 3N system on a 100 x 100 map.  Should SuperLU pivot off
  the diagonal (not seen for these SPD matrices), the method falls back to
  ``"blocked"`` and says so in ``info["variance_fallback"]``.
* ``"blocked"``: exact reference, ``H^-1 e_k`` for all ``k`` by solves with
  the same factor (``N`` solves, one right-hand side at a time because
  SuperLU's multi-right-hand-side solve measured slower per column; about 14 s
  for ``N = 10^4``: for checks and as the fallback only).
* ``"sampling"``: Monte-Carlo, ``x = P^T L^-T D^-1/2 z`` with ``z ~ N(0, I)``
  has covariance ``H^-1``; the variance is the mean of ``x^2`` over
  ``n_samples`` draws (relative error about ``sqrt(2 / n_samples)``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from dgse.errors import InputDataError
from dgse.mapping import GasMap, MappingEstimator, MappingInputs, check_inputs, positive, resolve_params
from dgse.sensing.sensors import Observations

__all__ = [
    "GGMRF",
    "VARIANCE_METHODS",
    "FreeGraph",
    "GGMRFParams",
    "SparseSPDFactor",
    "check_variance_method",
    "diag_of_inverse",
    "free_graph",
    "gas_precision",
    "ggmrf",
    "gmrf_info",
    "gmrf_inputs",
    "selected_inverse_diag",
]

#: Ways to compute ``diag(H^-1)``.
VARIANCE_METHODS = ("takahashi", "blocked", "sampling")
_BLOCK_RHS = 256


# -- the free-cell graph -----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FreeGraph:
    """The free cells of a map as graph nodes and their 4-neighbour free pairs as edges.

    Attributes:
        index: ``int64 (H, W)``: node of each free cell, -1 on solid cells.
        rows, cols: ``int64 (N,)`` cell ``(i, j)`` of each node (row-major order).
        edge_a, edge_b: ``int64 (E,)`` node pairs of the edges (``a < b``).
    """

    index: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    edge_a: np.ndarray
    edge_b: np.ndarray

    @property
    def n(self) -> int:
        return int(self.rows.size)

    def laplacian(self) -> sp.csr_matrix:
        """The graph Laplacian ``sum_edges (e_a - e_b)(e_a - e_b)^T`` (``N x N``, CSR)."""
        n = self.n
        a, b = self.edge_a, self.edge_b
        off = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
        off = off + off.T
        deg = np.bincount(np.concatenate([a, b]), minlength=n).astype(np.float64)
        return (sp.diags(deg) - off).tocsr()

    def scatter(self, values: np.ndarray, fill: float = 0.0) -> np.ndarray:
        """``(H, W)`` array with ``values`` (``(N,)``) on the free cells and ``fill`` elsewhere."""
        out = np.full(self.index.shape, fill, dtype=np.float64)
        out[self.rows, self.cols] = values
        return out


def free_graph(free: np.ndarray) -> FreeGraph:
    """The :class:`FreeGraph` of a ``bool (H, W)`` free-cell mask."""
    free = np.asarray(free, dtype=bool)
    index = np.full(free.shape, -1, dtype=np.int64)
    rows, cols = np.nonzero(free)
    index[rows, cols] = np.arange(rows.size)
    horiz = free[:, :-1] & free[:, 1:]
    vert = free[:-1, :] & free[1:, :]
    ea = np.concatenate([index[:, :-1][horiz], index[:-1, :][vert]])
    eb = np.concatenate([index[:, 1:][horiz], index[1:, :][vert]])
    return FreeGraph(index, rows.astype(np.int64), cols.astype(np.int64), ea, eb)


def gas_precision(
    graph: FreeGraph, obs_nodes: np.ndarray, z: np.ndarray, l_r: float, l_o: float, l_0: float
) -> tuple[sp.csc_matrix, np.ndarray]:
    """``H = l_r Lap + l_o diag(n_obs) + l_0 I`` and ``b = l_o sum_obs z`` of the G-GMRF (``H m = b``)."""
    n = graph.n
    counts = np.bincount(obs_nodes, minlength=n).astype(np.float64)
    H = l_r * graph.laplacian() + sp.diags(l_0 + l_o * counts)
    b = l_o * np.bincount(obs_nodes, weights=z, minlength=n)
    return H.tocsc(), b


# -- selected inverse ---------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def _add_rows_below(rows, lo, hi, j, mark, buf, m):  # pragma: no cover
    """Append to ``buf[m:]`` the rows ``rows[lo:hi]`` below ``j`` not yet marked for column ``j``
    (marking them); returns the new count of ``buf``."""
    for q in range(lo, hi):
        i = rows[q]
        if i > j and mark[i] != j:
            mark[i] = j
            buf[m] = i
            m += 1
    return m


@numba.njit(cache=True, nogil=True)
def _symbolic_cholesky(n: int, bp: np.ndarray, bi: np.ndarray):  # pragma: no cover
    """Row pattern of the strictly lower Cholesky factor of a matrix whose strictly lower part is (bp, bi).

    Column ``j`` of ``L`` holds the rows of column ``j`` of ``B`` below the
    diagonal and the rows of its elimination-tree children's columns below
    ``j``; returns CSC ``(indptr, indices)`` with sorted rows.
    """
    cap = max(16, 4 * bi.size)
    li = np.empty(cap, dtype=np.int64)
    lp = np.zeros(n + 1, dtype=np.int64)
    head = np.full(n, -1, dtype=np.int64)  # first child
    nxt = np.full(n, -1, dtype=np.int64)  # next sibling
    mark = np.full(n, -1, dtype=np.int64)
    buf = np.empty(n, dtype=np.int64)
    for j in range(n):
        m = _add_rows_below(bi, bp[j], bp[j + 1], j, mark, buf, 0)
        c = head[j]
        while c >= 0:
            m = _add_rows_below(li, lp[c], lp[c + 1], j, mark, buf, m)
            c = nxt[c]
        rows = np.sort(buf[:m])
        if lp[j] + m > cap:
            cap = max(2 * cap, lp[j] + m)
            grown = np.empty(cap, dtype=np.int64)
            grown[: lp[j]] = li[: lp[j]]
            li = grown
        li[lp[j] : lp[j] + m] = rows
        lp[j + 1] = lp[j] + m
        if m > 0:
            parent = rows[0]
            nxt[j] = head[parent]
            head[parent] = j
    return lp, li[: lp[n]].copy()


@numba.njit(cache=True, nogil=True)
def _scatter_values(lp, li, sp_, si, sx):  # pragma: no cover
    """Values of a factor ``(sp_, si, sx)`` placed on the pattern ``(lp, li)``; False if one does not fit."""
    n = lp.size - 1
    lx = np.zeros(li.size)
    ok = True
    for j in range(n):
        ptr = lp[j]
        end = lp[j + 1]
        for q in range(sp_[j], sp_[j + 1]):
            r = si[q]
            while ptr < end and li[ptr] < r:
                ptr += 1
            if ptr < end and li[ptr] == r:
                lx[ptr] = sx[q]
            elif sx[q] != 0.0:
                ok = False
    return lx, ok


@numba.njit(cache=True, nogil=True)
def _takahashi(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, dinv: np.ndarray
):  # pragma: no cover
    """``diag(B^-1)`` for ``B = L D L^T``; ``L`` strictly lower, CSC, sorted rows; False if not closed."""
    n = dinv.size
    z = np.zeros(data.size)
    zd = np.zeros(n)
    maxlen = 0
    for j in range(n):
        maxlen = max(maxlen, indptr[j + 1] - indptr[j])
    acc = np.zeros(maxlen)
    ok = True
    for j in range(n - 1, -1, -1):
        s = indptr[j]
        e = indptr[j + 1]
        m = e - s
        for a in range(m):
            acc[a] = data[s + a] * zd[indices[s + a]]
        for a in range(m):
            ra = indices[s + a]
            la = data[s + a]
            ptr = indptr[ra]
            end = indptr[ra + 1]
            for b in range(a + 1, m):
                rb = indices[s + b]
                while ptr < end and indices[ptr] < rb:
                    ptr += 1
                if ptr >= end or indices[ptr] != rb:
                    ok = False
                    continue
                zab = z[ptr]  # Z[rb, ra]
                acc[a] += data[s + b] * zab
                acc[b] += la * zab
        diag = dinv[j]
        for a in range(m):
            z[s + a] = -acc[a]
            diag -= data[s + a] * z[s + a]
        zd[j] = diag
    return zd, ok


class SparseSPDFactor:
    """A sparse symmetric positive definite matrix factored once, for solves and ``diag(A^-1)``.

    SuperLU in symmetric mode (see the module docstring); ``symmetric`` tells
    whether the factor is the ``L D L^T`` the Takahashi recursion needs.

    Args:
        A: ``N x N`` SPD sparse matrix.

    Raises:
        InputDataError: the matrix is not square or the factorization fails (singular).
    """

    def __init__(self, A: sp.spmatrix) -> None:
        A = sp.csc_matrix(A)
        if A.shape[0] != A.shape[1]:
            raise InputDataError(f"matrix must be square, got {A.shape}")
        t0 = time.perf_counter()
        try:
            self.lu = spla.splu(
                A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
            )
        except RuntimeError as e:
            raise InputDataError(f"GMRF precision matrix cannot be factored: {e}") from None
        self.n = int(A.shape[0])
        self.factor_seconds = time.perf_counter() - t0
        self._A = A
        self._ldl: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.symmetric = bool(np.array_equal(self.lu.perm_r, self.lu.perm_c))

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^-1 b`` (``b`` of shape ``(N,)`` or ``(N, k)``)."""
        return self.lu.solve(np.asarray(b, dtype=np.float64))

    def _lower(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """``(indptr, indices, values, D)`` of the strictly lower ``L`` of ``P A P^T = L D L^T``
        on the closed (symbolic Cholesky) pattern, or None when the factor is not ``L D L^T``.

        SuperLU's ``L`` drops entries that cancel to zero, so its pattern need not be
        closed under the Takahashi recursion; its values are placed on the symbolic
        pattern of the same ordering instead (the missing entries are zeros).
        """
        if self._ldl is None and self.symmetric:
            L = self.lu.L.tocsc()
            d = self.lu.U.diagonal()
            if not (np.allclose(L.diagonal(), 1.0) and (d > 0).all()):
                self.symmetric = False
                return None
            Ls = sp.tril(L, k=-1, format="csc")
            Ls.sort_indices()
            q = np.argsort(self.lu.perm_c)  # B = A[q][:, q]
            B = sp.tril(self._A[q][:, q], k=-1, format="csc")
            B.sort_indices()
            lp, li = _symbolic_cholesky(self.n, B.indptr.astype(np.int64), B.indices.astype(np.int64))
            lx, ok = _scatter_values(lp, li, Ls.indptr.astype(np.int64), Ls.indices.astype(np.int64), Ls.data)
            if not ok:
                self.symmetric = False
                return None
            self._ldl = (lp, li, lx, d)
        return self._ldl

    def inverse_diagonal(
        self, method: str = "takahashi", n_samples: int = 200, seed: int | None = 0
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """``diag(A^-1)`` by ``method`` (one of :data:`VARIANCE_METHODS`) and how it was computed."""
        check_variance_method(method)
        t0 = time.perf_counter()
        info: dict[str, Any] = {"variance_method": method}
        ldl = self._lower()
        if method in ("takahashi", "sampling") and ldl is None:
            info["variance_fallback"] = "factor is not L D L^T (SuperLU pivoted): blocked solves"
            method = "blocked"
        diag: np.ndarray | None = None
        if method == "takahashi":
            assert ldl is not None
            lp, li, lx, d = ldl
            zd, ok = _takahashi(lp, li, lx, 1.0 / d)
            if ok:
                diag = zd[self.lu.perm_c]
                info["factor_nnz"] = int(li.size + self.n)
            else:
                info["variance_fallback"] = "factor pattern not closed: blocked solves"
                method = "blocked"
        if method == "sampling":
            assert ldl is not None
            lp, li, lx, d = ldl
            Ls = sp.csc_matrix((lx, li, lp), shape=(self.n, self.n))
            n_samples = int(n_samples)
            if n_samples < 2:
                raise InputDataError(f"n_samples must be at least 2, got {n_samples}")
            rng = np.random.default_rng(seed)
            Lt = (Ls + sp.identity(self.n, format="csc")).T.tocsr()
            acc = np.zeros(self.n)
            for s in range(0, n_samples, _BLOCK_RHS):
                k = min(_BLOCK_RHS, n_samples - s)
                rhs = rng.standard_normal((self.n, k)) / np.sqrt(d)[:, None]
                y = spla.spsolve_triangular(Lt, rhs, lower=False, unit_diagonal=True)
                acc += (y * y).sum(axis=1)
            diag = (acc / n_samples)[self.lu.perm_c]
            info["n_samples"] = n_samples
        if method == "blocked":
            # one right-hand side at a time: SuperLU's multi-RHS solve is far slower per column here
            diag = np.empty(self.n)
            e_k = np.zeros(self.n)
            for k in range(self.n):
                e_k[k] = 1.0
                diag[k] = self.lu.solve(e_k)[k]
                e_k[k] = 0.0
        assert diag is not None
        info["variance_seconds"] = time.perf_counter() - t0
        return diag, info


def selected_inverse_diag(A: sp.spmatrix) -> np.ndarray:
    """``diag(A^-1)`` of a sparse SPD matrix by the Takahashi recursion (see :class:`SparseSPDFactor`)."""
    return SparseSPDFactor(A).inverse_diagonal("takahashi")[0]


def diag_of_inverse(
    A: sp.spmatrix, method: str = "takahashi", n_samples: int = 200, seed: int | None = 0
) -> np.ndarray:
    """``diag(A^-1)`` of a sparse SPD matrix by one of :data:`VARIANCE_METHODS`."""
    return SparseSPDFactor(A).inverse_diagonal(method, n_samples, seed)[0]


# -- G-GMRF ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class GGMRFParams:
    """G-GMRF parameters (gdm's values for 0.1 m cells; sigmas in units of ``gas_scale``).

    Attributes:
        sigma_z: observation noise (0.1).
        sigma_r: smoothness between neighbouring free cells (1.128).
        sigma_b: weak prior towards 0 (80).
        gas_scale: ppm per normalized unit; None: the largest reading.
    """

    sigma_z: float = 0.1
    sigma_r: float = 1.128
    sigma_b: float = 80.0
    gas_scale: float | None = None

    def __post_init__(self) -> None:
        for name in ("sigma_z", "sigma_r", "sigma_b"):
            positive(name, getattr(self, name))
        if self.gas_scale is not None:
            positive("gas_scale", self.gas_scale)


def check_variance_method(method: str) -> None:
    """Refuse a variance method that is not one of :data:`VARIANCE_METHODS` (:class:`InputDataError`)."""
    if method not in VARIANCE_METHODS:
        raise InputDataError(f"unknown variance method {method!r}; one of {VARIANCE_METHODS}")


def gmrf_inputs(
    occupancy: np.ndarray,
    resolution: float,
    observations: Observations,
    variance: str,
    gas_scale: float | None,
) -> tuple[MappingInputs, float, FreeGraph, np.ndarray]:
    """What every GMRF map starts from, its arguments checked (the variance method first).

    Returns the checked inputs, the ppm per normalized gas unit
    (:meth:`MappingInputs.gas_scale` of ``gas_scale``), the free-cell graph and the
    graph node of each reading ``int (n,)``.
    """
    check_variance_method(variance)
    inp = check_inputs(occupancy, resolution, observations)
    scale = inp.gas_scale(gas_scale)
    graph = free_graph(inp.free)
    return inp, scale, graph, graph.index[inp.cells[:, 0], inp.cells[:, 1]]


def gmrf_info(
    method: str,
    variance_kind: str,
    gas_scale: float,
    params: dict[str, Any],
    details: dict[str, Any],
    seconds: tuple[float, float],
    variance_info: dict[str, Any],
) -> dict[str, Any]:
    """The ``info`` of a GMRF map: its method and variance, the ``gas_scale`` (ppm per unit)
    and ``params`` it used, the method's ``details``, the solve's seconds, the variance
    computation's ``variance_info``, and the seconds of the whole map.

    ``seconds``: the map's start (a :func:`time.perf_counter` reading) and the solve's seconds.
    """
    t0, t_solve = seconds
    return {
        "method": method,
        "variance_kind": variance_kind,
        "nll_comparable": True,
        "obstacle_aware": True,
        "gas_scale": gas_scale,
        "params": params,
        **details,
        "solve_seconds": t_solve,
        **variance_info,
        "map_seconds": time.perf_counter() - t0,
    }


def ggmrf(
    occupancy: np.ndarray,
    resolution: float,
    observations: Observations,
    params: GGMRFParams | None = None,
    variance: str = "takahashi",
    n_samples: int = 200,
) -> GasMap:
    """G-GMRF gas mean and marginal variance (ppm) on the free cells.

    Args:
        occupancy, resolution, observations: the map and its readings
            (:func:`dgse.mapping.check_inputs`; the parameters are per cell, used as given).
        params: :class:`GGMRFParams` (gdm defaults when None).
        variance: one of :data:`VARIANCE_METHODS`.
        n_samples: draws for ``variance="sampling"``.

    Raises:
        InputDataError: see :func:`dgse.mapping.check_inputs`, or a bad ``variance``.
    """
    t0 = time.perf_counter()
    p = params or GGMRFParams()
    inp, scale, graph, obs_nodes = gmrf_inputs(occupancy, resolution, observations, variance, p.gas_scale)
    H, b = gas_precision(graph, obs_nodes, inp.gas / scale, p.sigma_r**-2, p.sigma_z**-2, p.sigma_b**-2)
    fac = SparseSPDFactor(H)
    mean = fac.solve(b)
    t_solve = time.perf_counter() - t0
    var, vinfo = fac.inverse_diagonal(variance, n_samples)
    info = gmrf_info(
        "ggmrf",
        "marginal posterior variance diag(H^-1)",
        scale,
        {"sigma_z": p.sigma_z, "sigma_r": p.sigma_r, "sigma_b": p.sigma_b},
        {"n_free": graph.n, "n_edges": int(graph.edge_a.size)},
        (t0, t_solve),
        vinfo,
    )
    return GasMap(graph.scatter(mean * scale), graph.scatter(np.maximum(var, 0.0) * scale**2), info=info)


class GMRFEstimator(MappingEstimator):
    """The Estimator side shared by the GMRF methods (``name``, ``params_class`` and the map
    function ``solve`` set by each).

    Args:
        tuning: optional tuning file (or mapping) whose ``name`` entry overrides the defaults.
        variance: one of :data:`VARIANCE_METHODS`.
        n_samples: draws for ``variance="sampling"``.
        **params: fields of ``params_class``, overriding defaults and tuning.
    """

    params_class: type
    #: the method's map function, ``solve(occupancy, resolution, observations, params, variance, n_samples)``
    solve: Callable[..., GasMap]

    def __init__(
        self,
        tuning: str | os.PathLike[str] | Mapping[str, Any] | None = None,
        variance: str = "takahashi",
        n_samples: int = 200,
        **params: Any,
    ) -> None:
        check_variance_method(variance)
        self.params = resolve_params(self.params_class, self.name, tuning, params)
        self.variance = variance
        self.n_samples = int(n_samples)

    def map(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> GasMap:
        return self.solve(occupancy, resolution, observations, self.params, self.variance, self.n_samples)


class GGMRF(GMRFEstimator):
    """G-GMRF behind the Estimator protocol (registry name ``"ggmrf"``)."""

    name = "ggmrf"
    params_class = GGMRFParams
    solve = staticmethod(ggmrf)
