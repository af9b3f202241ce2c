"""A given wind made a mass-conserving flow with an eddy viscosity (dgse.physics.projection)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.physics.fv import INLET, OUTLET, WALL
from dgse.physics.projection import (
    divergence,
    edge_mesh,
    face_fluxes,
    project_fluxes,
    project_wind,
    smoothed_exchange,
    transport_from_wind,
)
from dgse.physics.scenario import solve_cases
from tests.conftest import two_rooms
from tests.walled_slice import walled_fields


@pytest.fixture(scope="module")
def case():
    return solve_cases(two_rooms(), 1.0, [((2.05, 0.55), 0.8)])[0]


def _noisy(case, seed=0):
    rng = np.random.default_rng(seed)
    w = case.wind * (1.0 + 0.3 * rng.standard_normal(case.wind.shape)) + 0.05 * rng.standard_normal(
        case.wind.shape
    )
    return np.where(case.occupancy == 1, 0.0, w)


@pytest.mark.parametrize("openings", [True, False])
def test_every_cell_is_mass_balanced(case, openings):
    flow = project_wind(case.occupancy, case.resolution, _noisy(case), case.layout if openings else None)
    scale = np.abs(flow.F).max()
    assert np.abs(divergence(flow.F)).max() < 1e-10 * scale
    assert flow.info["max_divergence_before"] > 1e3 * flow.info["max_divergence_after"]
    # internal faces: the two cells see opposite fluxes; walls carry none
    m = flow.mesh
    for d, opp in ((0, 1), (1, 0), (2, 3), (3, 2)):
        inn = m.nb[:, d] >= 0
        assert np.allclose(flow.F[inn, d], -flow.F[m.nb[inn, d], opp])
    assert np.all(flow.F[m.ft == WALL] == 0)
    # open faces are split by the projected flow: inflow faces are inlets, outflow faces outlets
    assert np.all(flow.F[m.ft == INLET] <= 0) and np.all(flow.F[m.ft == OUTLET] > 0)
    assert flow.info["inlet_faces"] > 0 and flow.info["outlet_faces"] > 0


def test_a_divergence_free_field_is_unchanged(case):
    once = project_wind(case.occupancy, case.resolution, _noisy(case, 1), case.layout)
    again, phi = project_fluxes(once.mesh, once.F)
    assert np.array_equal(again, once.F) and not phi.any()
    # a uniform wind through an empty room with every edge open already conserves mass
    occ = np.zeros((12, 20), np.uint8)
    wind = np.stack([np.full(occ.shape, 0.7), np.full(occ.shape, -0.2)])
    mesh = edge_mesh(occ, 0.1)
    F = face_fluxes(mesh, wind)
    assert np.abs(divergence(F)).max() < 1e-14
    flow = project_wind(occ, 0.1, wind, open_fraction=0.0)
    assert flow.info["correction"] < 1e-12
    assert np.allclose(flow.wind, wind)


def test_a_closed_room_is_projected_too():
    occ = np.zeros((10, 10), np.uint8)
    rng = np.random.default_rng(2)
    wind = rng.standard_normal((2, 10, 10)) * 0.1
    mesh = edge_mesh(occ, 0.1)
    closed = replace(mesh, ft=np.where(mesh.ft == INLET, WALL, mesh.ft))
    F, _ = project_fluxes(closed, face_fluxes(closed, wind))
    assert np.abs(divergence(F)).max() < 1e-12


def test_the_k_epsilon_closure_gives_back_the_plume(case):
    """The RANS wind of a built-in case, projected, with k-epsilon on it: the case's own plume."""
    src = case.layout.grid.cell_of(*case.source)
    free = case.free

    def log_rmse(flow):
        ts = transport_from_wind(flow)
        c = ts.solve_cells([src], [case.release_rate])[0] * ts.physics.ppm_per_gm3
        return float(np.sqrt(np.mean((np.log1p(np.maximum(c, 0)) - np.log1p(case.concentration))[free] ** 2)))

    known = project_wind(case.occupancy, case.resolution, case.wind, case.layout)
    assert known.info["closure"] == "k-epsilon" and known.info["turbulence"]["converged"]
    assert log_rmse(known) < 0.1
    unknown = project_wind(case.occupancy, case.resolution, case.wind)  # openings from the wind
    assert log_rmse(unknown) < 0.3
    # the algebraic closure is a stated, cruder option
    ml = project_wind(case.occupancy, case.resolution, case.wind, case.layout, closure="mixing-length")
    assert ml.info["closure"] == "mixing-length" and np.all(ml.nut[free] > 0)


