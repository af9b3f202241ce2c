"""Finite volumes on the Cartesian grid with solid cells (pure array kernels).

Cells are the free cells of a layout; every face of a free cell is one of
``INTERNAL`` (free on both sides), ``WALL`` (a solid cell or the domain edge),
``INLET`` or ``OUTLET`` (an opening of the outer boundary).  Faces live on two
staggered arrays: ``x`` faces ``(H, W + 1)`` between cells ``(i, j - 1)`` and
``(i, j)``, and ``y`` faces ``(H + 1, W)`` between ``(i - 1, j)`` and ``(i, j)``.
Fluxes on them are positive along ``+x`` / ``+y``.

A transport equation is assembled in the usual form
``a_P phi_P - sum_nb a_nb phi_nb = b`` on the free cells and handed to a
sparse matrix whose pattern is built once per mesh.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from dgse.world.layout import Layout

NONE, INTERNAL, WALL, INLET, OUTLET = 0, 1, 2, 3, 4

DIRS = ("E", "W", "N", "S")
_SHIFT = {"E": (0, 1), "W": (0, -1), "N": (1, 0), "S": (-1, 0)}
_SIGN = {"E": 1.0, "W": -1.0, "N": 1.0, "S": -1.0}  # outward normal along its axis
_AXIS = {"E": 0, "W": 0, "N": 1, "S": 1}  # 0: x, 1: y


def neighbour(a: np.ndarray, d: str) -> np.ndarray:
    """Value of the neighbouring cell in direction ``d`` (0 beyond the edge)."""
    out = np.zeros_like(a)
    if d == "E":
        out[..., :, :-1] = a[..., :, 1:]
    elif d == "W":
        out[..., :, 1:] = a[..., :, :-1]
    elif d == "N":
        out[..., :-1, :] = a[..., 1:, :]
    else:
        out[..., 1:, :] = a[..., :-1, :]
    return out


def face_types(mesh: Mesh) -> dict[str, np.ndarray]:
    return {"E": mesh.tE, "W": mesh.tW, "N": mesh.tN, "S": mesh.tS}


def outward(phi_x: np.ndarray, phi_y: np.ndarray) -> dict[str, np.ndarray]:
    """Outward face fluxes of each cell, per direction, each ``(H, W)``."""
    return {"E": phi_x[:, 1:], "W": -phi_x[:, :-1], "N": phi_y[1:, :], "S": -phi_y[:-1, :]}


@dataclass
class BC:
    """Boundary condition of one variable on the faces of each cell.

    ``fixed[d]`` marks boundary faces with a fixed value ``value[d]``; the other
    boundary faces are zero-gradient.  ``gamma[d]`` overrides the diffusivity
    on boundary faces (wall functions).
    """

    fixed: dict[str, np.ndarray]
    value: dict[str, np.ndarray]
    gamma: dict[str, np.ndarray] = field(default_factory=dict)


def face_values(phi: np.ndarray, t: dict, bc: BC) -> dict[str, np.ndarray]:
    """Face values per direction: linear on internal faces, boundary values elsewhere."""
    out = {}
    for d in DIRS:
        nbv = neighbour(phi, d)
        internal = t[d] == INTERNAL
        v = np.where(internal, 0.5 * (phi + nbv), phi)
        out[d] = np.where(bc.fixed[d], bc.value[d], v)
    return out


def gauss_gradient(
    phi: np.ndarray, t: dict, bc: BC, h: float, limited: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Cell gradient ``(d/dx, d/dy)`` by Gauss's theorem, optionally cell-limited (OpenFOAM)."""
    fv = face_values(phi, t, bc)
    gx = (fv["E"] - fv["W"]) / h
    gy = (fv["N"] - fv["S"]) / h
    if not limited:
        return gx, gy
    vmax = phi.copy()
    vmin = phi.copy()
    for d in DIRS:
        internal = t[d] == INTERNAL
        bnd = t[d] >= WALL
        nbv = neighbour(phi, d)
        cand = np.where(internal, nbv, np.where(bnd, fv[d], phi))
        vmax = np.maximum(vmax, cand)
        vmin = np.minimum(vmin, cand)
    dmax = vmax - phi
    dmin = vmin - phi
    lim_x = np.ones_like(phi)
    lim_y = np.ones_like(phi)
    tiny = 1e-300
    for g, lim in ((gx, lim_x), (gy, lim_y)):
        ext = np.abs(g) * (0.5 * h)  # extrapolation to the + face; the - face is its negative
        with np.errstate(divide="ignore", invalid="ignore"):
            r_hi = np.where(ext > dmax + tiny, dmax / np.maximum(ext, tiny), 1.0)
            r_lo = np.where(-ext < dmin - tiny, dmin / np.minimum(-ext, -tiny), 1.0)
        np.minimum(lim, np.minimum(r_hi, r_lo), out=lim)
    return gx * lim_x, gy * lim_y



