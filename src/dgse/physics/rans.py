"""Steady 2-D RANS (standard k-epsilon, standard wall functions) by SIMPLEC.

A collocated finite-volume solver on the layout's Cartesian grid that
follows OpenFOAM's ``simpleFoam`` (v1912) discretization of spec section 4:
Rhie-Chow face fluxes from the SIMPLEC ("consistent") pressure equation,
bounded linear-upwind convection with cell-limited Gauss gradients
(deferred correction), the explicit ``div(nuEff dev2(T(grad U)))`` stress,
``nutkWallFunction`` / ``epsilonWallFunction`` / ``kqRWallFunction`` at walls,
inlet turbulence from the intensity and mixing length, a fixed-pressure
outlet.  Transport equations are relaxed implicitly and solved by symmetric
Gauss-Seidel to a relative tolerance, as OpenFOAM's ``smoothSolver`` does;
the pressure equation by conjugate gradients preconditioned with an
algebraic multigrid hierarchy (PyAMG; OpenFOAM would use GAMG) or, on small
maps, with stale sparse-LU factors.  Large maps start from the solution on a
grid twice as coarse (grid sequencing), and any solve can start from a given
state, e.g. the flow of the same map at another inlet speed
(:func:`scale_state`).  Everything is a function of arrays; the entry point
is :func:`solve_flow`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from dgse.errors import ConvergenceError, InputDataError
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.fv import (
    AXIS,
    INLET,
    INTERNAL,
    OUTLET,
    SIGN,
    WALL,
    Mesh,
    StencilMatrix,
    anchors,
    assemble,
    bound,
    boundary_gamma,
    build_mesh,
    gauss_seidel,
    gradient,
    ho_source,
    neighbour_sum,
    pin_cells,
    relax,
    residual_norm,
    row_dot,
    row_sum,
)
from dgse.world.generate import ventilated_cells
from dgse.world.layout import Layout

_jit = numba.njit(cache=True, nogil=True)


@dataclass
class FlowSettings:
    """Iteration controls of :func:`solve_flow`."""

    max_iterations: int = 1000
    tolerance: float = 1e-4  #: on every normalised initial residual (OpenFOAM's residualControl)
    alpha_u: float = 0.9
    alpha_turb: float = 0.8
    alpha_p: float = 1.0
    high_order: bool = True
    consistent: bool = True
    rel_tol: float = 0.1  #: relative tolerance of the transport-equation solves
    p_rel_tol: float = 0.1  #: relative tolerance of the pressure solve
    max_sweeps: int = 50  #: Gauss-Seidel sweeps at most per transport solve
    max_krylov: int = 8  #: CG iterations on a stale pressure preconditioner before rebuilding it
    #: pressure preconditioner: ``auto`` (sparse LU up to ``lu_cells`` unknowns, AMG above), ``amg``, ``lu``
    pressure_solver: str = "auto"
    lu_cells: int = 12000
    max_seconds: float = math.inf  #: give up (not converged) after this wall time
    #: give up when the worst residual has not halved over this many iterations and, at its
    #: rate over them, would not reach the tolerance within ``max_iterations``
    stall_window: int = 200
    #: the pressure residual measures how much the Rhie-Chow fluxes still change between
    #: iterations; it can level off at a small value once the fields no longer move
    p_tolerance_factor: float = 10.0
    #: (alpha_u, alpha_turb) of a second attempt after a stalled or diverged first one
    retry_relaxation: tuple[float, float] | None = (0.7, 0.7)
    #: maps with more free cells than this start from their solution on a grid twice as
    #: coarse (recursively); 0 never does
    coarse_cells: int = 30000
    #: residual tolerance of that coarse solution (it only has to be a good start)
    coarse_tolerance: float = 1e-3
    #: switched evolution relaxation (SER) of the turbulence, bounded by ``alpha_turb_max`` on
    #: maps with more free cells than this and by ``alpha_turb_max_small`` on the others (0: no
    #: SER on any map): the pseudo-time step ``alpha / (1 - alpha)`` of the k and epsilon
    #: equations grows as ``r0 / r`` (``r``: the worst residual of the last five iterations,
    #: ``r0``: of the first five) from that of ``alpha_turb`` up to that of ``alpha_turb_max``;
    #: a rising residual takes it back.  Large rooms converge slowly otherwise: the turbulence
    #: of their big eddies moves by a small pseudo-time step per iteration.  The converged
    #: solution does not depend on it (the momentum relaxation would: it enters the Rhie-Chow
    #: fluxes)
    ser_cells: int = 12000
    alpha_turb_max: float = 0.99
    #: the SER bound on maps of at most ``ser_cells`` free cells (``alpha_turb`` or less: no
    #: SER there).  Paper-size maps converge in fewer iterations with it, but ``alpha_turb_max``
    #: makes some of them stall (``docs/decisions.md``)
    alpha_turb_max_small: float = 0.9
    #: Gauss-Seidel sweeps at most per k and epsilon solve under SER: with the pseudo-time
    #: step near that of ``alpha_turb_max`` those equations lose their diagonal dominance
    #: and a solve to ``rel_tol`` takes ~50 sweeps (most of an iteration's time on large
    #: maps) for a change the next iteration undoes.  Capped solves can hold the k residual
    #: just above the tolerance: a stall under the cap lifts it (the iteration goes on from
    #: where it is, its stall test on half the window) before the relaxation retry
    ser_max_sweeps: int = 10
    #: Gauss-Seidel's short-chain arithmetic (``short_chain`` of
    #: :func:`~dgse.physics.fv.gauss_seidel`): faster sweeps, the same solution up to
    #: rounding.  False: the plain division in the sweeps' natural order
    short_chain: bool = True
    #: a run from rest that still stalls or diverges after the relaxation retry is tried
    #: once more from the solution on a grid twice as coarse (as large maps start): the
    #: cold iteration can fall into a limit cycle next to a steady state that another path
    #: reaches
    coarse_retry: bool = True

    def __post_init__(self) -> None:
        for name in ("alpha_u", "alpha_turb", "alpha_turb_max", "alpha_turb_max_small"):
            a = getattr(self, name)
            if not (0.0 <= a <= 1.0) or (a == 1.0 and name != "alpha_u"):
                raise InputDataError(f"FlowSettings.{name} must lie in [0, 1) (alpha_u: [0, 1]), got {a!r}")


@dataclass
class FlowState:
    """Per-cell fields ``(n,)`` and outward face fluxes ``F (n, 4)`` of the iteration."""

    ux: np.ndarray
    uy: np.ndarray
    p: np.ndarray
    k: np.ndarray
    eps: np.ndarray
    nut: np.ndarray
    F: np.ndarray

    def copy(self) -> FlowState:
        return FlowState(*(np.array(getattr(self, f)) for f in ("ux", "uy", "p", "k", "eps", "nut", "F")))


def scale_state(state: FlowState, factor: float) -> FlowState:
    """The state of the same map at ``factor`` times the inlet speed, by high-Reynolds similarity.

    Velocities and fluxes scale with the speed, kinematic pressure and ``k``
    with its square, ``epsilon`` with its cube, ``nu_t`` with the speed: the
    exact solution where the molecular viscosity does not matter, and a start
    a few iterations from the solution otherwise.
    """
    f = float(factor)
    return FlowState(
        ux=state.ux * f, uy=state.uy * f, p=state.p * f**2, k=state.k * f**2,
        eps=state.eps * f**3, nut=state.nut * f, F=state.F * f,
    )  # fmt: skip


def face_fluxes(mesh: Mesh, ux: np.ndarray, uy: np.ndarray, inlet_velocity: float) -> np.ndarray:
    """Outward face fluxes ``(n, 4)`` (m^2/s per m of depth) interpolated from cell velocities (m/s).

    Internal faces take the mean of their two cells, outlets the cell's
    velocity, inlets ``-inlet_velocity * h``, walls 0.  Not conservative: a
    start for :func:`solve_flow`, whose first pressure solve makes it so.
    """
    u = np.stack([ux, uy], axis=1)[:, AXIS]  # (n, 4): the velocity component normal to each face
    internal = mesh.ft == INTERNAL
    u_nb = u[np.where(internal, mesh.nb, 0), np.arange(4)]
    F = np.where(internal, 0.5 * (u + u_nb), 0.0)
    F = np.where(mesh.ft == OUTLET, u, F) * SIGN * mesh.h
    return np.where(mesh.ft == INLET, -inlet_velocity * mesh.h, F)


def coarsen_layout(layout: Layout) -> Layout | None:
    """``layout`` on a grid twice as coarse, or ``None`` where that loses an opening's way out.

    A coarse cell is solid when any of its (up to four) fine cells is: walls
    never leak, a gap one fine cell wide closes.  Free regions that touch no
    opening become solid; a region with inlets but no outlet gives ``None``.
    Odd sides repeat their last row or column.
    """
    occ = layout.occupancy
    H, W = occ.shape
    if min(H, W) < 8:
        return None
    pad = np.pad(occ, ((0, H % 2), (0, W % 2)), mode="edge")
    coarse = pad.reshape(pad.shape[0] // 2, 2, pad.shape[1] // 2, 2).max(axis=(1, 3))
    try:
        lay = Layout(coarse, layout.inlets, layout.outlets, 2 * layout.resolution, name=layout.name)
        from scipy import ndimage as ndi  # imported here: only large maps need it

        labels, _ = ndi.label(lay.free)
        with_in = set(np.unique(labels[lay.opening_mask("inlet")])) - {0}
        with_out = set(np.unique(labels[lay.opening_mask("outlet")])) - {0}
        if with_in - with_out:
            return None
        keep = np.isin(labels, sorted(with_in | with_out))
        return Layout(
            (~keep).astype(np.uint8), layout.inlets, layout.outlets, lay.resolution, name=layout.name
        )
    except InputDataError:  # an opening lost all its free cells
        return None


def prolong_state(coarse: Mesh, state: FlowState, fine: Mesh, inlet_velocity: float) -> FlowState:
    """A state on ``fine`` from one on ``coarse`` (cells twice the size), fluxes by :func:`face_fluxes`.

    Bilinear interpolation between the free coarse cells around each fine
    cell centre (weights 3/4 and 1/4 per axis, renormalised over the free
    ones); a fine cell with no free coarse cell around (a gap the coarse grid
    closed) takes the nearest one's pressure and turbulence, at rest.
    Piecewise-constant injection would leave velocity jumps between blocks of
    2 x 2 cells, whose spurious shear makes k-epsilon blow up.
    """
    Hc, Wc = coarse.shape
    i, j = fine.cells[:, 0], fine.cells[:, 1]
    ci, cj = i // 2, j // 2
    oi, oj = np.where(i % 2 == 0, -1, 1), np.where(j % 2 == 0, -1, 1)  # the second-nearest coarse row/column
    fields = np.stack([state.ux, state.uy, state.p, state.k, state.eps, state.nut])
    acc = np.zeros((fields.shape[0], fine.n))
    wsum = np.zeros(fine.n)
    for di, dj, w in ((0, 0, 9 / 16), (1, 0, 3 / 16), (0, 1, 3 / 16), (1, 1, 1 / 16)):
        ri, rj = ci + di * oi, cj + dj * oj
        inside = (ri >= 0) & (ri < Hc) & (rj >= 0) & (rj < Wc)
        idx = np.where(inside, coarse.index[np.clip(ri, 0, Hc - 1), np.clip(rj, 0, Wc - 1)], -1)
        ok = idx >= 0
        acc[:, ok] += w * fields[:, idx[ok]]
        wsum[ok] += w
    none = wsum == 0
    if none.any():
        from scipy import ndimage as ndi

        _, (ni, nj) = ndi.distance_transform_edt(~coarse.free, return_indices=True)
        near = coarse.index[ni[ci[none], cj[none]], nj[ci[none], cj[none]]]
        acc[:, none] = fields[:, near]
        # the nearest coarse cell can lie beyond a wall (a gap the coarse grid closed, between
        # furniture and a wall): its velocity says nothing of the gap's, which starts at rest
        acc[:2, none] = 0.0
        wsum[none] = 1.0
    ux, uy, p, k, eps, nut = acc / wsum
    return FlowState(ux=ux, uy=uy, p=p, k=k, eps=eps, nut=nut, F=face_fluxes(fine, ux, uy, inlet_velocity))


class GalerkinMap:
    """The coarse operator ``R A P`` as a linear map of ``A``'s values, for a fixed pattern.

    ``R A P`` is linear in the entries of ``A``: with ``A``'s sparsity pattern
    fixed (the stencil of a mesh), the coarse matrix's values are ``M a``, ``a``
    the fine values in CSR order and ``M`` a sparse matrix built once from
    ``R`` and ``P`` (one row per coarse entry, one column per fine entry).
    Applying it is one sparse product; forming ``R A P`` by two sparse
    matrix-matrix products each time costs several times more (and re-derives
    the same pattern).  Entries that cancel exactly stay as explicit zeros.

    Args:
        pattern (scipy.sparse.csr_matrix): a CSR matrix whose ``indptr``/``indices`` are ``A``'s pattern.
        R, P (scipy.sparse.spmatrix): restriction ``(nc, n)`` and interpolation ``(n, nc)``.
    """

    def __init__(self, pattern, R, P) -> None:
        A = pattern.tocsr()
        RT = R.T.tocsr()
        P = P.tocsr()
        nc = P.shape[1]
        rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        cols = A.indices
        n_i = np.diff(RT.indptr)[rows]  # coarse rows each fine entry restricts to
        n_j = np.diff(P.indptr)[cols]  # coarse columns it interpolates from
        count = n_i * n_j
        e = np.repeat(np.arange(A.nnz), count)
        t = np.arange(e.size) - np.repeat(np.cumsum(count) - count, count)
        ri = RT.indptr[rows[e]] + t // n_j[e]
        pj = P.indptr[cols[e]] + t % n_j[e]
        key = RT.indices[ri].astype(np.int64) * nc + P.indices[pj]
        uniq, pos = np.unique(key, return_inverse=True)
        self._M = sp.csr_matrix((RT.data[ri] * P.data[pj], (pos, e)), shape=(uniq.size, A.nnz))
        self._indices = (uniq % nc).astype(np.int32)
        per_row = np.bincount(uniq // nc, minlength=nc)
        self._indptr = np.concatenate([[0], np.cumsum(per_row)]).astype(np.int32)
        self.shape = (nc, nc)

    def pattern(self) -> sp.csr_matrix:
        """An all-ones matrix with the coarse pattern (to build the next level's map on)."""
        return sp.csr_matrix((np.ones(self._indices.size), self._indices, self._indptr), shape=self.shape)

    def apply(self, data: np.ndarray) -> sp.csr_matrix:
        """``R A P`` for the fine values ``data`` (CSR order of the pattern)."""
        return sp.csr_matrix((self._M @ data, self._indices, self._indptr), shape=self.shape)


class PressureSolver:
    """Preconditioned CG on the pressure equation, reusing its preconditioner across iterations.

    ``amg``: a classical (Ruge-Stuben) algebraic multigrid V-cycle, linear in
    the cells.  Its coarsening and interpolation are built once; every solve
    recomputes only the Galerkin coarse operators ``R A P`` of the current
    matrix (about a fifth of a full set-up), so the V-cycle stays exact for
    the matrix that changes with the flow.  ``lu``: sparse-LU factors
    (SuperLU) of an earlier matrix, refactorized only when CG needs more than
    ``max_krylov`` iterations; fastest on small maps, superlinear in the
    cells.  ``auto``: ``lu`` up to ``lu_cells`` unknowns, ``amg`` above.  A
    stale AMG hierarchy is rebuilt the same way.

    Args:
        max_krylov: CG iterations allowed before the preconditioner is rebuilt.
        method: ``"auto"``, ``"amg"`` or ``"lu"``.
        lu_cells: the size up to which ``auto`` factorizes.
    """

    def __init__(self, max_krylov: int, method: str = "auto", lu_cells: int = 12000) -> None:
        if method not in ("auto", "amg", "lu"):
            raise ValueError(f"unknown pressure solver {method!r}: use auto, amg or lu")
        self.max_krylov = max_krylov
        self.method = method
        self.lu_cells = lu_cells
        self._M = None
        self._ml = None
        self._maps: list[GalerkinMap] | None = None
        self.factorizations = 0  #: preconditioners built from scratch (LU factorizations or AMG set-ups)
        self.krylov_iterations = 0

    def _uses_amg(self, n: int) -> bool:
        return self.method == "amg" or (self.method == "auto" and n > self.lu_cells)

    def _preconditioner(self, A, rebuild: bool):
        if not self._uses_amg(A.shape[0]):
            if self._M is None or rebuild:
                # symmetric positive definite: minimum degree on A^T + A, no pivoting
                opts = {"SymmetricMode": True}
                try:
                    lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=opts)
                except RuntimeError as e:  # SuperLU's "Factor is exactly singular"
                    # (not from a closed region: those are held, see _pinned)
                    raise ConvergenceError(f"the pressure equation cannot be factorized ({e})") from None
                self._M = lu.solve
                self.factorizations += 1
            return self._M
        import pyamg  # imported here: small maps never need it

        if self._ml is None or rebuild:
            self._ml = pyamg.ruge_stuben_solver(A, max_coarse=400, coarse_solver="splu")
            self.factorizations += 1
            self._maps = None
        else:  # same coarsening and interpolation, coarse operators of the current matrix
            levels = self._ml.levels
            if self._maps is None:
                self._maps, pattern = [], A
                for fine in levels[:-1]:
                    self._maps.append(GalerkinMap(pattern, fine.R, fine.P))
                    pattern = self._maps[-1].pattern()
            levels[0].A = A
            for g, fine, coarse in zip(self._maps, levels[:-1], levels[1:], strict=True):
                coarse.A = g.apply(fine.A.data)
            self._ml.coarse_solver = pyamg.multilevel.coarse_grid_solver("splu")
        return self._ml.aspreconditioner(cycle="V").matvec

    def solve(self, A, b: np.ndarray, x0: np.ndarray, rel_tol: float) -> np.ndarray:
        """``x`` with ``|b - A x| <= rel_tol |b - A x0|`` (2-norm), starting from ``x0``."""
        A = A.tocsr()
        res0 = b - A @ x0
        r0 = float(np.linalg.norm(res0))
        if r0 == 0.0:
            return x0.copy()
        for attempt in range(2):
            psolve = self._preconditioner(A, rebuild=attempt == 1)
            with np.errstate(all="ignore"):
                x, converged, its = _pcg(A, b, x0, rel_tol * r0, self.max_krylov, psolve, res0.copy())
            self.krylov_iterations += its
            if converged and np.isfinite(x).all():
                return x
        return spla.spsolve(A.tocsc(), b)


