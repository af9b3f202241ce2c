"""Steady gas transport on a frozen flow, its factorization and its adjoint.

``div(phi c) - div(D_eff grad c) = S`` with ``D_eff = D_m + nu_t / Sc_t``
(spec section 4): inlet ``c = 0``, zero gradient at outlets and walls, the
source cell receiving ``q / (dx dy h)``.  Convection is linear upwind (the
face value extrapolated from the upwind cell with its Gauss gradient),
assembled implicitly: the operator is linear, so one sparse LU factorization
serves every source of a flow field, and its transpose gives the discrete
adjoint — the response of one sensor to a unit source in every cell.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from dgse.errors import InputDataError
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.fv import (
    BC,
    INLET,
    INTERNAL,
    OUTLET,
    Mesh,
    face_types,
    gauss_gradient,
    ho_correction,
    outward,
)

SCHEMES = ("limitedLinearUpwind", "linearUpwind", "upwind")

_DIRS = (
    ("E", 0, 1.0, (0, 1)),
    ("W", 0, -1.0, (0, -1)),
    ("N", 1, 1.0, (1, 0)),
    ("S", 1, -1.0, (-1, 0)),
)


def transport_matrix(
    mesh: Mesh,
    phi_x: np.ndarray,
    phi_y: np.ndarray,
    diffusivity: np.ndarray,
    scheme: str = "linearUpwind",
) -> sp.csr_matrix:
    """The ``(n, n)`` steady transport operator on the free cells.

    Args:
        mesh: the layout's mesh.
        phi_x, phi_y: face fluxes ``(H, W + 1)``, ``(H + 1, W)`` (m^2/s per m depth).
        diffusivity: ``(H, W)`` cell diffusivity ``D_eff`` (m^2/s).
        scheme: ``"linearUpwind"`` (second order, default) or ``"upwind"``.
    """
    if scheme not in ("linearUpwind", "upwind"):
        raise InputDataError(f"no linear operator for convection scheme {scheme!r}")
    free = mesh.free
    idx = mesh.index
    H, W = mesh.shape
    t = face_types(mesh)
    F = outward(phi_x, phi_y)
    ii, jj = np.nonzero(free)
    P = idx[ii, jj]
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []

    def add(r, c, v):
        rows.append(r)
        cols.append(c)
        vals.append(v)

    # half gradient along each axis of every cell: 0.5 (f_plus - f_minus) as terms
    # (cell itself, plus neighbour, minus neighbour), face values linear inside,
    # the cell value at zero-gradient faces, 0 at inlets (c = 0 there).
    def side_weights(d: str) -> tuple[np.ndarray, np.ndarray]:
        td = t[d][ii, jj]
        w_self = np.where(td == INTERNAL, 0.5, np.where(td == INLET, 0.0, 1.0))
        w_nb = np.where(td == INTERNAL, 0.5, 0.0)
        return w_self, w_nb

    def nb_index(di: int, dj: int, mask_internal: np.ndarray) -> np.ndarray:
        ni = np.clip(ii + di, 0, H - 1)
        nj = np.clip(jj + dj, 0, W - 1)
        return np.where(mask_internal, idx[ni, nj], P)

    half = {}
    for axis, (plus, minus) in ((0, ("E", "W")), (1, ("N", "S"))):
        wsp, wnp = side_weights(plus)
        wsm, wnm = side_weights(minus)
        sh_p = _DIRS[0][3] if axis == 0 else _DIRS[2][3]
        sh_m = _DIRS[1][3] if axis == 0 else _DIRS[3][3]
        np_idx = nb_index(*sh_p, t[plus][ii, jj] == INTERNAL)
        nm_idx = nb_index(*sh_m, t[minus][ii, jj] == INTERNAL)
        half[axis] = (0.5 * (wsp - wsm), np_idx, 0.5 * wnp, nm_idx, -0.5 * wnm)
    # lookup from a cell's unknown number to its position in (ii, jj)
    pos = np.empty(mesh.n, dtype=np.int64)
    pos[P] = np.arange(P.size)

    for d, axis, sign, (di, dj) in _DIRS:
        td = t[d][ii, jj]
        Fd = F[d][ii, jj]
        internal = td == INTERNAL
        N = nb_index(di, dj, internal)
        gam = diffusivity[ii, jj]
        gam_nb = diffusivity[np.clip(ii + di, 0, H - 1), np.clip(jj + dj, 0, W - 1)]
        gam_f = np.where(internal, 0.5 * (gam + gam_nb), gam)
        # diffusion
        add(P, P, np.where(internal, gam_f, 0.0))
        add(P, N, np.where(internal, -gam_f, 0.0))
        inlet = td == INLET
        add(P, P, np.where(inlet, 2.0 * gam, 0.0))  # c = 0 at the inlet, half a cell away
        # convection, upwind part
        out = Fd > 0
        add(P, P, np.where((internal & out) | (td == OUTLET), Fd, 0.0))
        add(P, N, np.where(internal & ~out, Fd, 0.0))
        if scheme == "linearUpwind":
            # correction F * (+/-) half-gradient of the upwind cell along this axis
            w_c, i_p, w_p, i_m, w_m = half[axis]
            up = np.where(out, P, N)
            up_pos = pos[up]
            coef = np.where(internal, Fd * np.where(out, sign, -sign), 0.0)
            add(P, up, coef * w_c[up_pos])
            add(P, i_p[up_pos], coef * w_p[up_pos])
            add(P, i_m[up_pos], coef * w_m[up_pos])
    A = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(mesh.n, mesh.n)
    ).tocsr()
    A.eliminate_zeros()
    return A


@dataclass
class TransportSolver:
    """The transport operator of one flow field, factorized once for many sources.

    ``scheme`` is the convection scheme of the forward solves:
    ``"limitedLinearUpwind"`` (default; OpenFOAM's ``linearUpwind`` with a
    cell-limited gradient, bounded, solved by deferred correction on the
    factorized upwind operator), ``"linearUpwind"`` (unlimited, linear) or
    ``"upwind"``.  The adjoint always uses a linear operator
    (``adjoint_scheme``, default ``"linearUpwind"``) and is exact for it.

    Example:
        >>> ts = TransportSolver.build(mesh, phi_x, phi_y, nut)      # doctest: +SKIP
        >>> c = ts.solve_cells([(31, 20)], [0.5])   # (1, H, W) g/m^3  # doctest: +SKIP
        >>> a = ts.adjoint([(10, 12), (40, 7)])     # (2, H, W)        # doctest: +SKIP
    """

    mesh: Mesh
    phi_x: np.ndarray
    phi_y: np.ndarray
    diffusivity: np.ndarray
    physics: Physics
    scheme: str = "limitedLinearUpwind"
    adjoint_scheme: str = "linearUpwind"
    tolerance: float = 1e-7
    max_outer: int = 300
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        for s in (self.scheme, self.adjoint_scheme):
            if s not in SCHEMES:
                raise InputDataError(f"unknown convection scheme {s!r}; use one of {SCHEMES}")
        self._lu: dict[str, object] = {}

    @classmethod
    def build(
        cls,
        mesh: Mesh,
        phi_x: np.ndarray,
        phi_y: np.ndarray,
        nut: np.ndarray,
        physics: Physics = DEFAULT_PHYSICS,
        scheme: str = "limitedLinearUpwind",
        **options,
    ) -> TransportSolver:
        D = np.where(mesh.free, physics.D_m + nut / physics.Sc_t, 0.0)
        return cls(mesh, phi_x, phi_y, D, physics, scheme, **options)

    def matrix(self, scheme: str) -> sp.csr_matrix:
        """The linear operator of ``scheme`` (``"upwind"`` or ``"linearUpwind"``)."""
        return transport_matrix(self.mesh, self.phi_x, self.phi_y, self.diffusivity, scheme)

    def factor(self, scheme: str):
        if scheme not in self._lu:
            self._lu[scheme] = spla.splu(self.matrix(scheme).tocsc())
        return self._lu[scheme]

    def _rhs(self, cells, rates) -> np.ndarray:
        m = self.mesh
        B = np.zeros((m.n, len(cells)))
        for n, ((i, j), q) in enumerate(zip(cells, rates, strict=True)):
            if not (0 <= i < m.shape[0] and 0 <= j < m.shape[1]) or not m.free[i, j]:
                raise InputDataError(f"source cell ({i}, {j}) is not a free cell of the map")
            B[m.index[i, j], n] = q / self.physics.slab_depth  # g/s per m of depth
        return B

    def solve_cells(self, cells, rates) -> np.ndarray:
        """Concentration fields ``(n_sources, H, W)`` in g/m^3 for sources in ``cells``.

        Args:
            cells: ``(i, j)`` source cells.
            rates: release rates in g/s.
        """
        m = self.mesh
        B = self._rhs(cells, rates)
        if self.scheme != "limitedLinearUpwind":
            X = self.factor(self.scheme).solve(B)
            self.info = {"outer_iterations": 1, "converged": True}
        else:
            X = self._deferred_correction(B)
        out = np.zeros((B.shape[1], *m.shape))
        out[:, m.free] = X.T
        return out

    def _deferred_correction(self, B: np.ndarray) -> np.ndarray:
        m = self.mesh
        lu = self.factor("upwind")
        t = face_types(m)
        F = outward(self.phi_x, self.phi_y)
        fixed = {d: (t[d] == INLET) & m.free for d in t}
        bc = BC(fixed, {d: np.zeros(m.shape) for d in t})
        X = lu.solve(B)
        C = np.zeros((B.shape[1], *m.shape))
        change = np.inf
        it = 0
        for it in range(1, self.max_outer + 1):
            C[:, m.free] = X.T
            gx, gy = gauss_gradient(C, t, bc, m.h, limited=True)
            S = ho_correction(C, gx, gy, t, F, m.h)
            X_new = lu.solve(B + S[:, m.free].T)
            scale = np.abs(X_new).max(axis=0) + 1e-300
            change = float((np.abs(X_new - X).max(axis=0) / scale).max())
            X = X_new
            if change < self.tolerance:
                break
        self.info = {
            "outer_iterations": it, "converged": change < self.tolerance, "last_change": change,
        }
        return X

    def outflow(self, conc: np.ndarray) -> tuple[float, float]:
        """Scalar flux ``(out of the outlets, out of the inlets by diffusion)``, g/s per m depth.

        Args:
            conc: ``(H, W)`` concentration in g/m^3.
        """
        m = self.mesh
        F = outward(self.phi_x, self.phi_y)
        t = face_types(m)
        out = 0.0
        inl = 0.0
        for d in t:
            out += float((F[d] * conc)[(t[d] == OUTLET) & m.free].sum())
            inl += float((2.0 * self.diffusivity * conc)[(t[d] == INLET) & m.free].sum())
        return out, inl

    def adjoint(self, sensor_cells) -> np.ndarray:
        """Sensor responses ``(n_sensors, H, W)`` in (g/m^3) / (g/s).

        Row ``i`` is ``A^-T e_i`` of the ``adjoint_scheme`` operator (scaled by
        the slab depth): the concentration at sensor ``i`` for a source of
        ``q`` g/s in cell ``s`` is ``adjoint[i][s] * q``.  One factorization,
        one triangular solve pair per sensor.
        """
        m = self.mesh
        cells = np.asarray(sensor_cells, dtype=np.int64).reshape(-1, 2)
        inside = (cells >= 0).all(axis=1) & (cells[:, 0] < m.shape[0]) & (cells[:, 1] < m.shape[1])
        if not inside.all() or not m.free[cells[:, 0], cells[:, 1]].all():
            raise InputDataError("a sensor cell lies outside the map or in a solid cell")
        E = np.zeros((m.n, len(cells)))
        E[m.index[cells[:, 0], cells[:, 1]], np.arange(len(cells))] = 1.0
        X = self.factor(self.adjoint_scheme).solve(E, trans="T") / self.physics.slab_depth
        out = np.zeros((len(cells), *m.shape))
        out[:, m.free] = X.T
        return out