def ho_correction(
    phi: np.ndarray, gx: np.ndarray, gy: np.ndarray, t: dict, F: dict, h: float
) -> np.ndarray:
    """Explicit source turning upwind into linear-upwind convection on internal faces."""
    src = np.zeros_like(phi)
    for d in DIRS:
        internal = t[d] == INTERNAL
        Fd = F[d]
        g = gx if _AXIS[d] == 0 else gy
        s = _SIGN[d]
        own = g * (s * 0.5 * h)  # extrapolation from this cell to the face
        nbr = -neighbour(g, d) * (s * 0.5 * h)  # from the neighbour to the same face
        corr = np.where(Fd > 0, Fd * own, Fd * nbr)
        src -= np.where(internal, corr, 0.0)
    return src





@dataclass(frozen=True)
class Mesh:
    """Face classification and index maps of a layout (built by :func:`build_mesh`).

    Attributes:
        h: cell size, m (faces have area ``h`` per metre of depth).
        free: ``(H, W)`` bool.
        xtype: ``(H, W + 1)`` face types; ``ytype``: ``(H + 1, W)``.
        index: ``(H, W)`` unknown number of each free cell, -1 in solid.
        n: number of free cells.
        inlet_normal: ``(H, W + 1)`` / ``(H + 1, W)`` arrays not needed; inlet
            face fluxes are built by :func:`inlet_fluxes`.
    """

    h: float
    free: np.ndarray
    xtype: np.ndarray
    ytype: np.ndarray
    index: np.ndarray
    n: int

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape

    # per-cell views of the four faces' types, each (H, W)
    @property
    def tE(self) -> np.ndarray:
        return self.xtype[:, 1:]

    @property
    def tW(self) -> np.ndarray:
        return self.xtype[:, :-1]

    @property
    def tN(self) -> np.ndarray:
        return self.ytype[1:, :]

    @property
    def tS(self) -> np.ndarray:
        return self.ytype[:-1, :]


def build_mesh(layout: Layout) -> Mesh:
    """Classify every face of the layout's free cells."""
    free = layout.free
    H, W = free.shape
    inlet = layout.opening_mask("inlet")
    outlet = layout.opening_mask("outlet")

    def classify(a: np.ndarray, b: np.ndarray, edge_a: np.ndarray, edge_b: np.ndarray) -> np.ndarray:
        # a, b: free flags of the two sides (False beyond the edge)
        t = np.where(a & b, INTERNAL, np.where(a ^ b, WALL, NONE)).astype(np.int8)
        for code, mask_a, mask_b in ((INLET, edge_a[0], edge_b[0]), (OUTLET, edge_a[1], edge_b[1])):
            t[mask_a | mask_b] = code
        return t

    pad_x = np.zeros((H, 1), bool)
    left = np.concatenate([pad_x, free], axis=1)  # cell west of each x face
    right = np.concatenate([free, pad_x], axis=1)  # cell east of each x face
    zx = np.zeros((H, W + 1), bool)
    west_in, east_in, west_out, east_out = zx.copy(), zx.copy(), zx.copy(), zx.copy()
    west_in[:, 0] = inlet[:, 0] & _side_mask(layout, "inlet", "west")
    east_in[:, W] = inlet[:, W - 1] & _side_mask(layout, "inlet", "east")
    west_out[:, 0] = outlet[:, 0] & _side_mask(layout, "outlet", "west")
    east_out[:, W] = outlet[:, W - 1] & _side_mask(layout, "outlet", "east")
    xtype = classify(left, right, (west_in, west_out), (east_in, east_out))

    pad_y = np.zeros((1, W), bool)
    below = np.concatenate([pad_y, free], axis=0)
    above = np.concatenate([free, pad_y], axis=0)
    zy = np.zeros((H + 1, W), bool)
    s_in, n_in, s_out, n_out = zy.copy(), zy.copy(), zy.copy(), zy.copy()
    s_in[0, :] = inlet[0, :] & _side_mask(layout, "inlet", "south", axis=1)
    n_in[H, :] = inlet[H - 1, :] & _side_mask(layout, "inlet", "north", axis=1)
    s_out[0, :] = outlet[0, :] & _side_mask(layout, "outlet", "south", axis=1)
    n_out[H, :] = outlet[H - 1, :] & _side_mask(layout, "outlet", "north", axis=1)
    ytype = classify(below, above, (s_in, s_out), (n_in, n_out))

    index = np.full((H, W), -1, dtype=np.int64)
    index[free] = np.arange(int(free.sum()))
    return Mesh(layout.resolution, free, xtype, ytype, index, int(free.sum()))


