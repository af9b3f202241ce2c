"""Prior knowledge: what each level holds, what estimators accept, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.belief.knowledge import LEVELS, Knowledge, KnowledgeUser, check_level
from dgse.errors import InputDataError, UnsupportedError
from dgse.estimators.registry import estimator_names, get_estimator
from dgse.physics.scenario import solve_cases
from tests.conftest import two_rooms


@pytest.fixture(scope="module")
def case():
    return solve_cases(two_rooms(), 1.0, [((2.05, 0.55), 0.8)])[0]


def test_each_level_holds_what_it_allows_and_no_truth(case):
    m = Knowledge.from_case(case, "map")
    assert m.level == "map" and not m.has_openings and m.wind is None and m.inlet_velocity is None
    assert np.array_equal(m.occupancy, case.occupancy) and m.resolution == case.resolution
    with pytest.raises(UnsupportedError, match=r"openings .* not known at knowledge level 'map'"):
        _ = m.layout
    o = Knowledge.from_case(case, "openings")
    assert o.has_openings and o.layout.inlets == case.layout.inlets and o.wind is None
    w = Knowledge.from_case(case, "wind")
    assert np.array_equal(w.wind, case.wind) and w.inlet_velocity == case.inlet_velocity
    assert [k.covers("openings") for k in (m, o, w)] == [False, True, True]
    # nothing of the scenario's truth beyond the level: no concentration, no source, anywhere
    for k in (m, o, w):
        values = [getattr(k, f) for f in ("occupancy", "resolution", "inlets", "outlets", "wind", "name")]
        for v in values:
            assert not (
                isinstance(v, np.ndarray)
                and v.shape == case.concentration.shape
                and np.array_equal(v, case.concentration)
            )
        assert not hasattr(k, "concentration") and not hasattr(k, "source")
        assert k.to_dict()["level"] == k.level
    # the arrays are read-only copies
    with pytest.raises(ValueError):
        w.wind[0, 0, 0] = 1.0


def test_bad_knowledge_is_a_clear_error(case):
    with pytest.raises(InputDataError, match="unknown knowledge level 'all'"):
        check_level("all")
    with pytest.raises(InputDataError, match="wind field has shape"):
        Knowledge("wind", case.occupancy, case.resolution, wind=np.zeros((2, 3, 3)))
    wind = np.array(case.wind)
    solid = case.occupancy == 1
    wind[0][solid] = 0.5
    with pytest.raises(InputDataError, match="flow through walls"):
        Knowledge("wind", case.occupancy, case.resolution, wind=wind)
    with pytest.raises(InputDataError, match="NaN"):
        Knowledge("wind", case.occupancy, case.resolution, wind=np.full_like(case.wind, np.nan))
    with pytest.raises(InputDataError, match="needs at least one inlet"):
        Knowledge("openings", case.occupancy, case.resolution)
    with pytest.raises(InputDataError, match="map alone"):
        Knowledge("map", case.occupancy, case.resolution, inlets=case.layout.inlets)
    k = Knowledge.from_case(case, "map")
    with pytest.raises(InputDataError, match="not the map of its knowledge"):
        k.check_map(np.zeros((4, 4)), case.resolution)


def test_every_estimator_declares_levels_and_refuses_others(case):
    for name in estimator_names():
        est = get_estimator(name)
        assert isinstance(est, KnowledgeUser), name
        levels = est.knowledge_levels
        assert levels and set(levels) <= set(LEVELS), name
        for level in LEVELS:
            k = Knowledge.from_case(case, level)
            if level in levels:
                continue
            with pytest.raises(UnsupportedError, match=rf"works at knowledge level .*not '{level}'"):
                est.set_knowledge(k)
    assert get_estimator("adjoint").knowledge_levels == ("openings", "wind")
    assert get_estimator("adjoint-oracle").knowledge_levels == ("wind",)
    assert "map" in get_estimator("dgse-s").knowledge_levels


def test_adjoint_uses_the_openings_it_is_told(case):
    obs_cells = np.array([[5, 5], [10, 20], [15, 25], [3, 28]])
    from dgse.sensing.sensors import Observations

    obs = Observations(
        obs_cells,
        case.concentration[obs_cells[:, 0], obs_cells[:, 1]],
        case.wind[:, obs_cells[:, 0], obs_cells[:, 1]].T,
    )
    est = get_estimator("adjoint", knowledge=Knowledge.from_case(case, "openings"), candidate_speeds=(1.0,))
    b = est.estimate(case.occupancy, case.resolution, obs)
    assert b.info["knowledge"] == "openings"
    with pytest.raises(InputDataError, match="not the map of its knowledge"):
        est.estimate(np.zeros_like(case.occupancy), case.resolution, obs)
    with pytest.raises(UnsupportedError, match="give --knowledge openings"):
        get_estimator("adjoint", knowledge=Knowledge.from_case(case, "map"))


class _Spy(KnowledgeUser):
    """Records everything the loops hand over; answers a uniform belief."""

    name = "spy"

    def __init__(self) -> None:
        self.seen: list[object] = []

    def _use_knowledge(self, knowledge: Knowledge) -> None:
        self.seen.append(knowledge)

    def estimate(self, occupancy, resolution, observations):
        from dgse.belief.belief import Belief, normalize_source_probs

        self.seen += [occupancy, resolution, observations]
        probs = normalize_source_probs(np.ones(occupancy.shape), occupancy)
        return Belief(occupancy, resolution, probs)


@pytest.mark.parametrize("loop", ["evaluate", "search"])
def test_an_estimator_at_map_cannot_reach_the_truth(case, loop):
    """The evaluation and search loops hand an estimator at 'map' the map and readings only."""
    from dgse.evaluation.evaluate import evaluate
    from dgse.planning.planners import get_planner
    from dgse.search.episode import run_episode
    from dgse.world.case import Case

    spy = _Spy()
    if loop == "evaluate":
        res = evaluate([case], spy, [5, 10], trials=2, knowledge="map")
        assert res["knowledge"] == "map"
    else:
        run_episode(case, spy, get_planner("utility"), rng=0, time_limit=60.0, record=False)
    told = [x for x in spy.seen if isinstance(x, Knowledge)]
    assert told and all(k.level == "map" for k in told)
    for k in told:
        assert k.wind is None and k.inlet_velocity is None and not k.inlets and not k.outlets
    truth = (case.wind, case.concentration)
    for x in spy.seen:
        assert not isinstance(x, Case)
        if isinstance(x, np.ndarray):
            assert not any(x.shape == t.shape and np.array_equal(x, t) for t in truth)
    # the readings are noisy samples at a few cells, never the fields themselves
    obs = [x for x in spy.seen if hasattr(x, "gas")]
    assert obs and all(len(o) < case.free.sum() for o in obs)