def test_frozen_turbulence_decays_in_quiet_rooms():
    """Generated scenario 2005 (its source in a quiet room): the frozen k-epsilon stopped at a flow
    solve's residual criterion keeps the inlet's turbulence there and misplaces the plume; at the
    default tolerance it is the case's own plume."""
    from dgse.physics.scenario import random_cases

    case = random_cases(2005, n_sources=1)[0]
    src = case.layout.grid.cell_of(*case.source)

    def log_rmse(**kw):
        flow = project_wind(case.occupancy, case.resolution, case.wind, case.layout, **kw)
        ts = transport_from_wind(flow)
        c = ts.solve_cells([src], [case.release_rate])[0] * ts.physics.ppm_per_gm3
        d = np.log1p(np.maximum(c, 0)) - np.log1p(case.concentration)
        return float(np.sqrt(np.mean(d[case.free] ** 2)))

    assert log_rmse(turbulence_tolerance=1e-4) > 0.6  # what the projection did before
    assert log_rmse() < 0.3
    with pytest.raises(InputDataError, match="turbulence_tolerance"):
        project_wind(case.occupancy, case.resolution, case.wind, turbulence_tolerance=2.0)


def test_bad_wind_is_a_clear_error(case):
    with pytest.raises(InputDataError, match="shape"):
        project_wind(case.occupancy, case.resolution, np.zeros((2, 3, 3)))
    wall_wind = np.array(case.wind)
    wall_wind[0][case.occupancy == 1] = 1.0
    with pytest.raises(InputDataError, match="flow through walls"):
        project_wind(case.occupancy, case.resolution, wall_wind)
    with pytest.raises(InputDataError, match="NaN"):
        project_wind(case.occupancy, case.resolution, np.full(case.wind.shape, np.nan))
    with pytest.raises(InputDataError, match="unknown closure"):
        project_wind(case.occupancy, case.resolution, case.wind, closure="smagorinsky")


def test_a_walled_slice_keeps_its_divergence_as_exchange_through_the_slice(case):
    """Walls drawn over the inlet and outlet (a GADEN-like slice): the air that crossed them now
    enters and leaves through the slice beside them; mass is conserved, and the gas leaves with
    the leaving air."""
    occ, wind, _ = walled_fields(case)
    flow = project_wind(occ, case.resolution, wind, closure="mixing-length")
    assert flow.info["through_slice"] and flow.info["correction"] == 0.0
    assert not ((flow.mesh.ft == INLET) | (flow.mesh.ft == OUTLET)).any()
    assert np.array_equal(flow.F, face_fluxes(flow.mesh, wind))  # no correction: walls already hold
    q = flow.mesh.field(flow.slice_flux)
    assert np.array_equal(flow.slice_flux, divergence(flow.F))
    # net exchange of a closed slice: zero (to round-off); what enters is what leaves
    assert abs(q.sum()) < 1e-12 * np.abs(q).sum()
    assert flow.info["slice_inflow"] == pytest.approx(flow.info["slice_outflow"], rel=1e-12)
    # the inflow enters beside the former inlet (west, 1.2-1.8 m): its volume flow, 1.0 m/s x 0.6 m
    inlet_rows = slice(12, 18)
    assert q[inlet_rows, 1].sum() == pytest.approx(1.0 * 0.6, rel=0.1)
    assert (q[inlet_rows, 1] > 0).all() and (q[2:8, -2] < 0).all()  # out beside the former outlet
    # every gram released leaves through the slice (the solver's tolerance)
    ts = transport_from_wind(flow)
    c = ts.solve_cells([case.source_cell], [0.8])[0]
    assert ts.outflow(c) == (0.0, 0.0)
    assert ts.slice_outflow(c) * ts.physics.slab_depth == pytest.approx(0.8, rel=1e-6)


