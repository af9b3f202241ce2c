"""The built-in solver proves physics: conservation, symmetry, the adjoint, OpenFOAM agreement."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import ConvergenceError, DGSEError, InputDataError, UnsupportedError
from dgse.physics.builtin import BuiltinEngine, flow_and_transport
from dgse.physics.engines import Source, get_engine
from dgse.physics.fv import INLET, INTERNAL, OUTLET, build_mesh
from dgse.physics.rans import FlowSettings
from dgse.physics.scenario import resolve_case, solve_cases
from dgse.physics.transport import TransportSolver
from dgse.world.case import Case
from dgse.world.layout import Layout, Opening
from tests.conftest import two_rooms


@pytest.fixture(scope="module")
def solved():
    layout = two_rooms()
    flow, ts = flow_and_transport(layout, 1.5, settings=FlowSettings(tolerance=1e-5))
    return layout, flow, ts


def test_flow_converges_and_is_zero_in_walls(solved):
    layout, flow, _ = solved
    assert flow.info["converged"]
    assert np.all(flow.wind[:, ~layout.free] == 0)
    assert np.all(flow.k[layout.free] > 0) and np.all(flow.nut[layout.free] >= 0)


def test_volume_flux_is_conserved_cell_by_cell(solved):
    _, _, ts = solved
    F, mesh = ts.F, ts.mesh
    inflow = 1.5 * 0.6  # v_in * inlet width (m^2/s per m depth)
    assert np.abs(F.sum(axis=1)).max() < 1e-4 * inflow  # continuity in every cell
    # both cells of an internal face see the same flux, with opposite signs
    internal = mesh.ft == INTERNAL
    opposite = F[np.where(internal, mesh.nb, 0), np.array([1, 0, 3, 2])]
    assert np.allclose(F[internal], -opposite[internal])
    assert F[mesh.ft == INLET].sum() == pytest.approx(-inflow)
    assert F[mesh.ft == OUTLET].sum() == pytest.approx(inflow, rel=1e-4)


def test_scalar_outflow_equals_release_rate(solved):
    _, _, ts = solved
    q = 0.7
    c = ts.solve_cells([(5, 20)], [q])[0]
    out, inlet_loss = ts.outflow(c)
    assert out + inlet_loss == pytest.approx(q, rel=1e-6)  # exact discrete conservation
    assert out == pytest.approx(q, rel=0.02)  # spec: outlet flux within 2 % of q
    assert c[5, 20] == c.max() and c.min() > -1e-6 * c.max()


def _mirror_x(layout: Layout) -> Layout:
    flip = {"west": "east", "east": "west"}
    W = layout.grid.width_m

    def m(o: Opening) -> Opening:
        if o.side in flip:
            return Opening(flip[o.side], o.start_m, o.end_m)
        return Opening(o.side, W - o.end_m, W - o.start_m)

    return Layout(
        layout.occupancy[:, ::-1].copy(),
        tuple(m(o) for o in layout.inlets),
        tuple(m(o) for o in layout.outlets),
        layout.resolution,
    )


def test_mirror_symmetry(solved):
    layout, flow, ts = solved
    mirrored = _mirror_x(layout)
    flow_m, ts_m = flow_and_transport(mirrored, 1.5, settings=FlowSettings(tolerance=1e-5))
    expect = flow.wind[:, :, ::-1] * np.array([-1.0, 1.0])[:, None, None]
    err = np.linalg.norm(flow_m.wind - expect) / np.linalg.norm(expect)
    assert err < 1e-3
    W = layout.grid.width
    c = ts.solve_cells([(5, 20)], [1.0])[0]
    c_m = ts_m.solve_cells([(5, W - 1 - 20)], [1.0])[0]
    assert np.abs(c_m - c[:, ::-1]).max() < 1e-3 * c.max()


@pytest.mark.parametrize("scheme", ["linearUpwind", "upwind"])
def test_adjoint_reproduces_forward_solution(solved, scheme):
    _, flow, ts0 = solved
    ts = TransportSolver.build(
        ts0.mesh, ts0.F, ts0.mesh.values(flow.nut), scheme=scheme, adjoint_scheme=scheme
    )
    sensors = [(3, 4), (15, 25), (10, 16), (2, 28)]
    a = ts.adjoint(sensors)  # (4, H, W)
    source, q = (12, 6), 0.37
    c = ts.solve_cells([source], [q])[0]
    for n, (i, j) in enumerate(sensors):
        assert a[n][source] * q == pytest.approx(c[i, j], rel=1e-9, abs=1e-15)


def test_openfoam_case_agreement(openfoam_cases_dir):
    """OpenFOAM's small layout (50 x 50 cells, four rooms, two sources): the issue's tolerances."""
    cases = [Case.load(p) for p in sorted(openfoam_cases_dir.glob("small_src*.npz"))]
    assert len(cases) == 2
    assert all(c.meta["solver"].startswith("openfoam") for c in cases)
    layout = cases[0].layout
    srcs = [Source((float(c.source[0]), float(c.source[1])), c.release_rate) for c in cases]
    ours = solve_cases(layout, cases[0].inlet_velocity, srcs)
    f = layout.free
    for ref, new in zip(cases, ours, strict=True):
        vel = np.linalg.norm((new.wind - ref.wind)[:, f]) / np.linalg.norm(ref.wind[:, f])
        rmse = np.sqrt(np.mean((np.log1p(new.concentration) - np.log1p(ref.concentration))[f] ** 2))
        assert vel <= 0.15
        assert rmse <= 0.3
        assert abs(new.meta["mass_balance"]["outlet_flux_ratio"] - 1.0) <= 0.02


def test_resolve_case_keeps_the_scenario(two_rooms_layout, tmp_path):
    case = solve_cases(two_rooms_layout, 1.2, [((2.05, 0.55), 0.8)])[0]
    path = case.save(tmp_path / "case.npz")
    new = resolve_case(Case.load(path))
    assert new.name == case.name
    assert np.array_equal(new.occupancy, case.occupancy)
    assert np.array_equal(new.source, case.source)
    assert new.release_rate == case.release_rate and new.inlet_velocity == case.inlet_velocity
    assert np.allclose(new.concentration, case.concentration, rtol=1e-3, atol=1e-3)
    back = Case.load(new.save(tmp_path / "x.npz"))
    assert back.meta == new.meta and np.array_equal(back.concentration, new.concentration)


def test_a_source_on_a_cell_edge_keeps_the_cell_it_was_released_in(two_rooms_layout, tmp_path):
    """x = 0.9 m, y = 1.3 m are cell edges (float64 0.9 / 0.1 = 9, float32 0.9 / 0.1 < 9): the
    saved case's source cell is the solver's release cell, the peak of the steady field."""
    case = solve_cases(two_rooms_layout, 1.0, [((0.9, 1.3), 0.5)])[0]
    back = Case.load(case.save(tmp_path / "edge.npz"))
    assert back.source.dtype == np.float32 and case.source_cell == back.source_cell == (13, 9)
    peak = np.unravel_index(np.argmax(back.concentration), back.concentration.shape)
    assert tuple(int(v) for v in peak) == back.source_cell


def test_non_convergence_is_reported(two_rooms_layout):
    engine = BuiltinEngine(settings=FlowSettings(max_iterations=3))
    with pytest.raises(ConvergenceError, match="did not converge in 3 iterations"):
        engine.solve(two_rooms_layout, 1.0, [Source((0.5, 0.5), 1.0)])
    sol = BuiltinEngine(settings=FlowSettings(max_iterations=3), allow_unconverged=True).solve(
        two_rooms_layout, 1.0, [Source((0.5, 0.5), 1.0)]
    )
    assert sol.info["flow_converged"] is False


@pytest.mark.parametrize(
    ("v", "src", "rate", "match"),
    [
        (-1.0, (0.5, 0.5), 1.0, "inlet velocity"),
        (float("nan"), (0.5, 0.5), 1.0, "inlet velocity"),
        (1.0, (1.55, 0.35), 1.0, "solid"),
        (1.0, (9.0, 0.5), 1.0, "outside"),
        (1.0, (0.5, 0.5), 0.0, "release rate"),
    ],
)
def test_bad_inputs_are_rejected(two_rooms_layout, v, src, rate, match):
    with pytest.raises(InputDataError, match=match):
        BuiltinEngine(settings=FlowSettings(max_iterations=2), allow_unconverged=True).solve(
            two_rooms_layout, v, [Source(src, rate)]
        )


def test_unknown_engine_is_a_clear_error():
    with pytest.raises(UnsupportedError, match="unknown engine 'fluent'"):
        get_engine("fluent")


def test_opening_on_a_wall_is_rejected():
    occ = np.zeros((10, 10), np.uint8)
    occ[:, 0] = 1
    with pytest.raises(DGSEError, match="touches no free cell"):
        Layout(occ, (Opening("west", 0.2, 0.6),), (Opening("east", 0.2, 0.6),))


def test_mesh_classifies_openings(two_rooms_layout):
    mesh = build_mesh(two_rooms_layout)
    assert mesh.n == 20 * 30 - 16
    assert (mesh.ft == INLET).sum() == 6 and (mesh.ft == OUTLET).sum() == 6
    assert (mesh.ft[:, 1] == INLET).sum() == 6  # on west faces
    # 31 x faces a row: 2 on the domain edge, 2 against the wall (none in the 4 door rows);
    # every internal face is seen from both of its cells
    assert (mesh.ft[:, :2] == INTERNAL).sum() == 2 * (20 * 27 + 4 * 2)