def _pcg(
    A: sp.csr_matrix,
    b: np.ndarray,
    x0: np.ndarray,
    atol: float,
    maxiter: int,
    psolve: Callable,
    r0: np.ndarray | None = None,
) -> tuple[np.ndarray, bool, int]:
    """Preconditioned conjugate gradients: ``(x, converged, iterations)``, converged when
    ``|b - A x| < atol`` within ``maxiter`` iterations.  ``r0``: the residual ``b - A x0``
    when the caller has it (it is overwritten), else computed here.

    The iteration of SciPy's ``cg`` (the same operations in the same order, so the same
    iterates bit for bit) without its per-call and per-iteration wrapping, which cost a third
    of the pressure solve on paper-size maps.
    """
    x = np.array(x0, dtype=float)
    if not np.linalg.norm(b):
        return np.array(b, dtype=float), True, 0
    if r0 is not None:
        r = r0
    else:
        r = b - A @ x if x.any() else b.copy()
    rho_prev, p = 1.0, None
    for it in range(maxiter):
        if np.linalg.norm(r) < atol:
            return x, True, it
        z = psolve(r)
        rho = np.dot(r, z)
        if p is None:
            p = z.copy()
        else:
            p *= rho / rho_prev
            p += z
        q = A @ p
        alpha = rho / np.dot(p, q)
        x += alpha * p
        r -= alpha * q
        rho_prev = rho
    return x, False, maxiter