def _ring(U: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    """A one-cell-wide corridor around a solid core, walled at the map's edge, with a constant
    counter-clockwise wind: its face fluxes are exactly divergence-free."""
    occ = np.ones((8, 8), np.uint8)
    occ[1, 1:7] = occ[6, 1:7] = occ[1:7, 1] = occ[1:7, 6] = 0
    w = np.zeros((2, 8, 8))
    w[0, 1, 1:7], w[0, 6, 1:7] = U, -U  # along the bottom east, along the top west
    w[1, 1:7, 6], w[1, 1:7, 1] = U, -U  # up the east side, down the west side
    return occ, w


@pytest.mark.parametrize("through_slice", [None, True, False])
def test_a_divergence_free_field_on_a_walled_map_is_unchanged(through_slice):
    occ, wind = _ring()
    flow = project_wind(occ, 0.1, wind, through_slice=through_slice, closure="mixing-length")
    assert np.array_equal(flow.F, face_fluxes(flow.mesh, wind))
    assert np.abs(divergence(flow.F)).max() < 1e-15
    assert np.allclose(flow.wind, wind, atol=1e-15)
    assert (flow.slice_flux is None) == (through_slice is False)
    if flow.slice_flux is not None:
        assert np.abs(flow.slice_flux).max() < 1e-15
    with pytest.raises(InputDataError, match="no way out"):  # a closed room: no steady plume
        transport_from_wind(flow)


def test_a_solid_map_corner_needs_no_placeholder_opening():
    occ = np.zeros((6, 9), np.uint8)
    occ[0, 0] = occ[-1, -1] = occ[0, -1] = occ[-1, 0] = 1
    wind = np.where(occ == 1, 0.0, np.stack([np.full(occ.shape, 0.5), np.zeros(occ.shape)]))
    flow = project_wind(occ, 0.1, wind, closure="mixing-length")
    assert not flow.info["through_slice"] and flow.info["inlet_faces"] == 4 and flow.info["outlet_faces"] == 4
    assert np.abs(divergence(flow.F)).max() < 1e-12


def test_a_smoothed_exchange_is_the_projected_divergence_and_keeps_its_sum(case):
    occ, wind, _ = walled_fields(case)
    raw = project_wind(occ, case.resolution, wind, closure="mixing-length")
    smooth = project_wind(occ, case.resolution, wind, closure="mixing-length", slice_smoothing=0.3)
    target = smoothed_exchange(smooth.mesh, raw.slice_flux, 0.3)
    scale = np.abs(raw.F).max()
    assert np.abs(divergence(smooth.F) - target).max() < 1e-10 * scale
    assert np.array_equal(smooth.slice_flux, divergence(smooth.F))
    assert abs(smooth.slice_flux.sum()) < 1e-12 * np.abs(raw.slice_flux).sum()  # mass conserved
    assert (smooth.F[smooth.mesh.ft == WALL] == 0).all()  # the walls still hold
    # alternating pairs cancel: less exchange in all, and none where the field has none
    assert np.abs(smooth.slice_flux).sum() < 0.8 * np.abs(raw.slice_flux).sum()
    assert np.array_equal(smoothed_exchange(smooth.mesh, raw.slice_flux, 0.0), raw.slice_flux)


def test_closed_rooms_apart_are_each_made_mass_conserving():
    """Two rooms with no door between them and no opening: each is its own closed part."""
    occ = np.zeros((8, 12), np.uint8)
    occ[:, 6] = 1
    rng = np.random.default_rng(3)
    wind = np.where(occ == 1, 0.0, rng.standard_normal((2, 8, 12)) * 0.2)
    mesh = edge_mesh(occ, 0.1)
    closed = replace(mesh, ft=np.where(mesh.ft == INLET, WALL, mesh.ft))
    F, _ = project_fluxes(closed, face_fluxes(closed, wind))
    assert np.abs(divergence(F)).max() < 1e-12
    with pytest.raises(InputDataError, match="net source"):  # a closed part cannot gain air
        project_fluxes(closed, face_fluxes(closed, wind), np.full(closed.n, 0.01))
