"""Infotaxis / Entrotaxis: outcome models, expected entropy, the choice on a hand-made posterior."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.errors import InputDataError
from dgse.localization.infotaxis import (
    InfotaxisPlanner,
    ObstacleGaussianModel,
    VergassolaModel,
    expected_entropy,
    information_gain,
    outcome_probabilities,
)
from dgse.planning.paths import graph_for
from dgse.planning.planners import SearchHistory, get_planner


def _two_hypotheses() -> tuple[np.ndarray, Belief]:
    occ = np.zeros((20, 30), np.uint8)
    p = np.zeros(occ.shape)
    p[5, 5] = 0.5
    p[5, 25] = 0.5
    return occ, Belief(occ, 0.1, normalize_source_probs(p, occ))


def test_outcome_probabilities_sum_to_one() -> None:
    mu = np.array([[0.0, 0.5, 3.0], [1.0, 10.0, 0.1]])
    P = outcome_probabilities(mu, "poisson")
    np.testing.assert_allclose(P.sum(axis=1), 1.0, atol=1e-9)
    assert P[0, 0, 0] == pytest.approx(1.0)  # zero rate: no hit for sure
    G = outcome_probabilities(mu, "gaussian", sigma=0.2 + 0.3 * mu, n_bins=8)
    assert G.shape == (2, 8, 3)
    np.testing.assert_allclose(G.sum(axis=1), 1.0, atol=1e-9)
    with pytest.raises(InputDataError):
        outcome_probabilities(mu, "gaussian")


def test_expected_entropy_limits() -> None:
    p = np.array([0.25, 0.25, 0.5])
    perfect = np.eye(3)[None]  # the outcome names the source
    eh, hz = expected_entropy(p, perfect)
    assert eh[0] == pytest.approx(0.0, abs=1e-12)
    assert hz[0] == pytest.approx(-(p * np.log(p)).sum())
    useless = np.full((1, 2, 3), 0.5)
    eh, _ = expected_entropy(p, useless)
    assert eh[0] == pytest.approx(-(p * np.log(p)).sum())


def test_infotaxis_picks_the_informative_cell() -> None:
    occ, belief = _two_hypotheses()
    graph = graph_for(occ, 0.1)
    model = ObstacleGaussianModel(graph, 100.0, 0.5, 0.1, 1.0)
    near_a = (5, 7)  # reads ~100 ppm if the source is A, ~0 if B
    middle = (15, 15)  # equally far from both: reads the same either way
    gain, _ = information_gain(belief.source_probs, model, np.array([near_a, middle]))
    assert gain[0] == pytest.approx(math.log(2), rel=0.02)
    assert gain[1] < 1e-3
    planner = InfotaxisPlanner(radius_m=3.0, max_candidates=500)
    bel = Belief(occ, 0.1, belief.source_probs, info={"response_model": model})
    robot = (10, 15)
    d = graph.distances_from(robot)
    goal = planner.next_goal(bel, robot, d, SearchHistory(graph, rng=np.random.default_rng(0)))
    assert goal is not None
    # any informative cell lies within the plume of A or B, not on the symmetry line
    assert abs(goal[1] - 15) > 3
    assert planner.last_scores["scores"].max() > 0.5


def test_vergassola_model_and_entrotaxis() -> None:
    occ, belief = _two_hypotheses()
    graph = graph_for(occ, 0.1)
    m = VergassolaModel(graph, wind=(1.0, 0.0))
    rates = m.mean_readings(np.array([[5, 10], [5, 0]]))
    assert rates.shape == (2, 20, 30)
    assert rates[0, 5, 5] > rates[1, 5, 5]  # downwind of A beats upwind of A
    for criterion in ("infotaxis", "entrotaxis"):
        planner = get_planner(criterion, radius_m=1.0, max_candidates=20)
        robot = (10, 15)
        goal = planner.next_goal(belief, robot, graph.distances_from(robot), SearchHistory(graph))
        assert goal is not None and occ[goal] == 0 and goal != robot
        assert planner.name == criterion


def test_planner_options_and_stop() -> None:
    with pytest.raises(InputDataError):
        get_planner("infotaxis", no_such_option=1)
    with pytest.raises(InputDataError):
        InfotaxisPlanner(hit="binary")  # type: ignore[arg-type]
    occ, belief = _two_hypotheses()
    assert InfotaxisPlanner(eta=0.2).should_stop(belief)  # log 2 / log 600 < 0.2
    uniform = Belief(occ, 0.1, normalize_source_probs(np.ones(occ.shape), occ))
    assert not InfotaxisPlanner().should_stop(uniform)
    with pytest.raises(InputDataError, match="response model"):
        InfotaxisPlanner(model="belief").response_model(uniform)