@_jit
def stress_source(nueff, gx, gy, nb, ft, h):
    """``div(nuEff dev2(T(grad U)))`` per cell (integrated), components ``(n, 2)``.

    ``gx``/``gy`` are the cell gradients ``(n, 2)`` of ``u_x``/``u_y``; face values
    are linear interpolations (the cell's own value on boundary faces).
    """
    n = nueff.shape[0]
    out = np.zeros((n, 2))
    for c in range(n):
        divc = gx[c, 0] + gy[c, 1]
        for d in range(4):
            t = ft[c, d]
            if t == 0:
                continue
            sg = 1.0 if (d == 0 or d == 2) else -1.0
            if t == 1:
                o = nb[c, d]
                nu_f = 0.5 * (nueff[c] + nueff[o])
                divo = gx[o, 0] + gy[o, 1]
                if d < 2:
                    tx = 0.5 * (gx[c, 0] + gx[o, 0]) - (1.0 / 3.0) * (divc + divo)
                    ty = 0.5 * (gx[c, 1] + gx[o, 1])
                else:
                    tx = 0.5 * (gy[c, 0] + gy[o, 0])
                    ty = 0.5 * (gy[c, 1] + gy[o, 1]) - (1.0 / 3.0) * (divc + divo)
            else:
                nu_f = nueff[c]
                if d < 2:
                    tx = gx[c, 0] - (2.0 / 3.0) * divc
                    ty = gx[c, 1]
                else:
                    tx = gy[c, 0]
                    ty = gy[c, 1] - (2.0 / 3.0) * divc
            out[c, 0] += sg * nu_f * tx * h
            out[c, 1] += sg * nu_f * ty * h
    return out


