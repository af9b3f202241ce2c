"""PMFS: hit map, wind map, filament hit maps, the likelihood peak on a tiny case, the planner."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.belief.knowledge import Knowledge
from dgse.errors import InputDataError
from dgse.localization.pmfs import (
    PMFSEstimator,
    PMFSMaps,
    PMFSParams,
    PMFSPlanner,
    _initial_leaves,
    _split,
    hit_map,
    hypothesis_log_likelihood,
    simulate_hits,
    wind_map,
)
from dgse.planning.paths import graph_for
from dgse.planning.planners import SearchHistory
from dgse.sensing.sensors import Observations
from tests.localization import cell_distance, channel_case, dense_readings


def test_hit_map_and_confidence() -> None:
    occ = np.zeros((20, 30), np.uint8)
    obs = Observations(
        np.array([[10, 5], [10, 25]]), np.array([3.0, 0.0]), np.array([[1.0, 0.0], [1.0, 0.0]])
    )
    ph, conf = hit_map(occ, 0.1, obs)
    assert ph[10, 5] > 0.5 > 0.3 > ph[10, 25]  # hit raises, miss lowers the prior 0.3
    assert ph[0, 15] == pytest.approx(0.3, abs=1e-4)  # far from both: the prior
    assert conf[10, 5] > 0.3 and conf[0, 15] < 1e-3
    three = Observations(np.array([[10, 5]] * 3), np.zeros(3), np.zeros((3, 2)))
    assert hit_map(occ, 0.1, three)[1][10, 5] > 0.6  # confidence grows with repeated readings
    assert ph[10, 7] > ph[12, 5]  # the kernel is stretched along the wind (x)


def test_wind_map_interpolates_on_free_cells() -> None:
    occ = np.zeros((10, 12), np.uint8)
    occ[:, 6] = 1
    cells = np.array([[2, 2], [7, 3], [5, 9]])
    wind = np.array([[1.0, 0.5], [1.0, 0.5], [-2.0, 0.0]])
    w = wind_map(occ, cells, wind)
    np.testing.assert_allclose(w[:, :, :6][:, occ[:, :6] == 0].T, [[1.0, 0.5]] * 60, atol=1e-3)
    np.testing.assert_allclose(w[0, 0, 11], -2.0, atol=1e-3)  # the wall separates the two fields
    assert (w[:, occ == 1] == 0).all()


def test_filaments_follow_the_wind_and_stop_at_walls() -> None:
    occ = np.zeros((12, 40), np.uint8)
    occ[:, 30] = 1  # a closed wall across the channel
    wind = np.zeros((2, 12, 40))
    wind[0] = 1.0
    hm = simulate_hits(occ, 0.1, wind, np.array([[6, 5]]), PMFSParams(noise=0.1), seed=0)
    assert hm.shape == occ.shape and hm.max() <= 1.0
    assert hm[:, 10:29].sum() > 10 * hm[:, :4].sum()  # downwind, not upwind
    assert hm[:, 30:].sum() == 0.0
    again = simulate_hits(occ, 0.1, wind, np.array([[6, 5]]), PMFSParams(noise=0.1), seed=0)
    np.testing.assert_array_equal(hm, again)
    with pytest.raises(InputDataError):
        simulate_hits(occ, 0.1, wind, np.array([[6, 30]]))


def test_quadtree_leaves_respect_walls() -> None:
    free = np.ones((24, 24), bool)
    free[:, 5] = False
    leaves = _initial_leaves(free, 12)
    cover = np.zeros(free.shape, int)
    for i, j, h, w in leaves:
        cover[i : i + h, j : j + w] += 1
    assert (cover[free] == 1).all()  # a partition of the free cells
    assert (5 not in range(j, j + w) or h * w == 1 for i, j, h, w in leaves)
    kids = _split((0, 0, 3, 3), free)
    assert sorted((h, w) for _, _, h, w in kids) == [(1, 1), (1, 2), (2, 1), (2, 2)]


def test_likelihood_peaks_near_the_true_source() -> None:
    # readings made by PMFS's own forward model: a source in a channel with a uniform wind
    occ = np.zeros((16, 36), np.uint8)
    wind = np.zeros((2, 16, 36))
    wind[0] = 1.0
    src = (8, 8)
    truth = simulate_hits(occ, 0.1, wind, np.array([src]), seed=1000)
    free = np.argwhere(occ == 0)
    cells = free[np.random.default_rng(0).choice(len(free), 120, replace=False)]
    obs = Observations(cells, truth[cells[:, 0], cells[:, 1]], np.tile([1.0, 0.0], (120, 1)))
    params = PMFSParams(hit_threshold=0.05)
    b = PMFSEstimator(params=params).estimate(occ, 0.1, obs)
    assert cell_distance(b.most_likely_cell(), src) <= 5.0
    assert b.localization_error(((src[1] + 0.5) * 0.1, (src[0] + 0.5) * 0.1)) < 0.8
    assert b.info["n_levels"] >= 3 and b.info["edges"] == "open everywhere"
    maps = b.info["planner_data"]
    assert isinstance(maps, PMFSMaps) and maps.hit_variance.max() > 0
    # the true source's hypothesis beats far ones
    ph, conf = maps.hit_prob, maps.confidence
    mask = occ == 0

    def loglik(cell: tuple[int, int]) -> float:
        hm = simulate_hits(occ, 0.1, b.wind_mean, np.array([cell]), params, seed=7)
        return hypothesis_log_likelihood(ph, conf, hm, params.beta, mask)

    true_ll = loglik(src)
    assert true_ll > loglik((8, 30)) and true_ll > loglik((2, 8)) and true_ll > loglik((14, 20))


def test_physical_case_runs_with_openings() -> None:
    case = channel_case()
    est = PMFSEstimator(params=PMFSParams(hit_threshold_fraction=0.05))
    obs = dense_readings(case, 60, seed=0)
    est.set_knowledge(Knowledge.from_case(case, "map"))
    assert est.estimate(case.occupancy, case.resolution, obs).info["edges"] != "openings of the layout"
    est.set_knowledge(Knowledge.from_case(case, "openings"))
    b = est.estimate(case.occupancy, case.resolution, obs)
    assert b.info["edges"] == "openings of the layout"
    assert b.info["hit_threshold_ppm"] == pytest.approx(0.05 * obs.gas.max())
    assert b.source_probs.sum() == pytest.approx(1.0) and np.isfinite(
        b.localization_error(tuple(case.source))
    )
    with pytest.raises(InputDataError, match="no observations"):
        est.estimate(case.occupancy, case.resolution, Observations.empty())
    with pytest.raises(InputDataError, match="wall"):
        occ = case.occupancy.copy()
        occ[0, 0] = 1
        est.estimate(occ, case.resolution, Observations(np.array([[0, 0]]), [1.0], [[0.0, 0.0]]))


def test_planner_explores_then_uses_variance() -> None:
    occ = np.zeros((20, 50), np.uint8)
    conf = np.zeros(occ.shape)
    conf[:, :15] = 1.0  # the west half is known
    var = np.zeros(occ.shape)
    var[10, 3] = 1.0  # ... but the hypotheses disagree at a cell there
    conf[10, 3] = 0.5
    p = normalize_source_probs(np.ones(occ.shape), occ)
    b = Belief(occ, 0.1, p, info={"planner_data": PMFSMaps(np.zeros(occ.shape), conf, var)})
    g = graph_for(occ, 0.1)
    robot = (10, 14)
    planner = PMFSPlanner(exploration_probability=0.0)
    hist = SearchHistory(g, rng=np.random.default_rng(0))
    goal = planner.next_goal(b, robot, g.distances_from(robot), hist)
    assert goal is not None and goal[1] > 14  # exploration: towards the unknown east
    planner._moves = planner.exploration_moves
    robot = (10, 8)
    goal = planner.next_goal(b, robot, g.distances_from(robot), hist)
    assert goal == (10, 3)
    assert not planner.should_stop(b)
    sharp = np.zeros(occ.shape)
    sharp[4, 4] = 1.0
    assert planner.should_stop(Belief(occ, 0.1, normalize_source_probs(sharp, occ)))
    with pytest.raises(InputDataError, match="pmfs"):
        planner.next_goal(Belief(occ, 0.1, p), robot, g.distances_from(robot), hist)
