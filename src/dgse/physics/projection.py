"""A given mean wind field made into a flow the gas transport can use.

Users with their own CFD (knowledge level ``wind``, :mod:`dgse.belief.knowledge`)
have a cell-centred mean wind on the map, often a 3-D flow sliced to 2-D:
it does not conserve mass on the 2-D grid, and it comes without the
turbulence fields the transport needs.  This module turns it into

1. **face fluxes** ``F (n, 4)`` (outward, m^2/s per m depth, the convention of
   :mod:`dgse.physics.fv`): the wind linearly interpolated to every internal
   face, the cell's own wind at open boundary faces, 0 through walls;
2. **mass-conserving face fluxes**: the smallest correction ``F' = F + c (phi_P -
   phi_N)`` (a discrete gradient of a potential ``phi``) that makes every cell's
   net outflow zero: ``L phi = -div F`` with ``L`` the graph Laplacian of the
   free cells, ``c = 1`` across internal faces and ``c = 2`` at open boundary
   faces (``phi = 0`` half a cell outside).  A field that already conserves
   mass is left unchanged (``div F = 0`` gives ``phi = 0``);
2b. **or a slice of a 3-D flow** (``through_slice``; by default where the map
   has no open face at all, a walled map edge as a GADEN import has): the air
   then enters and leaves through the slice, so the field's own divergence
   is kept as a through-slice exchange instead of being projected away.  The
   fluxes of point 1 already satisfy the wall (no-penetration) conditions, and
   among the fluxes that do, with the divergence prescribed as a source, the
   nearest is these fluxes themselves (the correction of point 2 with
   ``L phi = 0``): ``F' = F``, ``q = div F'`` per cell (``q > 0``: air enters
   through the slice, ``q < 0``: it leaves).  Mass is conserved exactly: the
   net exchange ``sum q`` is the net outflow through the open faces (0 on a
   closed map; internal faces cancel).  The gas transport takes the leaving
   air as a sink ``max(-q, 0) c`` (the gas goes with the air, at the cell's
   concentration) and the entering air as clean (:mod:`dgse.physics.transport`);
3. **open boundaries**: with the openings known, only their faces are open;
   without them a free cell's face on the map's edge is open where the
   field's normal wind there is at least ``open_fraction`` (0.75) times the
   mean speed (the rest of the edge is a wall: edge cells beside real walls
   carry small normal winds that would otherwise become clean-air inlets).
   After the projection an open face with outflow is an ``OUTLET`` of the
   transport and one with inflow an ``INLET`` (clean air, ``c = 0``), as the
   field says;
4. **an eddy diffusivity** from a stated closure: by default the standard
   k-epsilon model with wall functions solved on the frozen projected flow
   (:func:`dgse.physics.rans.solve_turbulence`: the spec's own turbulence
   model, inlet turbulence from the mean inflow speed); or the algebraic
   mixing-length closure :func:`mixing_length_nut` (``nu_t = C_mu^(1/4)
   sqrt(k) l``, ``k = 3/2 (I U)^2``, ``l = min(kappa d_wall, 0.07 x the
   hydraulic width)``), or a ``nu_t`` the user gives.  The frozen k-epsilon
   iterates to :data:`TURBULENCE_TOLERANCE` (1e-6), a hundred times tighter
   than a flow solve's residual criterion: it starts from the inlet's
   turbulence everywhere, and in quiet rooms, where production is tiny, ``k``
   and ``epsilon`` decay so slowly that the normalised residuals pass 1e-4
   long before they have (test scenario 2005, a nearly laminar flow: median
   ``nu_t`` 21 times the coupled solve's at 1e-4, 1.7 times at 1e-6; the
   plume on its own flow 1.23 off in log(1 + ppm) RMSE against 0.15;
   ``python benchmarks/phys.py turbulence``).

On validation scenarios 900-907 (``python benchmarks/phys.py projection``)
the tighter tolerance took the plume on the projected wind from 0.024 to
0.021 in log(1 + ppm) RMSE with the openings known and from 0.047 to 0.044
with them taken from the wind, for about twice the time (2.0-2.5 s a map
with the gas solves); on the coupled flows of 900-911 the frozen solve's
plume was within 0.043 of the coupled one's at 1e-4 and 0.017 at 1e-6.

Everything here is a pure function of arrays; :func:`transport_from_wind`
builds the :class:`~dgse.physics.transport.TransportSolver` from the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage
from scipy.sparse.csgraph import connected_components

from dgse.errors import InputDataError
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.fv import AXIS, INLET, INTERNAL, OUTLET, SIGN, WALL, Mesh, build_mesh, closed_mesh
from dgse.physics.rans import FlowSettings, solve_turbulence
from dgse.physics.transport import TransportSolver
from dgse.world.case import WALL_WIND_TOLERANCE, wind_problem
from dgse.world.layout import Layout

__all__ = [
    "ProjectedFlow",
    "divergence",
    "edge_mesh",
    "face_fluxes",
    "mixing_length_nut",
    "project_fluxes",
    "project_wind",
    "smoothed_exchange",
    "transport_from_wind",
]

#: Turbulence intensity of the closure (the spec's inlet value).
DEFAULT_INTENSITY = 0.05
#: von Karman constant.
KAPPA = 0.41
#: ``C_mu`` of the standard k-epsilon model.
C_MU = 0.09
#: Mixing-length cap as a fraction of the hydraulic width (the spec's inlet length scale).
LENGTH_FRACTION = 0.07
#: Open boundary faces (before they are split into inlets and outlets by the flow).
OPEN = INLET
#: Without the openings, an edge face is open where the normal wind is at least this fraction
#: of the mean speed: chosen on generated validation scenarios (``python benchmarks/phys.py projection``).
DEFAULT_OPEN_FRACTION = 0.75
#: Residual criterion of the frozen k-epsilon (module docstring, point 4).
TURBULENCE_TOLERANCE = 1e-6
#: Its iteration cap (validation 907 and 909 reach it on their coupled flows, plumes within 0.002).
TURBULENCE_ITERATIONS = 5000
#: Relative cell imbalance (to the largest face flux) taken as round-off.
BALANCED = 1e-12


def edge_mesh(
    occupancy: np.ndarray, resolution: float, wind: np.ndarray | None = None, open_fraction: float = 0.0
) -> Mesh:
    """The mesh of a map whose openings are unknown: free cells' faces on the map's edge are open.

    With ``wind`` given, an edge face is open only where the wind's normal
    component there is at least ``open_fraction`` times the mean speed over
    the free cells (the rest of the edge is a wall: a 2-D slice's edge cells
    beside real walls carry small, noisy normal winds that would otherwise
    become clean-air inlets).  Open faces carry the code :data:`OPEN` until
    :func:`project_wind` splits them into inlets and outlets.
    """
    occ = np.asarray(occupancy)
    H, W = occ.shape
    mesh = closed_mesh(occ == 0, resolution)
    ft = mesh.ft.copy()
    ii, jj = mesh.cells[:, 0], mesh.cells[:, 1]
    on_edge = (jj == W - 1, jj == 0, ii == H - 1, ii == 0)  # E, W, N, S
    keep = np.ones(mesh.n, dtype=bool)
    if wind is not None and open_fraction > 0:
        u = mesh.values(np.asarray(wind, dtype=np.float64))
        threshold = open_fraction * float(np.hypot(u[0], u[1]).mean()) if mesh.n else 0.0
    for d in range(4):
        if wind is not None and open_fraction > 0:
            keep = np.abs(u[AXIS[d]]) >= threshold
        ft[on_edge[d] & keep, d] = OPEN
    return replace(mesh, ft=ft)


def face_fluxes(mesh: Mesh, wind: np.ndarray) -> np.ndarray:
    """``(n, 4)`` outward face fluxes of the cell-centred ``wind`` (``(2, H, W)``, m/s).

    Internal faces: the mean of the two cells' normal components; open faces
    (``INLET``/``OUTLET``): the cell's own; walls: 0.  Times the face area ``h``.
    """
    w = np.asarray(wind, dtype=np.float64)
    if w.shape != (2, *mesh.shape):
        raise InputDataError(f"wind has shape {w.shape}; the map needs {(2, *mesh.shape)}")
    u = mesh.values(w)  # (2, n)
    n = mesh.n
    F = np.zeros((n, 4))
    for d in range(4):
        un = SIGN[d] * u[AXIS[d]]
        nb = mesh.nb[:, d]
        inn = mesh.ft[:, d] == INTERNAL
        face = np.where(inn, 0.5 * (un + np.where(inn, SIGN[d] * u[AXIS[d]][np.maximum(nb, 0)], 0.0)), un)
        open_face = (mesh.ft[:, d] == INLET) | (mesh.ft[:, d] == OUTLET)
        F[:, d] = np.where(inn | open_face, face, 0.0) * mesh.h
    return F


def divergence(F: np.ndarray) -> np.ndarray:
    """``(n,)`` net volume outflow of every cell (m^2/s per m depth): 0 where mass is conserved."""
    return np.asarray(F).sum(axis=1)


def _laplacian(mesh: Mesh, open_weight: float) -> sp.csr_matrix:
    """The free cells' graph Laplacian: 1 per internal face, ``open_weight`` per open face."""
    n, ft, nb = mesh.n, mesh.ft, mesh.nb
    internal = ft == INTERNAL
    open_face = (ft == INLET) | (ft == OUTLET)
    rows = [np.arange(n)]
    cols = [np.arange(n)]
    vals = [internal.sum(axis=1) + open_weight * open_face.sum(axis=1).astype(np.float64)]
    for d in range(4):
        m = internal[:, d]
        rows.append(np.nonzero(m)[0])
        cols.append(nb[m, d])
        vals.append(-np.ones(int(m.sum())))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


