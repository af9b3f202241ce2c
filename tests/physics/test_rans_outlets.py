"""Outlets with backflow: the backflow's momentum joins the relaxation, and its air is clean.

A drawn, furnished house (``dgse.world.plans``) whose outlets see air flowing
back in during the iteration (and at the steady state): with the outlet's zero
gradient on those faces the backflow fed itself and the run diverged in about
a hundred iterations (then stalled on both retries); with the backflow's inflow
in the momentum relaxation it converges at the first attempt, and its gas field
(clean air flowing back in) conserves mass.
"""

from __future__ import annotations

import numpy as np
import pytest

from dgse.physics.builtin import BuiltinEngine
from dgse.physics.engines import Source
from dgse.physics.fv import OUTLET, build_mesh
from dgse.physics.rans import FlowSettings, solve_flow
from dgse.world.floorplan import layout_from_floorplan, resample_occupancy
from dgse.world.plans import draw_house


@pytest.fixture(scope="module")
def house():
    plan = draw_house(9)
    occ = resample_occupancy(plan.solid, plan.pixel_size, 0.1)
    return layout_from_floorplan(occ, 0.1, plan.inlets, plan.outlets, name=plan.name), plan.inlet_velocity


def test_a_flow_with_outlet_backflow_converges_at_the_first_attempt(house):
    layout, v = house
    mesh = build_mesh(layout)
    st, info = solve_flow(layout, mesh, v, settings=FlowSettings(retry_relaxation=None, coarse_retry=False))
    assert info["converged"] and len(info["attempts"]) == 1, info["attempts"]
    out = mesh.ft == OUTLET
    back = -st.F[out & (st.F < 0)].sum()
    assert back > 0.01 * st.F[out & (st.F > 0)].sum()  # the steady state has backflow
    assert np.hypot(st.ux, st.uy).max() < 3 * v  # no runaway jet at an outlet
    # continuity: the fluxes of the last pressure solve balance in every cell
    inflow = -st.F[mesh.ft == 3].sum()
    assert np.abs(st.F.sum(axis=1)).max() < 1e-3 * inflow


def test_its_gas_field_keeps_the_mass_balance(house):
    layout, v = house
    grid = layout.grid
    free = np.argwhere(layout.free)
    i, j = free[len(free) // 2]
    sol = BuiltinEngine().solve(layout, v, [Source(tuple(grid.centers_of(np.array([[i, j]]))[0]), 1.0)])
    assert sol.flow.info["converged"]
    assert sol.outlet_flux_ratio[0] == pytest.approx(1.0, abs=0.02)


def test_a_gap_the_coarse_grid_closes_starts_at_rest():
    """A one-cell gap between a block (furniture) and a wall has no free coarse cell around it:
    the prolonged start holds its air at rest (the nearest coarse cell lies beyond the block, its
    velocity is another room's), with the nearest cell's turbulence."""
    from dgse.physics.rans import FlowState, coarsen_layout, prolong_state
    from dgse.world.layout import Layout, Opening

    occ = np.zeros((20, 20), dtype=np.uint8)
    occ[4:16, 0] = 1  # outer wall
    occ[4:16, 2:10] = 1  # a block one cell off it
    layout = Layout(occ, (Opening("west", 0.0, 0.3),), (Opening("east", 1.7, 2.0),), 0.1)
    fine, coarse = build_mesh(layout), build_mesh(coarsen_layout(layout))
    n = coarse.n
    state = FlowState(
        ux=np.ones(n), uy=np.full(n, 0.5), p=np.zeros(n), k=np.full(n, 0.01),
        eps=np.full(n, 0.001), nut=np.full(n, 1e-3), F=np.zeros((n, 4)),
    )  # fmt: skip
    st = prolong_state(coarse, state, fine, 1.0)
    gap = fine.index[6:14, 1]
    assert (gap >= 0).all()
    assert np.all(st.ux[gap] == 0.0) and np.all(st.uy[gap] == 0.0)
    assert np.allclose(st.k[gap], 0.01) and np.allclose(st.ux[fine.index[0:3, 15]], 1.0)
