"""Candidate openings from a wind field (dgse.physics.openings)."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.physics.openings import edge_runs, propose_openings
from dgse.physics.scenario import random_cases, solve_cases
from tests.conftest import two_rooms


def _centre(o):
    return 0.5 * (o.start_m + o.end_m)


def _matches(proposed, true, tol=0.5):
    return proposed.side == true.side and abs(_centre(proposed) - _centre(true)) <= tol


def test_edge_runs_bridge_small_gaps():
    mask = np.array([0, 1, 1, 0, 1, 0, 0, 1, 1, 1], bool)
    assert edge_runs(mask, max_gap=1) == [(1, 5), (7, 10)]
    assert edge_runs(mask, max_gap=0) == [(1, 3), (4, 5), (7, 10)]
    assert edge_runs(np.zeros(4, bool)) == []


@pytest.mark.parametrize("seed", [None, 3, 8])
def test_noiseless_wind_gives_back_the_true_openings(seed):
    """The wind of a built-in case (noiseless readings everywhere): the first proposal is the truth."""
    if seed is None:
        case = solve_cases(two_rooms(), 1.0, [((2.05, 0.55), 0.8)])[0]
    else:
        case = random_cases(seed, n_sources=1, width_range=(5, 7), height_range=(5, 7))[0]
    props = propose_openings(case.occupancy, case.resolution, case.wind)
    (inlet,), (outlet,) = case.layout.inlets, case.layout.outlets
    best = props[0]
    assert _matches(best.inlets[0], inlet) and _matches(best.outlets[0], outlet), (best, inlet, outlet)
    assert abs(best.inlets[0].width_m - inlet.width_m) <= 0.3
    assert best.inflow_speed == pytest.approx(case.inlet_velocity, rel=0.3)


def test_no_crossing_wind_is_a_clear_error():
    occ = np.zeros((10, 10), np.uint8)
    with pytest.raises(InputDataError, match="does not cross"):
        propose_openings(occ, 0.1, np.zeros((2, 10, 10)))
    with pytest.raises(InputDataError, match="shape"):
        propose_openings(occ, 0.1, np.zeros((2, 3, 3)))


@pytest.mark.parametrize("seed", [3, 8, 12])
def test_noiseless_readings_rank_the_true_openings_first(seed):
    """Potential flow between edge windows, fitted to noiseless wind readings of a built-in case."""
    from dgse.physics.openings import potential_flow_proposals

    case = random_cases(seed, n_sources=1, width_range=(5, 7), height_range=(5, 7))[0]
    rng = np.random.default_rng(seed)
    free = np.argwhere(case.occupancy == 0)
    cells = free[rng.choice(len(free), 80, replace=False)]
    wind = case.wind[:, cells[:, 0], cells[:, 1]].T
    props = potential_flow_proposals(case.occupancy, case.resolution, cells, wind, top=3)
    (inlet,), (outlet,) = case.layout.inlets, case.layout.outlets
    assert any(_matches(p.inlets[0], inlet, 0.6) and _matches(p.outlets[0], outlet, 0.6) for p in props)
    assert _matches(props[0].inlets[0], inlet, 0.6) and _matches(props[0].outlets[0], outlet, 0.6)
