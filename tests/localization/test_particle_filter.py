"""Dual-mode particle filter and planner on a map with a wall, readings from its own model."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.errors import InputDataError
from dgse.localization import blur_probs, free_graph, graph_distances
from dgse.localization.particle_filter import DualModePlanner, ParticleFilterEstimator, position_spread
from dgse.planning.planners import SearchHistory
from dgse.sensing.sensors import Observations
from tests.localization import cell_distance

SOURCE = (8, 10)


def _map() -> np.ndarray:
    occ = np.zeros((20, 40), np.uint8)
    occ[:14, 20] = 1  # a wall with a gap at the top
    return occ


def _model_readings(
    n: int, seed: int, q: float = 400.0, sigma_m: float = 1.0, source: tuple[int, int] = SOURCE
) -> Observations:
    occ = _map()
    free = np.argwhere(occ == 0)
    rng = np.random.default_rng(seed)
    cells = free[rng.choice(len(free), size=n, replace=False)]
    d = graph_distances(free_graph(occ, 0.1), cells)[:, source[0] * occ.shape[1] + source[1]]
    return Observations(cells, q * np.exp(-(d**2) / (2 * sigma_m**2)), np.zeros((n, 2)))


def test_filter_finds_the_source_of_its_own_model() -> None:
    occ = _map()
    obs = _model_readings(60, seed=0)
    est = ParticleFilterEstimator(seed=1)
    b = est.estimate(occ, 0.1, obs)
    assert cell_distance(b.most_likely_cell(), SOURCE) <= 2.0
    assert b.localization_error(((SOURCE[1] + 0.5) * 0.1, (SOURCE[0] + 0.5) * 0.1)) < 0.2
    assert b.info["n_particles"] == 1000 and b.info["n_resample"] >= 1
    assert 0.0 < b.info["mcmc_acceptance"] < 1.0
    assert (b.source_probs[occ == 0] > 0).all()  # the floor keeps the cross-entropy finite
    assert b.log_conc_mean is not None and b.conc_mean_ppm[SOURCE] > 100.0
    # the same seed and readings give the same posterior
    again = ParticleFilterEstimator(seed=1).estimate(occ, 0.1, obs)
    np.testing.assert_array_equal(again.source_probs, b.source_probs)


def test_obstacle_aware_distance_matters() -> None:
    occ = _map()
    # just right of the wall, far from its gap: the cells just left of the wall are close in a
    # straight line but far by path, and read almost nothing
    src = (3, 22)
    obs = _model_readings(60, seed=2, source=src)
    b = ParticleFilterEstimator(seed=0).estimate(occ, 0.1, obs)
    assert b.localization_error(((src[1] + 0.5) * 0.1, (src[0] + 0.5) * 0.1)) < 0.25
    left = b.source_probs[:, :20].sum()
    assert left < 0.01


def test_incremental_readings_resume() -> None:
    occ = _map()
    obs = _model_readings(30, seed=3)
    est = ParticleFilterEstimator(seed=0, n_particles=300)
    first = est.estimate(occ, 0.1, obs.take(slice(0, 20)))
    assert not first.info["resumed"]
    second = est.estimate(occ, 0.1, obs)
    assert second.info["resumed"] and second.info["n_observations"] == 30
    other = est.estimate(occ, 0.1, obs.take(slice(5, 30)))
    assert not other.info["resumed"]


def test_bad_input_is_rejected() -> None:
    occ = _map()
    est = ParticleFilterEstimator()
    with pytest.raises(InputDataError, match="no observations"):
        est.estimate(occ, 0.1, Observations.empty())
    with pytest.raises(InputDataError, match="wall"):
        est.estimate(occ, 0.1, Observations(np.array([[0, 20]]), np.array([1.0]), np.zeros((1, 2))))
    with pytest.raises(InputDataError):
        ParticleFilterEstimator(n_particles=3)


def test_dual_mode_planner_local_then_global() -> None:
    occ = _map()
    obs = _model_readings(10, seed=4)
    b = ParticleFilterEstimator(seed=0, n_particles=300).estimate(occ, 0.1, obs)
    graph = free_graph(occ, 0.1)
    robot = (2, 5)
    hist = SearchHistory(graph, obs.take(slice(0, 1)), np.array([robot]), rng=np.random.default_rng(0))
    planner = DualModePlanner()
    d = graph.distances_from(robot)
    goal = planner.next_goal(b, robot, d, hist)
    assert goal is not None and occ[goal] == 0 and d[goal] <= 2.8 + 1e-9
    assert planner.modes == ["local"]
    planner.switch_ratio = 1e12  # any local gain is now "too small": the frontier mode
    goal = planner.next_goal(b, robot, d, hist)
    assert planner.modes[-1] == "global"
    assert goal is not None and planner.frontier(b, d, hist)[goal]
    planner.reset()
    assert planner.gains == [] and planner.modes == []


def test_dual_mode_stop_rule() -> None:
    occ = _map()
    p = np.zeros(occ.shape)
    p[5, 5] = 1.0
    sharp = Belief(occ, 0.1, normalize_source_probs(p, occ))
    flat = Belief(occ, 0.1, normalize_source_probs(np.ones(occ.shape), occ))
    assert position_spread(sharp) == pytest.approx(0.0)
    assert DualModePlanner().should_stop(sharp)
    assert not DualModePlanner().should_stop(flat)


def test_smoothing_stays_on_its_side_of_walls() -> None:
    occ = np.zeros((10, 10), np.uint8)
    occ[:, 5] = 1
    w = np.zeros(occ.shape)
    w[5, 6] = 1.0
    p = blur_probs(w, occ, 2.0, 0.0)
    assert p.sum() == pytest.approx(1.0)
    assert p[:, :6].sum() == pytest.approx(0.0, abs=1e-15)
    assert p[5, 6] == p.max()
    q = blur_probs(w, occ, 1.0, 1e-3)
    assert (q[occ == 0] > 0).all() and (q[occ == 1] == 0).all()
