"""The RANS solver at building scale: AMG pressure, coarse start, SER relaxation, warm starts.

How the equations are solved must not change what they converge to: every
strategy is checked against the plain iteration on a small map, and a
200 x 200 multi-room map (slow) against the residual criteria and continuity.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from dgse.physics.builtin import flow_and_transport
from dgse.physics.fv import INLET, OUTLET, build_mesh
from dgse.physics.rans import (
    FlowSettings,
    PressureSolver,
    coarsen_layout,
    face_fluxes,
    prolong_state,
    scale_state,
    solve_flow,
)
from dgse.world.generate import random_layout_with_rooms
from tests.conftest import two_rooms

TIGHT = FlowSettings(tolerance=1e-5)
#: every large-map strategy off: the iteration of the paper-size maps
PLAIN = FlowSettings(tolerance=1e-5, coarse_cells=0, ser_cells=0, pressure_solver="lu")


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def plain():
    layout = two_rooms(40, 30)
    mesh = build_mesh(layout)
    st, info = solve_flow(layout, mesh, 1.5, settings=PLAIN)
    assert info["converged"] and info["start"] == "rest"
    return layout, mesh, st, info


def test_pressure_solvers_agree():
    """AMG- and LU-preconditioned CG solve a Poisson problem to the asked tolerance."""
    n = 60
    lap1 = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = (sp.kron(lap1, sp.identity(n)) + sp.kron(sp.identity(n), lap1)).tocsr()
    b = np.random.default_rng(0).normal(size=n * n)
    x0 = np.zeros(n * n)
    for method in ("amg", "lu"):
        ps = PressureSolver(max_krylov=20, method=method)
        for _ in range(2):  # the second solve reuses the preconditioner
            x = ps.solve(A * 1.01, b, x0, 1e-8)
            assert np.linalg.norm(b - A * 1.01 @ x) <= 1e-8 * np.linalg.norm(b)
        assert ps.factorizations == 1
    with pytest.raises(ValueError, match="unknown pressure solver"):
        PressureSolver(8, "gmg")


def test_own_pcg_loop_is_scipys_cg_bit_for_bit():
    """The pressure solve's CG loop repeats SciPy's iteration exactly (same iterates, same
    stopping), so replacing the library call changed no recorded flow."""
    import scipy.sparse.linalg as spla

    from dgse.physics.rans import _pcg

    n = 30
    lap1 = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = (sp.kron(lap1, sp.identity(n)) + sp.kron(sp.identity(n), lap1)).tocsr()
    rng = np.random.default_rng(3)
    b, x0 = rng.normal(size=n * n), rng.normal(size=n * n)
    stale = A + sp.diags(rng.uniform(0.0, 0.5, n * n))  # a stale preconditioner, as in the flow
    lu = spla.splu(stale.tocsc())
    M = spla.LinearOperator(A.shape, matvec=lu.solve)
    atol = 1e-3 * np.linalg.norm(b - A @ x0)
    iterates: list[np.ndarray] = []
    for maxiter in (2, 50):
        iterates.clear()
        ref, info = spla.cg(A, b, x0=x0, rtol=0.0, atol=atol, maxiter=maxiter, M=M, callback=iterates.append)
        x, converged, its = _pcg(A, b, x0, atol, maxiter, lu.solve)
        assert np.array_equal(x, ref) and converged == (info == 0) and its == len(iterates)
    assert converged and 2 < its < 50
    x, converged, its = _pcg(A, np.zeros(n * n), x0, atol, 5, lu.solve)
    assert converged and its == 0 and not x.any()


@pytest.mark.parametrize(
    "settings",
    [
        FlowSettings(tolerance=1e-5, coarse_cells=0, ser_cells=0, pressure_solver="amg"),
        FlowSettings(tolerance=1e-5, coarse_cells=0, ser_cells=1, pressure_solver="lu"),
        FlowSettings(tolerance=1e-5, coarse_cells=1, ser_cells=0, pressure_solver="lu"),
        FlowSettings(tolerance=1e-5, coarse_cells=0, pressure_solver="lu"),
    ],
    ids=["amg", "ser", "coarse-start", "ser-small"],
)
def test_strategies_converge_to_the_same_flow(plain, settings):
    layout, mesh, st0, _ = plain
    st, info = solve_flow(layout, mesh, 1.5, settings=settings)
    assert info["converged"]
    assert _rel(np.stack([st.ux, st.uy]), np.stack([st0.ux, st0.uy])) < 2e-3
    assert _rel(st.k, st0.k) < 1e-2
    if settings.coarse_cells:
        assert info["start"] == "coarse" and info["coarse"]["iterations"] > 0


def test_capped_turbulence_sweeps_are_lifted_when_they_stall(plain):
    """With no turbulence sweeps allowed under SER, k and epsilon cannot move: the stall
    lifts the cap, the iteration goes on from where it is and reaches the plain flow."""
    layout, mesh, st0, _ = plain
    settings = FlowSettings(
        tolerance=1e-5, coarse_cells=0, ser_cells=1, pressure_solver="lu", ser_max_sweeps=0,
        stall_window=50, retry_relaxation=None,
    )  # fmt: skip
    st, info = solve_flow(layout, mesh, 1.5, settings=settings)
    assert info["turbulence_sweeps_uncapped_at"] is not None
    assert info["turbulence_sweeps_uncapped_at"] < info["iterations"]
    assert info["converged"] and len(info["attempts"]) == 1
    assert _rel(np.stack([st.ux, st.uy]), np.stack([st0.ux, st0.uy])) < 2e-3
    assert _rel(st.k, st0.k) < 1e-2
    # the paper-size default (SER up to alpha_turb_max_small) does not stall under the cap
    _, info = solve_flow(layout, mesh, 1.5, settings=TIGHT)
    assert info["ser"] and info["turbulence_sweeps_uncapped_at"] is None


def test_paper_size_defaults_grow_the_turbulence_step_to_the_small_bound(plain):
    """Under 12k cells the defaults start from rest with SER bounded by ``alpha_turb_max_small``:
    fewer iterations than the plain iteration; without SER there they are that iteration,
    bit for bit."""
    layout, mesh, st0, info0 = plain
    st, info = solve_flow(layout, mesh, 1.5, settings=TIGHT)
    assert info["start"] == "rest" and info["ser"]
    assert info["iterations"] < info0["iterations"]
    assert _rel(np.stack([st.ux, st.uy]), np.stack([st0.ux, st0.uy])) < 2e-3
    no_ser = FlowSettings(tolerance=1e-5, alpha_turb_max_small=TIGHT.alpha_turb)
    st, info = solve_flow(layout, mesh, 1.5, settings=no_ser)
    assert not info["ser"] and info["iterations"] == info0["iterations"]
    assert np.array_equal(st.ux, st0.ux) and np.array_equal(st.k, st0.k)


@pytest.mark.parametrize("field", ["alpha_turb_max_small", "alpha_turb_max", "alpha_turb"])
def test_relaxation_bounds_outside_the_unit_interval_are_rejected(field):
    from dgse.errors import InputDataError

    with pytest.raises(InputDataError, match=field):
        FlowSettings(**{field: 1.0})
    with pytest.raises(InputDataError, match=field):
        FlowSettings(**{field: -0.1})


def test_a_flow_with_outlet_backflow_converges_from_rest():
    """Generated layout 928 (a validation scenario): from rest the iteration fell into a limit
    cycle (OpenFOAM converges it) and converged only when tried again from the coarse grid's
    solution.  The cycle was its outlet's backflow (a tenth of the outflow at the steady state)
    feeding itself: with the backflow's inflow in the momentum relaxation it converges from
    rest at the first attempt."""
    from dgse.world.generate import as_generator, random_inlet_velocity, random_layout

    rng = as_generator(928)
    layout = random_layout(rng)
    flow, _ = flow_and_transport(layout, random_inlet_velocity(rng))
    (first,) = flow.info["attempts"]
    assert first["converged"] and flow.info["start"] == "rest"


def test_coarsen_layout_keeps_walls_and_openings():
    layout = two_rooms(41, 30)  # odd width
    coarse = coarsen_layout(layout)
    assert coarse is not None
    assert coarse.occupancy.shape == (15, 21) and coarse.resolution == pytest.approx(0.2)
    assert coarse.occupancy[:, 10].sum() >= 13  # the wall stays, its door stays open
    assert coarse.opening_mask("inlet").any() and coarse.opening_mask("outlet").any()
    # a room reachable through a one-cell gap only is cut off: it becomes solid
    occ = layout.occupancy.copy()
    occ[:, 20] = 1
    occ[14, 20] = 0
    from dgse.world.layout import Layout

    cut = Layout(occ, layout.inlets, layout.outlets)
    assert coarsen_layout(cut) is None  # the inlet's air could not reach the outlet


def test_prolongation_and_scaling(plain):
    layout, mesh, st, _ = plain
    coarse = coarsen_layout(layout)
    cmesh = build_mesh(coarse)
    cst, _ = solve_flow(coarse, cmesh, 1.5, settings=FlowSettings(tolerance=1e-3))
    fine = prolong_state(cmesh, cst, mesh, 1.5)
    assert fine.ux.shape == (mesh.n,) and fine.F.shape == (mesh.n, 4)
    assert np.all(fine.k > 0) and np.all(fine.eps > 0)
    assert _rel(np.stack([fine.ux, fine.uy]), np.stack([st.ux, st.uy])) < 0.5  # a start, not the answer
    assert fine.F[mesh.ft == INLET].sum() == pytest.approx(-1.5 * 0.1 * (mesh.ft == INLET).sum())
    # interpolated fluxes of the solution are close to its conservative (Rhie-Chow) ones
    assert _rel(face_fluxes(mesh, st.ux, st.uy, 1.5), st.F) < 0.1
    s2 = scale_state(st, 2.0)
    assert np.allclose(s2.ux, 2 * st.ux) and np.allclose(s2.k, 4 * st.k) and np.allclose(s2.eps, 8 * st.eps)


def test_warm_start_equals_cold_start():
    layout = two_rooms(40, 30)
    cold, _ = flow_and_transport(layout, 2.0, settings=TIGHT)
    prev, _ = flow_and_transport(layout, 1.2, settings=TIGHT)
    warm, ts_warm = flow_and_transport(layout, 2.0, settings=TIGHT, warm_start=prev)
    assert cold.info["converged"] and warm.info["converged"]
    assert warm.info["start"] == "initial"
    assert warm.info["iterations"] < 0.8 * cold.info["iterations"]
    assert _rel(warm.wind, cold.wind) < 2e-3
    assert _rel(warm.k, cold.k) < 1e-2
    assert np.abs(ts_warm.F.sum(axis=1)).max() < 1e-4 * 2.0 * 0.9


def test_warm_start_from_another_layout_is_rejected():
    prev, _ = flow_and_transport(two_rooms(40, 30), 1.2, settings=FlowSettings(max_iterations=2))
    with pytest.raises(ValueError, match="not on this layout"):
        flow_and_transport(two_rooms(30, 20), 2.0, warm_start=prev)


@pytest.mark.slow
def test_multi_room_200x200_converges_and_conserves_mass():
    layout, rooms = random_layout_with_rooms(3, width_range=(20.0, 20.0), height_range=(20.0, 20.0))
    assert layout.occupancy.shape == (200, 200) and len(rooms) >= 2
    v = 2.0
    mesh = build_mesh(layout)
    st, info = solve_flow(layout, mesh, v)
    assert info["converged"], info["attempts"]
    assert info["start"] == "coarse"
    # fine-grid iterations of both attempts: on this map the first (SER) one stalls, at ~400
    # with its turbulence sweeps capped and again ~200 later with them lifted; the retry at
    # relaxation 0.7 from the same coarse start converges (1322 in all, 73 s; 1121 and 81 s
    # before the cap); before issue 14 the solver reported it not converged
    assert info["iterations"] <= 1400
    r = info["residuals"]
    s = FlowSettings()
    assert max(v for k, v in r.items() if k != "p") < s.tolerance
    assert r["p"] < s.tolerance * s.p_tolerance_factor
    inflow = -st.F[mesh.ft == INLET].sum()
    assert inflow == pytest.approx(v * sum(o.width_m for o in layout.inlets), rel=0.1)
    assert np.abs(st.F.sum(axis=1)).max() < 1e-3 * inflow  # every cell's net face flux ~ 0
    assert st.F[mesh.ft == OUTLET].sum() == pytest.approx(inflow, rel=1e-3)


def test_galerkin_map_gives_the_coarse_operators():
    """The precomputed map from fine values to coarse ones equals R A P for a new matrix of the
    same pattern, level after level."""
    import pyamg

    from dgse.physics.fv import StencilMatrix
    from dgse.physics.rans import GalerkinMap

    mesh = build_mesh(two_rooms(60, 40))
    rng = np.random.default_rng(3)
    st = StencilMatrix(mesh)

    def laplacian():
        a = np.where(mesh.nb >= 0, rng.uniform(0.5, 1.5, (mesh.n, 4)), 0.0)
        a = 0.5 * (a + np.where(mesh.nb >= 0, a[np.maximum(mesh.nb, 0), [1, 0, 3, 2]], 0.0))  # symmetric
        return st.assemble(a.sum(axis=1) + 1e-3, a).tocsr()

    ml = pyamg.ruge_stuben_solver(laplacian(), max_coarse=50)
    assert len(ml.levels) >= 3
    maps, pattern = [], laplacian()
    for lvl in ml.levels[:-1]:
        maps.append(GalerkinMap(pattern, lvl.R, lvl.P))
        pattern = maps[-1].pattern()
    A = laplacian()
    fine = A
    for g, lvl in zip(maps, ml.levels[:-1], strict=True):
        coarse = g.apply(fine.data)
        ref = (lvl.R @ fine @ lvl.P).tocsr()
        assert abs(coarse - ref).max() <= 1e-12 * abs(ref).max()
        fine = coarse