@_jit
def pressure_system(hbyax, hbyay, rAU, rAtU, p, ubx, uby, nb, ft, h, consistent):
    """Rhie-Chow fluxes ``phiHbyA (n, 4)`` and the pressure Laplacian ``(lapP, lapA)``.

    Fixed-velocity faces (inlets, walls) carry the boundary velocity
    ``(ubx, uby)``; outlets the cell's ``HbyA`` with ``p = 0`` half a cell away.
    """
    n = p.shape[0]
    phb = np.zeros((n, 4))
    lapP = np.zeros(n)
    lapA = np.zeros((n, 4))
    for c in range(n):
        diff_c = rAtU[c] - rAU[c]
        for d in range(4):
            t = ft[c, d]
            if t == 0:
                continue
            sg = 1.0 if (d == 0 or d == 2) else -1.0
            hb_c = hbyax[c] if d < 2 else hbyay[c]
            if t == 1:
                o = nb[c, d]
                hb_o = hbyax[o] if d < 2 else hbyay[o]
                flux = sg * 0.5 * (hb_c + hb_o) * h
                if consistent:
                    flux += 0.5 * (diff_c + rAtU[o] - rAU[o]) * (p[o] - p[c])
                coef = 0.5 * (rAtU[c] + rAtU[o])
                lapA[c, d] = coef
                lapP[c] += coef
            elif t == 4:
                flux = sg * hb_c * h
                if consistent:
                    flux += diff_c * 2.0 * (0.0 - p[c])
                lapP[c] += 2.0 * rAtU[c]
            else:
                ub = ubx[c, d] if d < 2 else uby[c, d]
                flux = sg * ub * h
            phb[c, d] = flux
    return phb, lapP, lapA


@_jit
def corrected_flux(phb, lapA, rAtU, p, nb, ft):
    """Face fluxes ``phiHbyA - rAtU snGrad(p) |S|`` after the pressure solve."""
    n = p.shape[0]
    F = phb.copy()
    for c in range(n):
        for d in range(4):
            t = ft[c, d]
            if t == 1:
                F[c, d] -= lapA[c, d] * (p[nb[c, d]] - p[c])
            elif t == 4:
                F[c, d] -= 2.0 * rAtU[c] * (0.0 - p[c])
    return F


@_jit
def turbulence_production(gux, gy, nut, yplus, nutw, ux, uy, k, wall_cell, nu, cmu25, cmu75, kappa, y, ypl):
    """``(G, epsilon_wall)`` per cell: the production of k, and epsilon in wall cells.

    ``G = nu_t (2 dux/dx^2 + 2 duy/dy^2 + (dux/dy + duy/dx)^2 - 2/3 div(u)^2)`` away from
    walls; in wall cells the standard wall functions: ``G = (nu_t,w + nu) |u| / y *
    C_mu^0.25 sqrt(k) / (kappa y)`` in the log region (``y+ > y+_lam``), 0 in the
    laminar one, and ``epsilon = C_mu^0.75 k^1.5 / (kappa y)`` (log) or ``2 k nu / y^2``
    (0 elsewhere).
    """
    n = k.shape[0]
    G = np.empty(n)
    eps_w = np.zeros(n)  # only wall cells use it
    for c in range(n):
        if wall_cell[c]:
            if yplus[c] > ypl:  # log region
                eps_w[c] = cmu75 * k[c] * math.sqrt(k[c]) / (kappa * y)
                umag = math.hypot(ux[c], uy[c])
                G[c] = (nutw[c] + nu) * (umag / y) * cmu25 * math.sqrt(k[c]) / (kappa * y)
            else:
                eps_w[c] = 2.0 * k[c] * nu / y**2
                G[c] = 0.0
        else:
            div = gux[c, 0] + gy[c, 1]
            shear = gux[c, 1] + gy[c, 0]
            G[c] = nut[c] * (2.0 * gux[c, 0] ** 2 + 2.0 * gy[c, 1] ** 2 + shear**2 - (2.0 / 3.0) * div**2)
    return G, eps_w