def _side_mask(layout: Layout, kind: str, side: str, axis: int = 0) -> np.ndarray:
    """Along-side mask (length H for west/east, W for south/north) of openings on ``side``."""
    g = layout.grid
    n = g.height if side in ("west", "east") else g.width
    m = np.zeros(n, bool)
    for o in layout.inlets if kind == "inlet" else layout.outlets:
        if o.side == side:
            rows, cols = o.cells(g)
            m[rows if side in ("west", "east") else cols] = True
    return m


def inlet_fluxes(mesh: Mesh, layout: Layout, inlet_velocity: float) -> tuple[np.ndarray, np.ndarray]:
    """Face fluxes ``(phi_x, phi_y)`` (m^2/s per m depth) of the inlets, 0 elsewhere."""
    H, W = mesh.shape
    h = mesh.h
    fx = np.zeros((H, W + 1))
    fy = np.zeros((H + 1, W))
    fx[:, 0][mesh.xtype[:, 0] == INLET] = inlet_velocity * h
    fx[:, W][mesh.xtype[:, W] == INLET] = -inlet_velocity * h
    fy[0, :][mesh.ytype[0, :] == INLET] = inlet_velocity * h
    fy[H, :][mesh.ytype[H, :] == INLET] = -inlet_velocity * h
    return fx, fy


def inlet_velocity_field(mesh: Mesh, inlet_velocity: float):
    """Boundary velocity ``(ux_x, uy_x)`` on x faces and ``(ux_y, uy_y)`` on y faces of inlets."""
    H, W = mesh.shape
    ux_x = np.zeros((H, W + 1))
    uy_y = np.zeros((H + 1, W))
    ux_x[:, 0][mesh.xtype[:, 0] == INLET] = inlet_velocity
    ux_x[:, W][mesh.xtype[:, W] == INLET] = -inlet_velocity
    uy_y[0, :][mesh.ytype[0, :] == INLET] = inlet_velocity
    uy_y[H, :][mesh.ytype[H, :] == INLET] = -inlet_velocity
    return ux_x, uy_y


class StencilMatrix:
    """Five-point sparse matrix on the free cells with a pattern built once.

    ``assemble(aP, aE, aW, aN, aS)`` takes ``(H, W)`` coefficient arrays of
    ``a_P phi_P - sum a_nb phi_nb`` (neighbour coefficients only used on
    internal faces) and returns a CSR matrix, reusing the index arrays.
    """

    def __init__(self, mesh: Mesh) -> None:
        self.mesh = mesh
        idx = mesh.index
        rows = [idx[mesh.free]]
        cols = [idx[mesh.free]]
        self._masks = []
        for t, shift in ((mesh.tE, (0, 1)), (mesh.tW, (0, -1)), (mesh.tN, (1, 0)), (mesh.tS, (-1, 0))):
            m = (t == INTERNAL) & mesh.free
            ii, jj = np.nonzero(m)
            rows.append(idx[ii, jj])
            cols.append(idx[ii + shift[0], jj + shift[1]])
            self._masks.append(m)
        r = np.concatenate(rows)
        c = np.concatenate(cols)
        order = np.arange(r.size)
        tmpl = sp.csr_matrix((order.astype(np.float64) + 1.0, (r, c)), shape=(mesh.n, mesh.n))
        tmpl.sort_indices()
        self._perm = (tmpl.data - 1.0).astype(np.int64)
        self._indices = tmpl.indices.copy()
        self._indptr = tmpl.indptr.copy()
        self.diag_positions = None

    def assemble(self, aP, aE, aW, aN, aS) -> sp.csr_matrix:
        m = self.mesh
        data = np.concatenate(
            [aP[m.free]]
            + [-a[mask] for a, mask in zip((aE, aW, aN, aS), self._masks, strict=True)]
        )
        return sp.csr_matrix(
            (data[self._perm], self._indices, self._indptr), shape=(m.n, m.n), copy=False
        )


def to_vector(mesh: Mesh, field: np.ndarray) -> np.ndarray:
    return field[mesh.free]


def to_field(mesh: Mesh, vec: np.ndarray, fill: float = 0.0) -> np.ndarray:
    out = np.full(mesh.shape, fill, dtype=np.float64)
    out[mesh.free] = vec
    return out
