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


# -- closed regions and the mass balance -------------------------------------------------------
def _rooms_with_pockets() -> Layout:
    """``two_rooms`` with a closed room (5 x 5 free cells walled in) and one walled-in free cell."""
    occ = two_rooms().occupancy.copy()
    occ[12:19, 3:10] = 1
    occ[13:18, 4:9] = 0
    occ[2:5, 21:24] = 1
    occ[3, 22] = 0
    return Layout(occ, (Opening("west", 0.2, 1.0),), (Opening("east", 0.2, 1.0),), name="pockets")


def test_closed_regions_leave_the_flow_and_the_gas_regular():
    """Free cells no opening reaches made the pressure and transport operators singular
    ("Factor is exactly singular"): now they stay at rest and gas-free, and the open part is
    solved as before, divergence-free and conserving the released gas."""
    layout = _rooms_with_pockets()
    mesh = build_mesh(layout)
    closed = np.zeros(layout.occupancy.shape, bool)
    closed[13:18, 4:9] = closed[3, 22] = True
    flow, ts = flow_and_transport(layout, 1.0)
    assert flow.info["converged"]
    assert np.abs(flow.wind[:, closed]).max() < 1e-9
    open_cells = ~closed[mesh.cells[:, 0], mesh.cells[:, 1]]
    inflow = -ts.F[mesh.ft == INLET].sum()
    assert inflow == pytest.approx(0.8)  # v_in * inlet width
    net = ts.F.sum(axis=1)  # volume flux out of each cell
    assert np.abs(net[open_cells]).max() < 1e-4 * inflow  # as on a map without closed regions
    assert np.abs(ts.F[~open_cells]).max() < 1e-12
    sol = BuiltinEngine().solve(layout, 1.0, [Source((2.05, 0.55), 0.5)])
    assert sol.outlet_flux_ratio[0] == pytest.approx(1.0, abs=0.01)
    assert np.abs(sol.concentrations[0][closed]).max() == 0.0
    assert np.isfinite(sol.concentrations[0]).all()
    with pytest.raises(InputDataError, match="closed region that no inlet reaches"):
        BuiltinEngine().solve(layout, 1.0, [Source((0.65, 1.55), 0.5)])


def test_an_inlet_into_a_region_without_outlet_is_refused():
    occ = two_rooms().occupancy.copy()
    occ[:, 15] = 1  # no door: the west room has the inlet, the east one the outlet
    layout = Layout(occ, (Opening("west", 0.2, 1.0),), (Opening("east", 0.2, 1.0),), name="split")
    with pytest.raises(InputDataError, match="no outlet reaches"):
        BuiltinEngine().solve(layout, 1.0, [Source((0.55, 0.55), 0.5)])


def _solution(ratio: float, conc: np.ndarray):
    from dgse.physics.engines import FlowField, Solution

    z = np.zeros_like(conc)
    flow = FlowField(np.zeros((2, *conc.shape)), z, z, z, z)
    return Solution(flow, [Source((0.55, 0.55), 0.5)], [conc], [ratio], {"engine": "test"})


def test_a_field_failing_its_mass_balance_is_an_error():
    from dgse.errors import MassBalanceError
    from dgse.physics.engines import MASS_BALANCE_TOLERANCE, check_mass_balance

    ok = np.ones((4, 4))
    good = _solution(1.0 + 0.5 * MASS_BALANCE_TOLERANCE, ok)
    assert check_mass_balance(good) is good
    for ratio in (2.1e243, 1.0 + 2 * MASS_BALANCE_TOLERANCE, 1.0 - 2 * MASS_BALANCE_TOLERANCE, float("nan")):
        with pytest.raises(MassBalanceError, match="fails its mass balance") as e:
            check_mass_balance(_solution(ratio, ok))
        assert f"{ratio:.4g}" in str(e.value) and "source 0 at (0.55, 0.55) m" in str(e.value)
    with pytest.raises(MassBalanceError, match="non-finite"):
        check_mass_balance(_solution(1.0, np.full((4, 4), np.inf)))


def test_solve_writes_no_case_whose_gas_fails_its_mass_balance(monkeypatch, capsys, tmp_path):
    """A transport solve that returns a wrong field (here 1e3 times too much gas) is a one-line
    error of ``dgse solve``, exit status 2, and no case file."""
    from dgse.cli.main import main
    from dgse.world.layout_io import save_layout

    solve_cells = TransportSolver.solve_cells
    monkeypatch.setattr(TransportSolver, "solve_cells", lambda self, *a: 1e3 * solve_cells(self, *a))
    lay = save_layout(two_rooms(), tmp_path / "rooms.npz")
    out = tmp_path / "case.npz"
    args = ["solve", str(lay), "-o", str(out), "-v", "1.0", "--source", "0.55", "0.55", "-q", "0.5"]
    code = main(args)
    _, err = capsys.readouterr()
    assert code == 2 and not out.exists()
    line = err.strip()
    assert line.startswith("error: ") and "\n" not in line and "fails its mass balance" in line
    assert "outlet flux / release rate = 99" in line  # 1e3 times the true ratio, 0.99...


def test_a_singular_transport_operator_is_a_convergence_error():
    """No flux and no diffusion: the operator is 0 and SuperLU cannot factorize it."""
    from dgse.physics.constants import DEFAULT_PHYSICS

    mesh = build_mesh(two_rooms())
    ts = TransportSolver(mesh, np.zeros((mesh.n, 4)), np.zeros(mesh.n), DEFAULT_PHYSICS, "upwind")
    with pytest.raises(ConvergenceError, match="cannot be factorized"):
        ts.solve_cells([(5, 5)], [1.0])