def project_fluxes(
    mesh: Mesh, F: np.ndarray, target: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(F', phi)``: the face fluxes nearest ``F`` whose divergence is ``target`` (default 0:
    mass-conserving), and the potential of the correction.

    ``F'[P, d] = F[P, d] + c_d (phi_P - phi_N)`` with ``c = 1`` across internal
    faces and ``c = 2`` at open faces (``phi = 0`` outside); walls stay closed.
    In every connected part without an open face (a closed room) ``phi`` is fixed at one
    cell, and ``target`` must sum there to ``F``'s divergence (a closed part's net source
    is 0).  Fluxes whose largest cell imbalance is below :data:`BALANCED` times the largest
    flux already have the divergence and come back unchanged.
    """
    F = np.asarray(F, dtype=np.float64)
    n = mesh.n
    ft, nb = mesh.ft, mesh.nb
    internal = ft == INTERNAL
    open_face = (ft == INLET) | (ft == OUTLET)
    L = _laplacian(mesh, 2.0).tocoo()
    b = (np.zeros(n) if target is None else np.asarray(target, dtype=np.float64)) - divergence(F)
    parts, label = connected_components(_laplacian(mesh, 0.0), directed=False)
    opened = np.bincount(label, weights=open_face.any(axis=1), minlength=parts) > 0
    scale = float(np.abs(F).max()) if F.size else 0.0
    closed = ~opened[label]
    for k in np.unique(label[closed]):
        net = float(b[label == k].sum())
        if abs(net) > 1e-9 * max(scale, float(np.abs(b).max())) * max(1, int((label == k).sum())):
            raise InputDataError(f"a closed part of the map would need a net source of {net:.3g} m^2/s")
    pinned = np.zeros(n, dtype=bool)
    if closed.any():
        first = np.unique(label[closed], return_index=True)[1]
        pinned[np.nonzero(closed)[0][first]] = True
        keep = ~pinned[L.row]
        idx = np.nonzero(pinned)[0]
        L = sp.coo_matrix(
            (np.concatenate([L.data[keep], np.ones(idx.size)]),
             (np.concatenate([L.row[keep], idx]), np.concatenate([L.col[keep], idx]))),
            shape=(n, n),
        )  # fmt: skip
        b[pinned] = 0.0
    if not np.any(b) or float(np.abs(b).max()) <= BALANCED * scale:
        return F.copy(), np.zeros(n)  # already of that divergence (to round-off): unchanged
    phi = spla.spsolve(L.tocsc(), b)
    Fp = F.copy()
    for d in range(4):
        m = internal[:, d]
        Fp[m, d] += phi[m] - phi[nb[m, d]]
        o = open_face[:, d]
        Fp[o, d] += 2.0 * phi[o]
    return Fp, phi


def smoothed_exchange(mesh: Mesh, q: np.ndarray, length: float) -> np.ndarray:
    """``(I + (length / h)^2 L)^-1 q``: the exchange ``q`` (n,) smoothed over about ``length``
    metres along the free cells (``L`` the internal faces' graph Laplacian, so each connected
    part keeps its sum exactly); ``length = 0``: ``q`` itself."""
    q = np.asarray(q, dtype=np.float64)
    if length <= 0:
        return q.copy()
    M = sp.identity(mesh.n, format="csr") + (length / mesh.h) ** 2 * _laplacian(mesh, 0.0)
    return spla.spsolve(M.tocsc(), q)


def _cell_wind(mesh: Mesh, F: np.ndarray) -> np.ndarray:
    """``(2, H, W)`` cell-centred wind of face fluxes (mean of the opposite faces' normal velocities)."""
    u = np.zeros((2, mesh.n))
    cnt = np.zeros((2, mesh.n))
    for d in range(4):
        closed = mesh.ft[:, d] == WALL
        vel = SIGN[d] * F[:, d] / mesh.h
        u[AXIS[d]] += np.where(closed, 0.0, vel)
        cnt[AXIS[d]] += ~closed
    u = np.where(cnt > 0, u / np.maximum(cnt, 1), 0.0)
    return mesh.field(u)


def mixing_length_nut(
    occupancy: np.ndarray,
    resolution: float,
    wind: np.ndarray,
    intensity: float = DEFAULT_INTENSITY,
    floor_fraction: float = 0.5,
) -> np.ndarray:
    """``(H, W)`` eddy viscosity ``nu_t`` (m^2/s) of the mixing-length closure (module docstring).

    0 on walls; the speed is floored at ``floor_fraction`` times the mean speed.
    """
    occ = np.asarray(occupancy) != 0
    free = ~occ
    h = float(resolution)
    w = np.asarray(wind, dtype=np.float64)
    speed = np.hypot(w[0], w[1])
    mean_speed = float(speed[free].mean()) if free.any() else 0.0
    U = np.maximum(speed, floor_fraction * mean_speed)
    # distance to the nearest solid cell or to the map's edge, m (cell centres)
    padded = np.pad(free, 1, constant_values=False)
    d_wall = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * h - 0.5 * h
    d_wall = np.maximum(d_wall, 0.5 * h)
    width = 2.0 * float(np.percentile(d_wall[free], 90)) if free.any() else h
    length = np.minimum(KAPPA * d_wall, LENGTH_FRACTION * width)
    k = 1.5 * (intensity * U) ** 2
    nut = C_MU**0.25 * np.sqrt(k) * length
    return np.where(free, nut, 0.0)


@dataclass(frozen=True, eq=False)
class ProjectedFlow:
    """A given wind made mass-conserving on its map.

    Attributes:
        mesh: the free cells, with the open faces split into inlets and outlets by the flow.
        F: ``(n, 4)`` mass-conserving outward face fluxes.
        wind: ``(2, H, W)`` cell-centred wind of ``F``.
        nut: ``(H, W)`` eddy viscosity, m^2/s.
        info: ``correction`` (relative L2 change of the face fluxes), ``max_divergence``
            before and after (m^2/s), the open faces, the closure, the through-slice
            exchange (``slice_inflow``/``slice_outflow``, m^2/s per m depth).
        slice_flux: ``(n,)`` air entering the cell through the slice (m^2/s per m depth,
            negative where it leaves; the fluxes' divergence), or None for a 2-D flow
            (module docstring, point 2b).
    """

    mesh: Mesh
    F: np.ndarray
    wind: np.ndarray
    nut: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
    slice_flux: np.ndarray | None = None

    @property
    def slice_sink(self) -> np.ndarray | None:
        """``(n,)`` air leaving each cell through the slice (``max(-slice_flux, 0)``), or None."""
        return None if self.slice_flux is None else np.maximum(-self.slice_flux, 0.0)


def project_wind(
    occupancy: np.ndarray,
    resolution: float,
    wind: np.ndarray,
    layout: Layout | None = None,
    *,
    nut: np.ndarray | None = None,
    closure: str = "k-epsilon",
    intensity: float = DEFAULT_INTENSITY,
    floor_fraction: float = 0.5,
    open_fraction: float = DEFAULT_OPEN_FRACTION,
    physics: Physics = DEFAULT_PHYSICS,
    turbulence_tolerance: float = TURBULENCE_TOLERANCE,
    through_slice: bool | None = None,
    slice_smoothing: float = 0.0,
) -> ProjectedFlow:
    """Make ``wind`` a mass-conserving flow on the map (module docstring).

    Args:
        occupancy: ``(H, W)`` map, 1 solid.
        resolution: cell size, m.
        wind: ``(2, H, W)`` cell-centred mean wind, m/s, 0 in solid cells.
        layout: the map with its openings (only their faces are open); None: every
            free cell's face on the map's edge is open.
        nut: ``(H, W)`` eddy viscosity to use instead of the closure, m^2/s.
        intensity, floor_fraction: the closure's (:func:`mixing_length_nut`).
        open_fraction: without a layout, an edge face is open where the normal wind is at
            least this fraction of the mean speed (:func:`edge_mesh`).
        turbulence_tolerance: the frozen k-epsilon's residual criterion (module docstring).
        through_slice: keep the field's divergence as an exchange through the slice (module
            docstring, point 2b) instead of projecting it away; None: where the map has no
            open face (its edge is walled everywhere).
        slice_smoothing: with the exchange through the slice, smooth it over about this many
            metres first (:func:`smoothed_exchange`; 0: the field's own divergence).

    Raises:
        InputDataError: a wind of the wrong shape, not finite, or with flow in solid cells;
            a layout of another map.
    """
    occ = np.asarray(occupancy)
    res = float(resolution)
    if occ.ndim != 2:
        raise InputDataError(f"occupancy must be 2-D, got shape {occ.shape}")
    if not (res > 0 and math.isfinite(res)):
        raise InputDataError(f"resolution must be positive, got {resolution}")
    w = np.asarray(wind, dtype=np.float64)
    problem = wind_problem(occ, w, "wind field", WALL_WIND_TOLERANCE)
    if problem:
        raise InputDataError(problem)
    solid = occ != 0
    if layout is not None:
        if layout.occupancy.shape != occ.shape or not np.array_equal(layout.occupancy != 0, solid):
            raise InputDataError("the layout's map differs from the wind's map")
        mesh = build_mesh(layout)
    else:
        mesh = edge_mesh(occ, res, w, open_fraction)
        fraction = open_fraction
        edge_free = bool(np.any(edge_mesh(occ, res).ft == OPEN))
        while edge_free and not ((mesh.ft == OPEN).any()) and fraction > 1e-3:  # keep one open face
            fraction /= 2.0
            mesh = edge_mesh(occ, res, w, fraction)
    open_face = (mesh.ft == INLET) | (mesh.ft == OUTLET)
    slice_mode = bool(not open_face.any() if through_slice is None else through_slice)
    F0 = face_fluxes(mesh, w)
    if slice_mode:  # the wall-consistent fluxes with their own divergence as the source (point 2b)
        target = smoothed_exchange(mesh, divergence(F0), slice_smoothing)
        F, _ = project_fluxes(mesh, F0, target)
        slice_flux = divergence(F)
    else:
        F, _ = project_fluxes(mesh, F0)
        slice_flux = None
    # open faces: outflow is an outlet, inflow an inlet (clean air), as the projected flow says
    ft = mesh.ft.copy()
    ft[open_face & (F > 0)] = OUTLET
    ft[open_face & (F <= 0)] = INLET
    mesh = replace(mesh, ft=ft)
    norm = float(np.linalg.norm(F0))
    cell_wind = _cell_wind(mesh, F)
    turb_info: dict[str, Any] = {}
    if nut is not None:
        nut_field = np.asarray(nut, float)
    elif closure == "k-epsilon":
        u = mesh.values(cell_wind)
        if not (0 < turbulence_tolerance < 1):
            raise InputDataError(f"turbulence_tolerance must be in (0, 1), got {turbulence_tolerance}")
        settings = FlowSettings(tolerance=turbulence_tolerance, max_iterations=TURBULENCE_ITERATIONS)
        _, _, nut_cells, turb_info = solve_turbulence(mesh, u[0], u[1], F, physics, settings)
        nut_field = mesh.field(nut_cells)
    elif closure == "mixing-length":
        nut_field = mixing_length_nut(occ, res, cell_wind, intensity, floor_fraction)
    else:
        raise InputDataError(f"unknown closure {closure!r}; use k-epsilon or mixing-length")
    if nut_field.shape != occ.shape or not np.isfinite(nut_field).all() or (nut_field < 0).any():
        raise InputDataError(f"nut must be finite, non-negative and (H, W); got shape {nut_field.shape}")
    info = {
        "correction": float(np.linalg.norm(F - F0)) / norm if norm > 0 else 0.0,
        "max_divergence_before": float(np.abs(divergence(F0)).max()) if mesh.n else 0.0,
        "max_divergence_after": float(np.abs(divergence(F)).max()) if mesh.n and not slice_mode else 0.0,
        "open_faces": "openings of the layout" if layout is not None else "every free face on the map's edge",
        "through_slice": slice_mode,
        "slice_inflow": float(np.maximum(slice_flux, 0.0).sum()) if slice_flux is not None else 0.0,
        "slice_outflow": float(np.maximum(-slice_flux, 0.0).sum()) if slice_flux is not None else 0.0,
        "inlet_faces": int((ft == INLET).sum()),
        "outlet_faces": int((ft == OUTLET).sum()),
        "closure": "given nu_t" if nut is not None else closure,
        "turbulence": turb_info,
    }
    return ProjectedFlow(mesh, F, cell_wind, nut_field, info, slice_flux)


def transport_from_wind(flow: ProjectedFlow, physics: Physics = DEFAULT_PHYSICS) -> TransportSolver:
    """The gas transport operator on a projected flow (``D_eff = D_m + nu_t / Sc_t``; the air
    leaving through the slice takes its gas with it, module docstring point 2b).

    Raises:
        InputDataError: a flow that gives the gas no way out (no open face and no air leaving
            through the slice: a closed room has no steady plume).
    """
    sink = flow.slice_sink
    open_face = (flow.mesh.ft == INLET) | (flow.mesh.ft == OUTLET)
    if not open_face.any() and (sink is None or not (sink > 0).any()):
        raise InputDataError(
            "the wind gives the gas no way out: the map has no open face and no air leaves through "
            "the slice (a closed room has no steady plume)"
        )
    return TransportSolver.build(flow.mesh, flow.F, flow.mesh.values(flow.nut), physics, sink=sink)
