"""Steady gas transport on a frozen flow, its factorization and its adjoint.

``div(phi c) - div(D_eff grad c) + sigma c = S`` with ``D_eff = D_m + nu_t / Sc_t``
(spec section 4): inlet ``c = 0``, zero gradient at outlets and walls (air that
flows back in through an outlet is clean: ``inletOutlet``), the source cell
receiving ``q / (dx dy h)``.  ``sigma >= 0`` (``sink``, per cell) is
the air leaving the 2-D slice of a 3-D flow through the cell (a given wind
whose divergence is kept, :mod:`dgse.physics.projection`): the gas leaves with
it at the cell's concentration; air entering through the slice is clean and
adds no term; 0 for the built-in 2-D flows.  Convection is linear upwind (the
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

from dgse.errors import ConvergenceError, InputDataError
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.fv import (
    INLET,
    INTERNAL,
    OUTLET,
    Mesh,
    anchors,
    gradient,
    ho_source,
    parts,
    unreached,
)

SCHEMES = ("limitedLinearUpwind", "linearUpwind", "upwind")


def transport_matrix(
    mesh: Mesh,
    F: np.ndarray,
    diffusivity: np.ndarray,
    scheme: str = "linearUpwind",
    sink: np.ndarray | None = None,
) -> sp.csr_matrix:
    """The ``(n, n)`` steady transport operator on the free cells.

    Args:
        mesh: the layout's mesh.
        F: ``(n, 4)`` outward face fluxes (m^2/s per m depth).
        diffusivity: ``(n,)`` cell diffusivity ``D_eff`` (m^2/s).
        scheme: ``"linearUpwind"`` (implicit, unlimited, second order) or ``"upwind"``.
        sink: ``(n,)`` volume outflow through the slice per cell (m^2/s per m depth, >= 0;
            module docstring), or None.
    """
    if scheme not in ("linearUpwind", "upwind"):
        raise InputDataError(f"no linear operator for convection scheme {scheme!r}")
    n = mesh.n
    nb, ft = mesh.nb, mesh.ft
    P = np.arange(n)
    internal = ft == INTERNAL
    nbi = np.where(internal, nb, P[:, None])  # the cell itself where there is no neighbour
    rows, cols, vals = [], [], []

    def add(r, c, v):
        rows.append(r)
        cols.append(c)
        vals.append(v)

    # half a cell of gradient along each axis, 0.5 (f_plus - f_minus), as weights on
    # (cell, plus neighbour, minus neighbour): linear face values inside, the cell
    # value at zero-gradient faces, 0 at inlets (c = 0 there)
    w_self = np.where(internal, 0.5, np.where(ft == INLET, 0.0, 1.0))
    w_nb = np.where(internal, 0.5, 0.0)
    half = [
        (
            0.5 * (w_self[:, plus] - w_self[:, minus]),
            nbi[:, plus],
            0.5 * w_nb[:, plus],
            nbi[:, minus],
            -0.5 * w_nb[:, minus],
        )
        for plus, minus in ((0, 1), (2, 3))
    ]
    for d in range(4):
        Fd = F[:, d]
        inn = internal[:, d]
        Nd = nbi[:, d]
        g_f = np.where(inn, 0.5 * (diffusivity + diffusivity[Nd]), 0.0)
        add(P, P, g_f)
        add(P, Nd, -g_f)
        add(P, P, np.where(ft[:, d] == INLET, 2.0 * diffusivity, 0.0))
        out = Fd > 0
        # outlets: the cell's gas leaves where air flows out; air flowing back in through an
        # outlet face is clean (inletOutlet, c = 0 on that face): it adds no term.  With the
        # cell's own value on such a face (zero gradient) the backflow would carry gas in,
        # taking the row's diagonal below the sum of its neighbours, and a strong backflow
        # made the operator indefinite (a gas field of either sign, its balance lost)
        add(P, P, np.where((inn | (ft[:, d] == OUTLET)) & out, Fd, 0.0))
        add(P, Nd, np.where(inn & ~out, Fd, 0.0))
        if scheme == "linearUpwind":
            sign = 1.0 if d in (0, 2) else -1.0
            w_c, i_p, w_p, i_m, w_m = half[0 if d < 2 else 1]
            up = np.where(out, P, Nd)
            coef = np.where(inn, Fd * np.where(out, sign, -sign), 0.0)
            add(P, up, coef * w_c[up])
            add(P, i_p[up], coef * w_p[up])
            add(P, i_m[up], coef * w_m[up])
    if sink is not None:
        add(P, P, np.asarray(sink, dtype=np.float64))
    r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    # a part of the free cells that no inlet reaches and no through-slice sink drains (a closed
    # room, a walled-in cell) has no concentration level: its operator is singular.  No gas
    # reaches it (a source there is refused, :func:`check_release_cells`), so its steady
    # concentration is 0: one cell of each such part reads c = 0, which makes it regular
    pin = anchors(mesh, INLET)
    if pin.any():
        pin &= ~_drained(mesh, sink)
    if pin.any():
        keep = ~pin[r]
        fixed = np.flatnonzero(pin)
        r, c, v = np.r_[r[keep], fixed], np.r_[c[keep], fixed], np.r_[v[keep], np.ones(fixed.size)]
    A = sp.coo_matrix((v, (r, c)), shape=(n, n)).tocsr()
    A.eliminate_zeros()
    return A


def _drained(mesh: Mesh, sink: np.ndarray | None) -> np.ndarray:
    """``bool (n,)``: the free cells whose part (:func:`~dgse.physics.fv.parts`) loses air
    through the slice (some ``sink > 0``), which gives its gas a way out without an inlet."""
    if sink is None or not (np.asarray(sink) > 0).any():
        return np.zeros(mesh.n, dtype=bool)
    labels, _ = parts(mesh)
    return np.isin(labels, np.unique(labels[np.asarray(sink) > 0]))


def check_release_cells(mesh: Mesh, cells, sink: np.ndarray | None = None) -> None:
    """Raise :class:`InputDataError` unless every ``(i, j)`` of ``cells`` is a free cell of ``mesh``
    that an inlet reaches or a through-slice ``sink`` drains: gas released where none can leave
    has no steady state."""
    closed = None
    for i, j in cells:
        if not (0 <= i < mesh.shape[0] and 0 <= j < mesh.shape[1]) or not mesh.free[i, j]:
            raise InputDataError(f"source cell ({i}, {j}) is not a free cell of the map")
        closed = unreached(mesh, INLET) & ~_drained(mesh, sink) if closed is None else closed
        if closed[mesh.index[i, j]]:
            raise InputDataError(
                f"source cell ({i}, {j}) lies in a closed region that no inlet reaches: "
                "its gas has nowhere to go and no steady concentration"
            )


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
        >>> ts = TransportSolver.build(mesh, F, nut)                  # doctest: +SKIP
        >>> c = ts.solve_cells([(31, 20)], [0.5])   # (1, H, W) g/m^3  # doctest: +SKIP
        >>> a = ts.adjoint([(10, 12), (40, 7)])     # (2, H, W)        # doctest: +SKIP
    """

    mesh: Mesh
    F: np.ndarray
    diffusivity: np.ndarray
    physics: Physics
    scheme: str = "limitedLinearUpwind"
    adjoint_scheme: str = "linearUpwind"
    tolerance: float = 1e-7
    max_outer: int = 300
    sink: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.sink is not None:
            self.sink = np.asarray(self.sink, dtype=np.float64)
            if self.sink.shape != (self.mesh.n,) or not (self.sink >= 0).all():
                raise InputDataError(f"sink must be (n,) and non-negative, got shape {self.sink.shape}")
        for s in (self.scheme, self.adjoint_scheme):
            if s not in SCHEMES:
                raise InputDataError(f"unknown convection scheme {s!r}; use one of {SCHEMES}")
        self._lu: dict[str, object] = {}

    @classmethod
    def build(
        cls,
        mesh: Mesh,
        F: np.ndarray,
        nut: np.ndarray,
        physics: Physics = DEFAULT_PHYSICS,
        scheme: str = "limitedLinearUpwind",
        **options,
    ) -> TransportSolver:
        """From outward face fluxes ``F (n, 4)`` and the cell ``nu_t (n,)`` of a flow."""
        D = physics.D_m + nut / physics.Sc_t
        return cls(mesh, F, D, physics, scheme, **options)

    def matrix(self, scheme: str) -> sp.csr_matrix:
        """The linear operator of ``scheme`` (``"upwind"`` or ``"linearUpwind"``)."""
        return transport_matrix(self.mesh, self.F, self.diffusivity, scheme, self.sink)

    def factor(self, scheme: str):
        if scheme not in self._lu:
            try:
                self._lu[scheme] = spla.splu(self.matrix(scheme).tocsc())
            except RuntimeError as e:  # SuperLU's "Factor is exactly singular"
                raise ConvergenceError(
                    f"the {scheme} transport operator of this flow cannot be factorized ({e}): "
                    "no unique steady concentration"
                ) from None
        return self._lu[scheme]

    def _rhs(self, cells, rates) -> np.ndarray:
        m = self.mesh
        check_release_cells(m, cells, self.sink)
        B = np.zeros((m.n, len(cells)))
        for n, ((i, j), q) in enumerate(zip(cells, rates, strict=True)):
            B[m.index[i, j], n] = q / self.physics.slab_depth  # g/s per m of depth
        return B

    def solve_cells(self, cells, rates) -> np.ndarray:
        """Concentration fields ``(n_sources, H, W)`` in g/m^3 for sources in ``cells``.

        Args:
            cells (Sequence[tuple[int, int]]): ``(i, j)`` source cells.
            rates (Sequence[float]): release rates in g/s.
        """
        B = self._rhs(cells, rates)
        if self.scheme != "limitedLinearUpwind":
            X = self.factor(self.scheme).solve(B)
            self.info = {"outer_iterations": 1, "converged": True}
        else:
            X = self._deferred_correction(B)
        return self.mesh.field(X.T)

    def _deferred_correction(self, B: np.ndarray) -> np.ndarray:
        m = self.mesh
        lu = self.factor("upwind")
        fixed = m.ft == INLET  # c = 0 at inlets; zero gradient elsewhere
        pin = anchors(m, INLET)
        bval = np.zeros((m.n, 4))
        X = lu.solve(B)
        change = np.inf
        it = 0
        while it < self.max_outer:
            it += 1
            S = np.empty_like(X)
            for k in range(X.shape[1]):
                x = np.ascontiguousarray(X[:, k])
                g = gradient(x, bval, fixed, m.nb, m.ft, m.h, True)
                S[:, k] = ho_source(x, g, self.F, m.nb, m.ft, m.h)
            S[pin] = 0.0  # the cells that read c = 0 (transport_matrix)
            X_new = lu.solve(B + S)
            scale = np.abs(X_new).max(axis=0) + 1e-300
            change = float((np.abs(X_new - X).max(axis=0) / scale).max())
            X = X_new
            if change < self.tolerance:
                break
        self.info = {"outer_iterations": it, "converged": change < self.tolerance, "last_change": change}
        if not np.isfinite(X).all():
            raise ConvergenceError(
                f"the gas transport's deferred correction diverged in {it} iterations (non-finite values)",
                self.info,
            )
        return X

    def outflow(self, conc: np.ndarray) -> tuple[float, float]:
        """Scalar flux ``(out of the outlets, out of the inlets by diffusion)``, g/s per m depth.

        Args:
            conc: ``(H, W)`` concentration in g/m^3.
        """
        m = self.mesh
        c = m.values(conc)
        out = float((np.maximum(self.F, 0.0) * (m.ft == OUTLET) * c[:, None]).sum())  # clean backflow
        inl = float((2.0 * (self.diffusivity * c)[:, None] * (m.ft == INLET)).sum())
        return out, inl

    def slice_outflow(self, conc: np.ndarray) -> float:
        """Scalar flux out through the slice (``sum sink c``), g/s per m depth; 0 without a sink.

        Args:
            conc: ``(H, W)`` concentration in g/m^3.
        """
        if self.sink is None:
            return 0.0
        return float(self.sink @ self.mesh.values(conc))

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
        return m.field(X.T)
