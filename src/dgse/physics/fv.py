"""Finite volumes on the Cartesian grid with solid cells: topology and compiled kernels.

The unknowns are the free cells of a layout, numbered ``0 .. n-1``.  Every
cell has four faces in the order ``E, W, N, S``; a face is ``INTERNAL`` (a
free cell beyond it), ``WALL`` (a solid cell or the domain edge), ``INLET``
or ``OUTLET`` (an opening of the outer boundary).  Per-face quantities are
``(n, 4)`` arrays seen from the cell: ``F[c, d]`` is the volume flux *out* of
cell ``c`` through face ``d`` (m^2/s per metre of depth), so the two cells of
an internal face hold opposite values.

A transport equation is written ``aP phi_P - sum_d a[:, d] phi_nb(d) = b``.
The kernels (numba-compiled, cached on disk) follow OpenFOAM's discretization
on a uniform orthogonal grid: Gauss linear gradients, optionally cell-limited;
upwind convection with a linear-upwind deferred correction; central
diffusion; ``bounded`` continuity correction.  They are pure functions of
arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp

from dgse.world.layout import Layout

NONE, INTERNAL, WALL, INLET, OUTLET = 0, 1, 2, 3, 4
E, W, N, S = 0, 1, 2, 3
#: opposite face, outward sign along the face's axis, and that axis (0: x, 1: y)
OPPOSITE = np.array([W, E, S, N])
SIGN = np.array([1.0, -1.0, 1.0, -1.0])
AXIS = np.array([0, 0, 1, 1])
_SHIFT = ((0, 1), (0, -1), (1, 0), (-1, 0))

_jit = numba.njit(cache=True, nogil=True)


@dataclass(frozen=True)
class Mesh:
    """Free-cell numbering and face classification of a layout.

    Attributes:
        h: cell size, m (a face has area ``h`` per metre of depth).
        free: ``(H, W)`` bool, the free cells.
        index: ``(H, W)`` number of each free cell, -1 in solid cells.
        cells: ``(n, 2)`` grid position ``(i, j)`` of each unknown.
        nb: ``(n, 4)`` neighbour across each face, -1 unless ``INTERNAL``.
        ft: ``(n, 4)`` face types.
    """

    h: float
    free: np.ndarray
    index: np.ndarray
    cells: np.ndarray
    nb: np.ndarray
    ft: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape

    @property
    def n(self) -> int:
        return int(self.cells.shape[0])

    def field(self, values: np.ndarray, fill: float = 0.0) -> np.ndarray:
        """Grid fields ``(..., H, W)`` from per-cell values ``(..., n)``."""
        out = np.full((*values.shape[:-1], *self.shape), fill, dtype=np.float64)
        out[..., self.free] = values
        return out

    def values(self, field: np.ndarray) -> np.ndarray:
        """Per-cell values ``(..., n)`` of grid fields ``(..., H, W)``."""
        return np.ascontiguousarray(field[..., self.free], dtype=np.float64)


def build_mesh(layout: Layout) -> Mesh:
    """Number the free cells of ``layout`` and classify their faces."""
    mesh = closed_mesh(layout.free, layout.resolution)
    H, Wd = mesh.shape
    ii, jj = mesh.cells[:, 0], mesh.cells[:, 1]
    ft = mesh.ft.copy()
    outside = (jj == Wd - 1, jj == 0, ii == H - 1, ii == 0)  # cells whose face E, W, N, S is the map's edge
    for d, side in enumerate(("east", "west", "north", "south")):
        for openings, code in ((layout.inlets, INLET), (layout.outlets, OUTLET)):
            on_opening = np.zeros((H, Wd), dtype=bool)  # boundary cells whose face d is open
            for o in openings:
                if o.side == side:
                    on_opening[o.cells(layout.grid)] = True
            ft[outside[d] & on_opening[ii, jj], d] = code
    return Mesh(mesh.h, mesh.free, mesh.index, mesh.cells, mesh.nb, ft)


def closed_mesh(free: np.ndarray, h: float) -> Mesh:
    """Number the ``free`` cells ``(H, W)`` of a map of cell size ``h`` (m); every face that is not
    internal is a wall (a map without openings)."""
    free = np.asarray(free, dtype=bool)
    H, Wd = free.shape
    index = np.full((H, Wd), -1, dtype=np.int64)
    ii, jj = np.nonzero(free)
    index[ii, jj] = np.arange(ii.size)
    n = ii.size
    nb = np.full((n, 4), -1, dtype=np.int64)
    ft = np.full((n, 4), WALL, dtype=np.int8)
    for d, (di, dj) in enumerate(_SHIFT):
        ni, nj = ii + di, jj + dj
        inside = (ni >= 0) & (ni < H) & (nj >= 0) & (nj < Wd)
        nbr = np.full(n, -1, dtype=np.int64)
        nbr[inside] = index[ni[inside], nj[inside]]
        internal = nbr >= 0
        nb[internal, d] = nbr[internal]
        ft[internal, d] = INTERNAL
    return Mesh(float(h), free, index, np.stack([ii, jj], axis=1), nb, ft)


def parts(mesh: Mesh) -> tuple[np.ndarray, int]:
    """The 4-connected parts of the free cells (:func:`~dgse.world.generate.free_components`):
    ``(labels (n,), count)``, labels ``0 .. count-1``."""
    from dgse.world.generate import free_components  # imported here: few meshes need it

    grid_labels, count = free_components((~mesh.free).astype(np.uint8))
    return grid_labels[mesh.cells[:, 0], mesh.cells[:, 1]] - 1, count


def unreached(mesh: Mesh, face_type: int) -> np.ndarray:
    """``bool (n,)``: the free cells whose part (:func:`parts`) has no face of ``face_type``.

    A Dirichlet condition on the faces of ``face_type`` (the outlet pressure, the inlet
    concentration) does not reach these cells: the equation of such a part (a closed room, a
    free cell walled in on all sides) is singular, its solution fixed only up to a constant.
    """
    has = (mesh.ft == face_type).any(axis=1)
    if mesh.n == 0:
        return has
    labels, count = parts(mesh)
    reached = np.zeros(count, dtype=bool)
    reached[labels[has]] = True
    return ~reached[labels]


def anchors(mesh: Mesh, face_type: int) -> np.ndarray:
    """``bool (n,)``: one cell (the lowest-numbered) of each part of the free cells that has no face
    of ``face_type`` (:func:`unreached`), where a solver fixes its unknown to make the part regular."""
    loose = unreached(mesh, face_type)
    out = np.zeros(mesh.n, dtype=bool)
    if loose.any():
        labels, _ = parts(mesh)
        cells = np.flatnonzero(loose)
        _, first = np.unique(labels[cells], return_index=True)
        out[cells[first]] = True
    return out


class StencilMatrix:
    """CSR matrices ``aP phi_P - sum a phi_nb`` on a fixed pattern built once per mesh."""

    def __init__(self, mesh: Mesh) -> None:
        n = mesh.n
        rows = [np.arange(n)]
        cols = [np.arange(n)]
        flat = [np.arange(n)]  # where each entry's value sits in [aP, a.ravel()]
        for d in range(4):
            m = mesh.nb[:, d] >= 0
            rows.append(np.nonzero(m)[0])
            cols.append(mesh.nb[m, d])
            flat.append(n + 4 * np.nonzero(m)[0] + d)
        r = np.concatenate(rows)
        c = np.concatenate(cols)
        tmpl = sp.csr_matrix((np.arange(r.size, dtype=np.float64) + 1.0, (r, c)), shape=(n, n))
        tmpl.sort_indices()
        # where each entry's value sits in [aP, -a.ravel()]: the diagonal takes aP, the others -a
        self._gather = np.concatenate(flat)[(tmpl.data - 1.0).astype(np.int64)]
        self._indices = tmpl.indices
        self._indptr = tmpl.indptr
        self.n = n

    def assemble(self, aP: np.ndarray, a: np.ndarray) -> sp.csr_matrix:
        data = np.concatenate([aP, -a.ravel()])[self._gather]
        return sp.csr_matrix((data, self._indices.copy(), self._indptr.copy()), shape=(self.n, self.n))


# ----------------------------------------------------------------------------------------
# compiled kernels
# ----------------------------------------------------------------------------------------
@_jit
def gradient(phi, bval, fixed, nb, ft, h, limited):
    """Gauss linear cell gradient ``(n, 2)``; boundary faces take ``bval`` where
    ``fixed`` and the cell value otherwise; ``limited`` applies OpenFOAM's
    ``cellLimited`` (limiter 1) per component."""
    n = phi.shape[0]
    g = np.zeros((n, 2))
    for c in range(n):
        fv0 = 0.0
        fv1 = 0.0
        fv2 = 0.0
        fv3 = 0.0
        vmax = phi[c]
        vmin = phi[c]
        for d in range(4):
            t = ft[c, d]
            if t == 1:
                other = phi[nb[c, d]]
                v = 0.5 * (phi[c] + other)
                vmax = max(vmax, other)
                vmin = min(vmin, other)
            elif fixed[c, d]:
                v = bval[c, d]
                vmax = max(vmax, v)
                vmin = min(vmin, v)
            else:
                v = phi[c]
            if d == 0:
                fv0 = v
            elif d == 1:
                fv1 = v
            elif d == 2:
                fv2 = v
            else:
                fv3 = v
        gx = (fv0 - fv1) / h
        gy = (fv2 - fv3) / h
        if limited:
            dmax = vmax - phi[c]
            dmin = vmin - phi[c]
            for k in range(2):
                gk = gx if k == 0 else gy
                ext = abs(gk) * 0.5 * h
                lim = 1.0
                if ext > dmax + 1e-300:
                    lim = min(lim, dmax / ext)
                if -ext < dmin - 1e-300:
                    lim = min(lim, dmin / (-ext))
                if k == 0:
                    gx = gx * lim
                else:
                    gy = gy * lim
        g[c, 0] = gx
        g[c, 1] = gy
    return g


@_jit
def assemble(F, gamma, fixed, gamma_b, nb, ft, bounded):
    """Upwind convection + central diffusion of ``div(F phi) - div(gamma grad phi)``.

    Returns ``aP (n,)``, ``a (n, 4)`` and ``cb (n, 4)``: the source of a fixed
    boundary value ``phi_b`` on face ``d`` is ``cb[c, d] * phi_b``.  Zero-gradient
    boundaries carry the cell value out (``aP += F``).  ``bounded`` takes the
    cell's continuity error off the diagonal (OpenFOAM's ``bounded Gauss``).
    """
    n = F.shape[0]
    aP = np.zeros(n)
    a = np.zeros((n, 4))
    cb = np.zeros((n, 4))
    for c in range(n):
        net = 0.0
        for d in range(4):
            t = ft[c, d]
            f = F[c, d]
            if t == 1:
                gf = 0.5 * (gamma[c] + gamma[nb[c, d]])
                a[c, d] = gf + max(-f, 0.0)
                aP[c] += gf + max(f, 0.0)
                net += f
            elif t >= 2:
                net += f
                if fixed[c, d]:
                    gb = 2.0 * gamma_b[c, d]
                    aP[c] += gb
                    cb[c, d] = gb - f
                else:
                    aP[c] += f
        if bounded:
            aP[c] -= net
    return aP, a, cb


@_jit
def boundary_gamma(gamma, inlet, gamma_inlet, wall, gamma_wall):
    """``(n, 4)`` face diffusivities for :func:`assemble`'s ``gamma_b``: ``gamma_wall[c]`` on
    the faces ``wall`` marks, else ``gamma_inlet`` on those ``inlet`` marks, else the cell's own
    ``gamma[c]`` (one pass instead of NumPy's nested ``where`` on ``(n, 4)`` arrays)."""
    n = gamma.shape[0]
    out = np.empty((n, 4))
    for c in range(n):
        for d in range(4):
            if wall[c, d]:
                out[c, d] = gamma_wall[c]
            elif inlet[c, d]:
                out[c, d] = gamma_inlet
            else:
                out[c, d] = gamma[c]
    return out


@_jit
def pin_cells(cells, aP, a, b, value):
    """Make the rows of ``cells`` read ``x = value`` (``aP = 1``, no neighbours, ``b = value``),
    in place."""
    for c in range(aP.shape[0]):
        if cells[c]:
            aP[c] = 1.0
            b[c] = value[c]
            for d in range(4):
                a[c, d] = 0.0


@_jit
def ho_source(phi, g, F, nb, ft, h):
    """Explicit source turning upwind into linear-upwind convection on internal faces."""
    n = phi.shape[0]
    src = np.zeros(n)
    for c in range(n):
        s = 0.0
        for d in range(4):
            if ft[c, d] != 1:
                continue
            f = F[c, d]
            ax = 0 if d < 2 else 1
            sg = 1.0 if (d == 0 or d == 2) else -1.0
            if f > 0.0:
                s += f * g[c, ax] * sg * 0.5 * h
            else:
                s -= f * g[nb[c, d], ax] * sg * 0.5 * h
        src[c] = -s
    return src


@_jit
def residual_norm(aP, a, b, nb, x):
    """OpenFOAM's normalised residual of ``x`` in ``aP x - sum a x_nb = b``."""
    n = x.shape[0]
    xm = 0.0
    for c in range(n):
        xm += x[c]
    xm /= max(n, 1)
    r = 0.0
    norm = 0.0
    for c in range(n):
        ax = aP[c] * x[c]
        aavg = aP[c] * xm
        for d in range(4):
            j = nb[c, d]
            if j >= 0:
                ax -= a[c, d] * x[j]
                aavg -= a[c, d] * xm
        r += abs(b[c] - ax)
        norm += abs(ax - aavg) + abs(b[c] - aavg)
    return r / (norm + 1e-20)


@_jit
def _gathered(s, a, nb, x, c, k, order):
    """``s`` plus cell ``c``'s neighbour terms ``a[c, d] x[nb[c, d], k]``, added in the face
    order ``order`` (E, W, N, S = 0, 1, 2, 3; missing neighbours skipped)."""
    for d in order:
        j = nb[c, d]
        if j >= 0:
            s += a[c, d] * x[j, k]
    return s


@_jit
def gauss_seidel(aP, a, b, nb, x, rel_tol, max_sweeps, short_chain=False):
    """Symmetric Gauss-Seidel on ``aP x - sum a x_nb = b`` for ``m`` right-hand sides.

    ``b`` and ``x`` are ``(n, m)``; ``x`` is updated in place until every column's
    residual fell by ``rel_tol`` (estimated during the forward sweep) or after
    ``max_sweeps`` symmetric sweeps.  Returns ``(sweeps, initial)``: the sweeps
    done and OpenFOAM's normalised initial residual of each column.

    ``short_chain``: multiply by ``1 / aP`` instead of dividing by ``aP``, and add the
    neighbour the sweep has just updated (west going forward, east going back) last
    rather than second: both shorten the sweep's dependency chain from one cell to the
    next (timings in ``benchmarks/results/solver_speed.md``).  The results differ in the
    last bits (a search driven by the flow can then take another path).
    """
    n, m = x.shape
    initial = np.zeros(m)
    r0 = np.zeros(m)
    for k in range(m):
        xm = 0.0
        for c in range(n):
            xm += x[c, k]
        xm /= max(n, 1)
        norm = 0.0
        for c in range(n):
            ax = aP[c] * x[c, k]
            aavg = aP[c] * xm
            for d in range(4):
                j = nb[c, d]
                if j >= 0:
                    ax -= a[c, d] * x[j, k]
                    aavg -= a[c, d] * xm
            r0[k] += abs(b[c, k] - ax)
            norm += abs(ax - aavg) + abs(b[c, k] - aavg)
        initial[k] = r0[k] / (norm + 1e-20)
    if short_chain:
        return _sweeps_short_chain(aP, a, b, nb, x, rel_tol, max_sweeps, r0), initial
    sweeps = 0
    est = np.empty(m)
    while sweeps < max_sweeps:
        est[:] = 0.0
        for c in range(n):
            for k in range(m):
                s = _gathered(b[c, k], a, nb, x, c, k, (0, 1, 2, 3))
                est[k] += abs(s - aP[c] * x[c, k])
                x[c, k] = s / aP[c]
        if sweeps > 0 and _settled(est, r0, rel_tol):
            break
        for c in range(n - 1, -1, -1):
            for k in range(m):
                x[c, k] = _gathered(b[c, k], a, nb, x, c, k, (0, 1, 2, 3)) / aP[c]
        sweeps += 1
    return sweeps, initial


@_jit
def _settled(est, r0, rel_tol):
    """Every column's residual estimate ``est`` fell to ``rel_tol`` of its initial ``r0``."""
    for k in range(est.shape[0]):
        if est[k] > rel_tol * r0[k]:
            return False
    return True


@_jit
def _sweeps_short_chain(aP, a, b, nb, x, rel_tol, max_sweeps, r0):
    """:func:`gauss_seidel`'s sweeps with ``short_chain``; returns the sweeps done."""
    n, m = x.shape
    sweeps = 0
    est = np.empty(m)
    inv = 1.0 / aP
    while sweeps < max_sweeps:
        est[:] = 0.0
        for c in range(n):
            for k in range(m):
                s = _gathered(b[c, k], a, nb, x, c, k, (0, 2, 3, 1))  # W, updated just before, last
                est[k] += abs(s - aP[c] * x[c, k])
                x[c, k] = s * inv[c]
        if sweeps > 0 and _settled(est, r0, rel_tol):
            break
        for c in range(n - 1, -1, -1):
            for k in range(m):
                x[c, k] = _gathered(b[c, k], a, nb, x, c, k, (1, 2, 3, 0)) * inv[c]  # E last
        sweeps += 1
    return sweeps


@_jit
def face_average(phi, nb, ft):
    """Mean over the four faces of face-interpolated values (cell value on boundaries)."""
    n = phi.shape[0]
    out = np.empty(n)
    for c in range(n):
        s = 0.0
        for d in range(4):
            s += 0.5 * (phi[c] + phi[nb[c, d]]) if ft[c, d] == 1 else phi[c]
        out[c] = 0.25 * s
    return out


@_jit
def row_sum(a):
    """``a.sum(axis=1)`` for ``(n, 4)`` arrays (numpy's axis reduction is slow here)."""
    n = a.shape[0]
    out = np.empty(n)
    for c in range(n):
        out[c] = a[c, 0] + a[c, 1] + a[c, 2] + a[c, 3]
    return out


@_jit
def row_dot(a, b):
    """``(a * b).sum(axis=1)`` for ``(n, 4)`` arrays."""
    n = a.shape[0]
    out = np.empty(n)
    for c in range(n):
        out[c] = a[c, 0] * b[c, 0] + a[c, 1] * b[c, 1] + a[c, 2] * b[c, 2] + a[c, 3] * b[c, 3]
    return out


@_jit
def neighbour_sum(a, x, nb):
    """``sum_d a[:, d] x[nb[:, d]]`` over internal faces."""
    n = a.shape[0]
    out = np.zeros(n)
    for c in range(n):
        for d in range(4):
            j = nb[c, d]
            if j >= 0:
                out[c] += a[c, d] * x[j]
    return out


@_jit
def relax(aP, a, b, phi, alpha):
    """OpenFOAM's implicit under-relaxation (diagonal dominance enforced first):
    returns the relaxed diagonal and source."""
    n = aP.shape[0]
    D = np.empty(n)
    out = np.empty(n)
    for c in range(n):
        off = abs(a[c, 0]) + abs(a[c, 1]) + abs(a[c, 2]) + abs(a[c, 3])
        D[c] = max(abs(aP[c]), off) / alpha
        out[c] = b[c] + (D[c] - aP[c]) * phi[c]
    return D, out


def bound(phi: np.ndarray, nb: np.ndarray, ft: np.ndarray, minimum: float) -> np.ndarray:
    """OpenFOAM's ``bound``: values below ``minimum`` become the local face average."""
    low = phi < minimum
    if not low.any():
        return phi
    avg = face_average(np.maximum(phi, minimum), nb, ft)
    return np.where(low, np.maximum(avg, minimum), phi)