class KEpsilon:
    """The standard k-epsilon model with standard wall functions on one mesh (one step of it).

    :meth:`step` updates ``k``, ``epsilon`` and ``nu_t`` of a :class:`FlowState`
    for its current velocity and face fluxes: the epsilon then the k
    equation, relaxed and solved by Gauss-Seidel as in :func:`_simplec`,
    ``inletOutlet`` at outlets, wall functions in wall cells, and the
    realizability guard on the length scale.  SIMPLEC calls it once per
    iteration; :func:`solve_turbulence` iterates it on a frozen flow.

    Args:
        mesh: the free cells and face types.
        physics: model constants.
        ubx, uby: ``(n, 4)`` velocity components at the faces where the velocity is fixed (inlets).
        k_in, eps_in: inlet turbulence.
    """

    def __init__(
        self, mesh: Mesh, physics: Physics, ubx: np.ndarray, uby: np.ndarray, k_in: float, eps_in: float
    ) -> None:
        self.mesh = mesh
        self.physics = physics
        ft = mesh.ft
        self.wall = ft == WALL
        self.inlet = ft == INLET
        self.outlet = ft == OUTLET
        self.wall_cell = self.wall.any(axis=1)
        self.fixed_u = self.wall | self.inlet
        self.ubx, self.uby = ubx, uby
        self.k_in, self.eps_in = float(k_in), float(eps_in)
        self.nut_in = physics.C_mu * self.k_in**2 / self.eps_in
        self.max_length = max(mesh.shape) * mesh.h
        self.k_b = np.full((mesh.n, 4), self.k_in)  # face values where k is fixed (inlets)
        self.eps_b = np.full((mesh.n, 4), self.eps_in)
        self.no_face = np.zeros((mesh.n, 4), dtype=bool)

    def velocity_gradients(self, st: FlowState) -> tuple[np.ndarray, np.ndarray]:
        """The cell gradients ``(n, 2)`` of ``st.ux`` and ``st.uy`` (fixed values at walls and inlets)."""
        mesh = self.mesh
        gux = gradient(st.ux, self.ubx, self.fixed_u, mesh.nb, mesh.ft, mesh.h, False)
        guy = gradient(st.uy, self.uby, self.fixed_u, mesh.nb, mesh.ft, mesh.h, False)
        return gux, guy

    def wall_functions(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(y+, nu_t at walls)`` of the cells for turbulent kinetic energy ``k``."""
        ph = self.physics
        nu, y = ph.nu, 0.5 * self.mesh.h
        yplus = ph.C_mu**0.25 * y * np.sqrt(k) / nu
        ypl = ph.y_plus_lam
        log_law = nu * (yplus * ph.kappa / np.log(ph.E * np.maximum(yplus, ypl)) - 1.0)
        nutw = np.where(yplus > ypl, log_law, 0.0)
        return yplus, nutw

    def step(
        self,
        st: FlowState,
        s: FlowSettings,
        yplus: np.ndarray,
        nutw: np.ndarray,
        residuals: dict[str, float],
        sweeps: dict[str, int],
        velocity_gradients: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> int:
        """One update of ``st.k``, ``st.eps``, ``st.nut``; returns the cells whose length scale was capped.

        ``velocity_gradients``: the cell gradients ``(gux, guy)`` of ``st.ux`` and ``st.uy``
        (:meth:`velocity_gradients`) when the caller has them, else computed here.
        """
        mesh, physics = self.mesh, self.physics
        nb, ft, h = mesh.nb, mesh.ft, mesh.h
        V = h * h
        nu, Cmu = physics.nu, physics.C_mu
        Cmu25, Cmu75 = Cmu**0.25, Cmu**0.75
        kappa, y = physics.kappa, 0.5 * h
        inlet, outlet, wall_cell = self.inlet, self.outlet, self.wall_cell
        k_in, eps_in, nut_in = self.k_in, self.eps_in, self.nut_in
        F = st.F
        gux, guy = velocity_gradients or self.velocity_gradients(st)
        k_old, eps_old = st.k, st.eps
        G, eps_wall = turbulence_production(
            gux, guy, st.nut, yplus, nutw, st.ux, st.uy, k_old, wall_cell,
            nu, Cmu25, Cmu75, kappa, y, physics.y_plus_lam,
        )  # fmt: skip
        fixed_t = inlet | (outlet & (F < 0))  # inletOutlet at outlets

        deff = nu + st.nut / physics.sigma_eps
        gam_b = boundary_gamma(deff, inlet, nu + nut_in / physics.sigma_eps, self.no_face, deff)
        aP, a, cb = assemble(F, deff, fixed_t, gam_b, nb, ft, True)
        b = row_sum(cb) * eps_in + physics.C_1 * G * eps_old / k_old * V
        aP = aP + physics.C_2 * eps_old / k_old * V
        if s.high_order:
            b += ho_source(st.eps, gradient(st.eps, self.eps_b, fixed_t, nb, ft, h, True), F, nb, ft, h)
        aP, b = relax(aP, a, b, st.eps, s.alpha_turb)
        # wall cells take the wall-function value (OpenFOAM's setValues)
        pin_cells(wall_cell, aP, a, b, eps_wall)
        eps_new = st.eps.copy()[:, None]
        n_sw, res = gauss_seidel(aP, a, b[:, None], nb, eps_new, s.rel_tol, s.max_sweeps, s.short_chain)
        sweeps["epsilon"] += n_sw
        residuals["epsilon"] = float(res[0])
        eps_new = eps_new[:, 0]
        eps_new = bound(eps_new, nb, ft, 1e-15)

        dk = nu + st.nut / physics.sigma_k
        gam_b = boundary_gamma(dk, inlet, nu + nut_in / physics.sigma_k, self.no_face, dk)
        aP, a, cb = assemble(F, dk, fixed_t, gam_b, nb, ft, True)
        b = row_sum(cb) * k_in + G * V
        aP = aP + eps_new / k_old * V
        if s.high_order:
            b += ho_source(st.k, gradient(st.k, self.k_b, fixed_t, nb, ft, h, True), F, nb, ft, h)
        aP, b = relax(aP, a, b, st.k, s.alpha_turb)
        k_new = st.k.copy()[:, None]
        n_sw, res = gauss_seidel(aP, a, b[:, None], nb, k_new, s.rel_tol, s.max_sweeps, s.short_chain)
        sweeps["k"] += n_sw
        residuals["k"] = float(res[0])
        k_new = k_new[:, 0]
        st.k = bound(k_new, nb, ft, 1e-15)
        # realizability guard: the length scale Cmu^0.75 k^1.5 / eps cannot exceed the
        # domain; without it a transient dip of epsilon gives an unbounded nu_t
        eps_floor = Cmu75 * st.k**1.5 / self.max_length
        limited = eps_new < eps_floor
        st.eps = np.where(limited, eps_floor, eps_new)
        st.nut = Cmu * st.k**2 / st.eps
        return int(limited.sum())


def solve_turbulence(
    mesh: Mesh,
    ux: np.ndarray,
    uy: np.ndarray,
    F: np.ndarray,
    physics: Physics = DEFAULT_PHYSICS,
    settings: FlowSettings | None = None,
    inlet_width_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """k-epsilon on a frozen flow: ``(k, epsilon, nu_t, info)`` per cell for the given velocity and fluxes.

    The turbulence closure of a mean wind known from elsewhere (a user's CFD):
    the same model, wall functions and iteration as :func:`solve_flow`, with
    the velocity and the face fluxes ``F (n, 4)`` held fixed.  Inlet faces are
    the faces of type ``INLET`` (their velocity is ``-F / h`` along the normal);
    the inlet turbulence comes from the mean inflow speed and ``inlet_width_m``
    (default: the total width of the inlet faces), as for a solved layout.
    """
    s = settings or FlowSettings()
    t0 = time.perf_counter()
    h, n = mesh.h, mesh.n
    inlet = mesh.ft == INLET
    vel = -np.where(inlet, F, 0.0) / h  # inflow speed through each inlet face (> 0 for inflow)
    ubx = np.where(inlet & (AXIS == 0), -SIGN * vel, 0.0)
    uby = np.where(inlet & (AXIS == 1), -SIGN * vel, 0.0)
    n_in = int(inlet.sum())
    v_in = float(np.maximum(vel[inlet], 0.0).mean()) if n_in else float(np.hypot(ux, uy).mean())
    v_in = max(v_in, 1e-3)
    width = inlet_width_m if inlet_width_m is not None else max(n_in, 1) * h
    k_in, eps_in = physics.inlet_turbulence(v_in, width)
    turb = KEpsilon(mesh, physics, ubx, uby, k_in, eps_in)
    st = FlowState(
        ux=np.asarray(ux, float), uy=np.asarray(uy, float), p=np.zeros(n),
        k=np.full(n, k_in), eps=np.full(n, eps_in), nut=np.full(n, turb.nut_in), F=np.asarray(F, float),
    )  # fmt: skip
    residuals: dict[str, float] = {}
    sweeps = {"k": 0, "epsilon": 0}
    converged = False
    grad_u = turb.velocity_gradients(st)  # the flow is frozen
    it = 0
    while it < s.max_iterations:
        it += 1
        yplus, nutw = turb.wall_functions(st.k)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # tested just below
            turb.step(st, s, yplus, nutw, residuals, sweeps, grad_u)
        if not (np.isfinite(st.k).all() and np.isfinite(st.eps).all()):
            break
        if all(v < s.tolerance for v in residuals.values()):
            converged = True
            break
        if time.perf_counter() - t0 > s.max_seconds:
            break
    info = {
        "iterations": it,
        "converged": converged,
        "residuals": dict(residuals),
        "seconds": time.perf_counter() - t0,
        "inlet_speed": v_in,
    }
    return st.k, st.eps, st.nut, info


def solve_flow(
    layout: Layout,
    mesh: Mesh,
    inlet_velocity: float,
    physics: Physics = DEFAULT_PHYSICS,
    settings: FlowSettings | None = None,
    progress: Callable[[int, dict], None] | None = None,
    initial: FlowState | None = None,
) -> tuple[FlowState, dict]:
    """Solve the steady RANS flow; returns the final state and an info dict.

    The iteration starts from ``initial`` when given (a warm start: e.g. the
    solution of the same map at another inlet speed, scaled by
    :func:`scale_state`), else on a map with more than
    ``settings.coarse_cells`` free cells from the solution on a grid twice as
    coarse (:func:`coarsen_layout`, solved the same way to
    ``settings.coarse_tolerance``), else from rest.  The start changes the
    path, not the converged solution.  A run that stalls or diverges is tried
    again with the stronger under-relaxation ``settings.retry_relaxation`` from
    the same start (as one would by hand in OpenFOAM); one from rest that still
    does, once more from the coarse grid's solution (``settings.coarse_retry``).  ``info`` holds
    ``iterations`` (all attempts on this grid), ``converged``, ``stalled``,
    ``diverged``, the last normalised initial residuals per equation,
    ``seconds`` (coarse solves included), the residual ``history``, one summary
    per attempt, ``start`` (``"initial"``, ``"coarse"`` or ``"rest"``) and, after a
    coarse start, ``coarse``: the coarse solve's info (without its history).
    """
    s = settings or FlowSettings()
    ventilated_cells(layout)  # raises on an inlet whose air cannot leave
    t0 = time.perf_counter()
    start = "rest" if initial is None else "initial"
    coarse_info = None
    if initial is None and 0 < s.coarse_cells < mesh.n:
        initial, coarse_info = _coarse_start(layout, mesh, inlet_velocity, physics, s)
        if initial is not None:
            start = "coarse"
    s_fine = replace(s, max_seconds=s.max_seconds - (time.perf_counter() - t0))
    st, info = _simplec(layout, mesh, inlet_velocity, physics, s_fine, progress, initial)
    attempts = [_summary(info, s, start)]
    if (info["stalled"] or info["diverged"]) and s.retry_relaxation is not None:
        a_u, a_t = s.retry_relaxation
        left = s.max_seconds - (time.perf_counter() - t0)
        s2 = replace(s, alpha_u=a_u, alpha_turb=a_t, max_seconds=left, ser_cells=0)
        st, info = _simplec(layout, mesh, inlet_velocity, physics, s2, progress, initial)
        attempts.append(_summary(info, s2, start))
    if (info["stalled"] or info["diverged"]) and s.coarse_retry and start == "rest" and coarse_info is None:
        # another path to the same steady state: from the coarse grid's solution
        initial_c, coarse_info = _coarse_start(layout, mesh, inlet_velocity, physics, s)
        if initial_c is not None:
            left = s.max_seconds - (time.perf_counter() - t0)
            s_c = replace(s, max_seconds=left)
            st_c, info_c = _simplec(layout, mesh, inlet_velocity, physics, s_c, progress, initial_c)
            attempts.append(_summary(info_c, s_c, "coarse"))
            if not (info_c["stalled"] or info_c["diverged"]):
                st, info, start = st_c, info_c, "coarse"
    info["attempts"] = attempts
    info["iterations"] = sum(a["iterations"] for a in attempts)
    info["start"] = start
    if coarse_info is not None:
        info["coarse"] = coarse_info
    info["inlet_velocity"] = float(inlet_velocity)
    info["seconds"] = time.perf_counter() - t0
    return st, info


def _coarse_start(
    layout: Layout, mesh: Mesh, inlet_velocity: float, physics: Physics, s: FlowSettings
) -> tuple[FlowState | None, dict | None]:
    """The flow on a grid twice as coarse (solved by :func:`solve_flow` to ``coarse_tolerance``),
    prolonged to ``layout``'s grid, and that solve's info; ``(None, info)`` where it did not
    settle, ``(None, None)`` where the map cannot be coarsened."""
    coarse_layout = coarsen_layout(layout)
    if coarse_layout is None:
        return None, None
    cmesh = build_mesh(coarse_layout)
    cs = replace(s, tolerance=max(s.tolerance, s.coarse_tolerance))
    cst, coarse_info = solve_flow(coarse_layout, cmesh, inlet_velocity, physics, cs)
    coarse_info.pop("history", None)
    settled = coarse_info["converged"] or _worst(coarse_info["residuals"], s) < 10 * cs.tolerance
    if not (settled and np.isfinite(cst.ux).all()):
        return None, coarse_info
    return prolong_state(cmesh, cst, mesh, inlet_velocity), coarse_info


def _pinned(
    lapP: np.ndarray, lapA: np.ndarray, pin: np.ndarray, nb: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The pressure Laplacian ``(lapP, lapA)`` with the unknowns of ``pin`` held at 0: their rows
    and columns out (the matrix stays symmetric), a positive diagonal on their rows."""
    lapA = lapA.copy()
    lapA[pin] = 0.0
    lapA[(nb >= 0) & pin[np.maximum(nb, 0)]] = 0.0
    diag = np.where(pin & (lapP <= 0.0), 1.0, lapP)
    return diag, lapA


def _converged(residuals: dict[str, float], s: FlowSettings) -> bool:
    """Every residual under the tolerance; the pressure one under ``p_tolerance_factor`` times it."""
    p_ok = residuals["p"] < s.tolerance * s.p_tolerance_factor
    return p_ok and all(v < s.tolerance for k, v in residuals.items() if k != "p")


def _summary(info: dict, s: FlowSettings, start: str) -> dict:
    keys = ("iterations", "converged", "stalled", "diverged", "residuals", "seconds")
    return {
        **{k: info[k] for k in keys},
        "start": start,
        "alpha_u": s.alpha_u,
        "alpha_turb": s.alpha_turb,
        "ser": info["ser"],
    }


def _worst(residuals: dict[str, float], s: FlowSettings) -> float:
    """The largest residual, the pressure one divided by ``p_tolerance_factor`` (as :func:`_converged`)."""
    return max(v / s.p_tolerance_factor if k == "p" else v for k, v in residuals.items())


def _stalled(worst: list[float], window: int, tolerance: float, iterations_left: int) -> bool:
    """The worst residual did not halve over the last ``window`` iterations and, falling at
    its rate over them, would not reach ``tolerance`` in ``iterations_left`` (an oscillating
    or stuck iteration; a slow but steady one goes on)."""
    recent, before = min(worst[-window:]), min(worst[:-window])
    if recent <= 0.5 * before:
        return False
    rate = math.log(before / recent) / window if recent > 0 else math.inf
    return rate <= 0 or math.log(recent / tolerance) / rate > iterations_left


def _pseudo_step_factor(worst: list[float]) -> float:
    """SER growth of the pseudo-time step: ``r0 / r``, at least 1 (see :class:`FlowSettings`)."""
    if not worst:
        return 1.0
    r = max(worst[-5:])
    return max(1.0, max(worst[:5]) / r) if r > 0 else math.inf


def _relaxation(alpha: float, alpha_max: float, factor: float) -> float:
    """``alpha`` with its pseudo-time step ``alpha / (1 - alpha)`` times ``factor``, at most ``alpha_max``."""
    if alpha >= alpha_max:
        return alpha
    w = min(alpha / (1.0 - alpha) * factor, alpha_max / (1.0 - alpha_max))
    return w / (1.0 + w)


def _simplec(
    layout: Layout,
    mesh: Mesh,
    inlet_velocity: float,
    physics: Physics,
    s: FlowSettings,
    progress: Callable[[int, dict], None] | None,
    initial: FlowState | None = None,
) -> tuple[FlowState, dict]:
    """One SIMPLEC run from ``initial`` or from rest (see :func:`solve_flow`)."""
    t0 = time.perf_counter()
    nb, ft, h = mesh.nb, mesh.ft, mesh.h
    n = mesh.n
    V = h * h
    nu = physics.nu
    Cmu = physics.C_mu
    k_in, eps_in = physics.inlet_turbulence(inlet_velocity, max(o.width_m for o in layout.inlets))

    inlet = ft == INLET
    outlet = ft == OUTLET
    # inflow velocity points against the outward normal of the inlet face
    ubx = np.where(inlet & (AXIS == 0), -SIGN * inlet_velocity, 0.0)
    uby = np.where(inlet & (AXIS == 1), -SIGN * inlet_velocity, 0.0)
    turb = KEpsilon(mesh, physics, ubx, uby, k_in, eps_in)
    fixed_u = turb.fixed_u
    wall = turb.wall
    nut_in = turb.nut_in
    zero4 = np.zeros((n, 4))
    stencil = StencilMatrix(mesh)
    psolver = PressureSolver(s.max_krylov, s.pressure_solver, s.lu_cells)
    # a part of the free cells without an outlet (a closed room, a walled-in cell) has no
    # pressure level: its pressure equation is singular.  One cell of each such part is held at
    # p = 0 in the matrix solved; the part's equation is consistent (no net flux leaves it), so
    # this picks one of its solutions, and the fluxes come from the full equation
    p_pin = anchors(mesh, OUTLET)

    if initial is None:
        st = FlowState(
            ux=np.zeros(n),
            uy=np.zeros(n),
            p=np.zeros(n),
            k=np.full(n, k_in),
            eps=np.full(n, eps_in),
            nut=np.full(n, Cmu * k_in**2 / eps_in),
            F=np.where(inlet, -inlet_velocity * h, 0.0),
        )
    else:
        if initial.ux.shape != (n,) or initial.F.shape != (n, 4):
            raise InputDataError(f"initial state has {initial.ux.shape[0]} cells, the mesh {n}")
        st = initial.copy()
        st.F = np.where(inlet, -inlet_velocity * h, st.F)
        st.k = np.maximum(st.k, 1e-15)
        st.eps = np.maximum(st.eps, 1e-15)
    residuals: dict[str, float] = {}
    history: list[dict[str, float]] = []
    converged = False
    stalled = False
    worst: list[float] = []
    n_limited = 0
    sweeps = {"U": 0, "k": 0, "epsilon": 0}
    a_max = s.alpha_turb_max if n > s.ser_cells else s.alpha_turb_max_small
    ser = s.ser_cells > 0 and a_max > s.alpha_turb
    capped = ser and s.ser_max_sweeps < s.max_sweeps  # turbulence sweeps capped until a stall
    uncapped_at = None
    window_start = 0  # the stall test looks at the residuals since the last switch
    s_it = s
    grad_u = gp = None
    it = 0
    for it in range(1, s.max_iterations + 1):
        F = st.F
        if ser:
            a_t = _relaxation(s.alpha_turb, a_max, _pseudo_step_factor(worst))
            n_sweeps = s.ser_max_sweeps if capped else s.max_sweeps
            if (s_it.alpha_turb, s_it.max_sweeps) != (a_t, n_sweeps):
                s_it = replace(s, alpha_turb=a_t, max_sweeps=n_sweeps)
        nueff = nu + st.nut
        yplus, nutw = turb.wall_functions(st.k)
        # ---- momentum predictor ---------------------------------------------------------
        gam_b = boundary_gamma(nueff, inlet, nu + nut_in, wall, nu + nutw)
        aP, a, cb = assemble(F, nueff, fixed_u, gam_b, nb, ft, True)
        bx = row_dot(cb, ubx)
        by = row_dot(cb, uby)
        # the gradients of the velocity and pressure this iteration starts from were computed
        # at the end of the last one (k-epsilon changes neither field)
        if grad_u is None:
            grad_u = turb.velocity_gradients(st)
        gux, guy = grad_u
        stress = stress_source(nueff, gux, guy, nb, ft, h)
        bx += stress[:, 0]
        by += stress[:, 1]
        if s.high_order:
            bx += ho_source(st.ux, gradient(st.ux, ubx, fixed_u, nb, ft, h, True), F, nb, ft, h)
            by += ho_source(st.uy, gradient(st.uy, uby, fixed_u, nb, ft, h, True), F, nb, ft, h)
        aPr, bx = relax(aP, a, bx, st.ux, s_it.alpha_u)
        by = by + (aPr - aP) * st.uy
        # air flowing back in through an outlet face: with the outlet's zero gradient it
        # brings the cell's own momentum, and a backflow can feed itself from one iteration to
        # the next (a jet through the outlet growing without bound).  Its inflow |F| joins the
        # relaxation (diagonal |F|, source |F| u_old): the iteration moves such a cell by a
        # smaller pseudo-time step, the steady equations stay the zero-gradient outlet's
        back_in = np.where(outlet & (F < 0.0), -F, 0.0).sum(axis=1)
        if back_in.any():
            aPr = aPr + back_in
            bx = bx + back_in * st.ux
            by = by + back_in * st.uy
        if gp is None:
            gp = gradient(st.p, zero4, outlet, nb, ft, h, False)
        rhs_x = bx - gp[:, 0] * V
        rhs_y = by - gp[:, 1] * V
        u_star = np.stack([st.ux, st.uy], axis=1)
        n_sw, res = gauss_seidel(
            aPr, a, np.stack([rhs_x, rhs_y], axis=1), nb, u_star, s.rel_tol, s.max_sweeps, s.short_chain
        )
        sweeps["U"] += n_sw
        residuals["Ux"], residuals["Uy"] = float(res[0]), float(res[1])
        ux_star, uy_star = u_star[:, 0], u_star[:, 1]

        # ---- SIMPLEC pressure equation ---------------------------------------------------
        hbyax = (bx + neighbour_sum(a, ux_star, nb)) / aPr
        hbyay = (by + neighbour_sum(a, uy_star, nb)) / aPr
        rAU = V / aPr
        rAtU = V / (aPr - row_sum(a)) if s.consistent else rAU
        phb, lapP, lapA = pressure_system(hbyax, hbyay, rAU, rAtU, st.p, ubx, uby, nb, ft, h, s.consistent)
        if s.consistent:
            hbyax = hbyax - (rAU - rAtU) * gp[:, 0]
            hbyay = hbyay - (rAU - rAtU) * gp[:, 1]
        p_rhs = -row_sum(phb)
        residuals["p"] = residual_norm(lapP, lapA, p_rhs, nb, st.p)
        if p_pin.any():
            P = stencil.assemble(*_pinned(lapP, lapA, p_pin, nb))
            p_new = psolver.solve(P, np.where(p_pin, 0.0, p_rhs), np.where(p_pin, 0.0, st.p), s.p_rel_tol)
        else:
            p_new = psolver.solve(stencil.assemble(lapP, lapA), p_rhs, st.p, s.p_rel_tol)
        st.F = corrected_flux(phb, lapA, rAtU, p_new, nb, ft)
        st.p = s.alpha_p * p_new + (1.0 - s.alpha_p) * st.p
        gp = gradient(st.p, zero4, outlet, nb, ft, h, False)
        st.ux = hbyax - rAtU * gp[:, 0]
        st.uy = hbyay - rAtU * gp[:, 1]
        grad_u = turb.velocity_gradients(st)

        # ---- k-epsilon ---------------------------------------------------------------------
        # a diverging run overflows here; the finiteness test below reports it, without
        # NumPy's warnings on the user's terminal
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            n_limited = turb.step(st, s_it, yplus, nutw, residuals, sweeps, grad_u)

        history.append(dict(residuals))
        if progress is not None:
            progress(it, residuals)
        finite = all(math.isfinite(v) for v in residuals.values()) and np.isfinite(st.ux).all()
        if finite and _converged(residuals, s):
            converged = True
            break
        worst.append(_worst(residuals, s))
        w = s.stall_window if uncapped_at is None else max(s.stall_window // 2, 1)
        recent = worst[window_start:]
        if len(recent) > 2 * w and _stalled(recent, w, s.tolerance, s.max_iterations - it):
            if capped:  # the capped turbulence solves may be what holds it: solve them fully
                capped, uncapped_at, window_start = False, it, len(worst)
                continue
            stalled = True  # an oscillating or stuck iteration: report it, don't burn time
            break
        if not finite or time.perf_counter() - t0 > s.max_seconds:
            break
    info = {
        "iterations": it,
        "converged": converged,
        "stalled": stalled,
        "diverged": not finite,
        "residuals": dict(residuals),
        "seconds": time.perf_counter() - t0,
        "length_scale_limited_cells": n_limited,
        "pressure_factorizations": psolver.factorizations,
        "pressure_cg_iterations": psolver.krylov_iterations,
        "ser": ser,
        "final_relaxation": (s_it.alpha_u, s_it.alpha_turb),
        "turbulence_sweeps_uncapped_at": uncapped_at,
        "gauss_seidel_sweeps": sweeps,
        "history": history,
    }
    return st, info
