"""The utility planner on hand-made beliefs; entropy termination; the planner registry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.errors import InputDataError, UnsupportedError
from dgse.planning.paths import FreeSpaceGraph
from dgse.planning.planners import (
    Deadline,
    Planner,
    PlannerBase,
    SearchHistory,
    StopRule,
    UtilityPlanner,
    UtilityWeights,
    disk_estimate,
    get_planner,
    mass_within,
    planner_names,
    point_estimates,
    register_planner,
)
from dgse.sensing.sensors import Observations


def _belief(occ, probs, res=1.0, wind_var=None, conc_var=None) -> Belief:
    H, W = occ.shape
    kw = {}
    if wind_var is not None:
        kw.update(wind_mean=np.zeros((2, H, W)), wind_var=wind_var)
    if conc_var is not None:
        kw.update(log_conc_mean=np.zeros((H, W)), log_conc_var=conc_var)
    return Belief(occ, res, normalize_source_probs(probs, occ), **kw)


def _history(graph, cells=()) -> SearchHistory:
    c = np.array(cells, np.int64).reshape(-1, 2)
    return SearchHistory(graph, Observations(c, np.zeros(len(c)), np.zeros((len(c), 2))))


def test_utility_formula_and_choice():
    """A 1 x 12 corridor of 1 m cells, robot at 0: the nearer, smaller peak wins after the discount."""
    occ = np.zeros((1, 12), np.uint8)
    occ[0, 6] = 1  # a wall: cells beyond it are unreachable
    g = FreeSpaceGraph(occ, 1.0)
    p = np.full((1, 12), 1.0)
    p[0, 2], p[0, 5], p[0, 9] = 30.0, 36.0, 1000.0  # the biggest peak is behind the wall
    wv = np.zeros((2, 1, 12))
    wv[:, 0, 4] = 8.0  # var(u_x) + var(u_y) = 16
    cv = np.zeros((1, 12))
    cv[0, 3] = 3.0
    b = _belief(occ, p, wind_var=wv, conc_var=cv)
    d = g.distances_from((0, 0))
    planner = UtilityPlanner()
    u = planner.utility(b, d)
    pi = b.source_probs[0]
    for j in range(12):
        if j >= 6:
            assert u[0, j] == -math.inf
            continue
        gain = 100.0 * pi[j] + 0.25 * wv[:, 0, j].sum() + 2.0 * cv[0, j]
        assert u[0, j] == pytest.approx(math.exp(-0.1 * j) * gain, rel=1e-12)
    expected = max(range(1, 6), key=lambda j: u[0, j])
    assert planner.next_goal(b, (0, 0), d, _history(g)) == (0, expected)


def test_goal_is_never_the_current_cell_nor_a_measured_cell():
    occ = np.zeros((5, 5), np.uint8)
    g = FreeSpaceGraph(occ, 0.1)
    p = np.full((5, 5), 1e-6)
    p[2, 2] = 1.0  # the robot stands on the peak
    p[2, 3] = 1e-2
    p[1, 2] = 5e-3
    b = _belief(occ, p, res=0.1)
    planner = UtilityPlanner()
    d = g.distances_from((2, 2))
    assert planner.next_goal(b, (2, 2), d, _history(g)) == (2, 3)
    assert planner.next_goal(b, (2, 2), d, _history(g, [(2, 2), (2, 3)])) == (1, 2)
    # every other cell measured: measured cells are allowed again, never the robot's own
    all_cells = [(i, j) for i in range(5) for j in range(5)]
    assert planner.next_goal(b, (2, 2), d, _history(g, all_cells)) == (2, 3)
    # a one-cell map: nowhere to go
    one = np.ones((3, 3), np.uint8)
    one[1, 1] = 0
    b1 = _belief(one, np.ones((3, 3)))
    g1 = FreeSpaceGraph(one, 1.0)
    assert planner.next_goal(b1, (1, 1), g1.distances_from((1, 1)), _history(g1)) is None


def test_ties_go_to_the_nearest_cell():
    occ = np.zeros((1, 9), np.uint8)
    g = FreeSpaceGraph(occ, 1.0)
    b = _belief(occ, np.ones((1, 9)))  # uniform: utility decreases with distance only
    assert UtilityPlanner().next_goal(b, (0, 4), g.distances_from((0, 4)), _history(g)) == (0, 3)
    flat = UtilityPlanner(weights=UtilityWeights(w_d=0.0))  # all equal: nearest, then lowest index
    assert flat.next_goal(b, (0, 4), g.distances_from((0, 4)), _history(g)) == (0, 3)


def test_entropy_termination():
    occ = np.zeros((10, 10), np.uint8)
    occ[0, :] = 1
    planner = UtilityPlanner(stop=StopRule(eta=0.65))
    uniform = _belief(occ, np.ones((10, 10)))
    assert not planner.should_stop(uniform, None)
    N = 90
    peaked = np.zeros((10, 10))
    peaked[5, 5] = 1.0
    assert planner.should_stop(_belief(occ, peaked), None)
    # uniform over M cells: H = log M; stops iff log M <= eta log N
    for M, stops in ((int(N**0.65), True), (int(N**0.65) + 1, False)):
        p = np.zeros((10, 10))
        p[1:, :].flat[:M] = 1.0
        assert planner.should_stop(_belief(occ, p), None) is stops, M
    assert UtilityPlanner(stop=StopRule(eta=1.0)).should_stop(uniform, None)


def test_min_observations_delays_the_entropy_test():
    occ = np.zeros((10, 10), np.uint8)
    peaked = np.zeros((10, 10))
    peaked[5, 5] = 1.0
    belief = _belief(occ, peaked)
    history = _history(FreeSpaceGraph(occ, 1.0))
    planner = UtilityPlanner(stop=StopRule(min_observations=5))
    for step, stops in ((1, False), (4, False), (5, True), (9, True)):
        history.step = step
        assert planner.should_stop(belief, history) is stops, step
    history.step = 1
    assert UtilityPlanner().should_stop(belief, history)  # the paper's rule: from the first reading
    for bad in (-1, 2.5, True):
        with pytest.raises(InputDataError, match=r"stop\.min_observations"):
            UtilityPlanner(stop=StopRule(min_observations=bad))


def test_a_deadline_stop_can_declare_the_disk_with_the_most_mass():
    """deadline.estimate_radius_m: a split posterior's mean lies between its parts; the disk doesn't."""
    occ = np.zeros((20, 20), np.uint8)
    p = np.full((20, 20), 1e-9)
    p[10, 2] = 0.45  # one sharp cell on the west
    p[9:12, 16:19] = 0.55 / 9  # a broader blob on the east holding more
    belief = _belief(occ, p, res=0.1)
    disk = Deadline(estimate_radius_m=0.15)
    mean = belief.source_estimate()
    assert Deadline().declare(belief, True) == mean
    assert disk.declare(belief, False) == mean  # a stop before the deadline declares the mean
    x, y = disk.declare(belief, True)
    assert (x, y) == pytest.approx((1.75, 1.05))  # the east blob's centre cell
    assert abs(mean[0] - 1.0) < 0.1  # the mean: between the two, where neither is
    assert PlannerBase().declare(belief, True) == mean  # planners without a deadline: the mean
    assert UtilityPlanner().declare(belief, True) == mean
    with pytest.raises(InputDataError, match=r"deadline\.estimate_radius_m"):
        Deadline(estimate_radius_m=-1.0)
    # every reading of it at once: the mode is the sharp west cell, 0.5-2 m disks the east blob
    est = point_estimates(belief)
    assert est["mean"] == mean and est["mode"] == pytest.approx((0.25, 1.05))
    radii = ("0.5m", "1m", "2m")
    assert set(est) == {"mean", "mode", *(f"{w}{r}" for w in ("disk", "local") for r in radii)}
    # a 0.5 m disk holds the whole blob from several centres: one of them, east of the mean;
    # the mean within it is the blob's centre
    assert math.dist(est["disk0.5m"], (1.75, 1.05)) <= 0.5 and est["disk0.5m"][0] > 1.3
    assert est["local0.5m"] == pytest.approx((1.75, 1.05), abs=1e-6)
    assert est["disk1m"] == disk_estimate(belief, 1.0)
    # a 2 m disk holds both parts: its mean is the posterior's
    assert est["local2m"] == pytest.approx(mean, abs=1e-6)


def test_mass_within_is_the_disk_sum():
    rng = np.random.default_rng(3)
    p = rng.random((15, 12))
    got = mass_within(p, 0.1, 0.25)
    ii, jj = np.mgrid[0:15, 0:12]
    for i, j in [(0, 0), (7, 5), (14, 11), (3, 9)]:
        disk = np.hypot(ii - i, jj - j) * 0.1 <= 0.25 + 1e-9
        assert got[i, j] == pytest.approx(p[disk].sum(), rel=1e-9, abs=1e-12)


def test_deadline_is_reached_within_its_margin_and_the_utility_planner_has_none():
    """Deadline.margin_s: less than the margin (at most a tenth of the limit) left of the time
    limit; the utility planner (the paper's rule) has no deadline stop."""
    occ = np.zeros((10, 10), np.uint8)
    belief = _belief(occ, np.ones((10, 10)))  # flat: the entropy test never passes
    graph = FreeSpaceGraph(occ, 0.1)
    h = _history(graph, [(1, 1)] * 6)
    h.step, h.time_limit_s = 6, 2000.0
    deadline = Deadline(margin_s=60.0)
    h.time_s = 1900.0
    assert not deadline.reached(h)
    h.time_s = 1945.0
    assert deadline.reached(h) and not Deadline().reached(h) and not deadline.reached(None)
    utility = UtilityPlanner(stop=StopRule(min_observations=5))
    assert not utility.should_stop(belief, h) and not utility.deadline_reached(h)
    h.time_limit_s, h.time_s = 60.0, 10.0
    assert not deadline.reached(h)  # a short limit: at most a tenth of it is the margin
    h.time_s = 55.0
    assert deadline.reached(h)
    h.time_limit_s = math.inf
    assert not deadline.reached(h)
    with pytest.raises(InputDataError, match=r"deadline\.margin_s"):
        Deadline(margin_s=-1.0)


def test_registry():
    assert "utility" in planner_names()
    p = get_planner("utility", **{"stop.eta": 0.75})
    assert isinstance(p, UtilityPlanner) and isinstance(p, Planner) and p.name == "utility"
    assert p.stop == StopRule(eta=0.75) and p.weights == UtilityWeights()
    with pytest.raises(UnsupportedError, match=r"known planners: .*utility"):
        get_planner("nope")
    with pytest.raises(
        InputDataError, match=r"unknown planner .utility. option\(s\) bogus; known: .*stop\.eta"
    ):
        get_planner("utility", bogus=1)
    known = r"known: stop\.eta, stop\.min_observations$"
    with pytest.raises(InputDataError, match=r"option\(s\) stop\.etta; " + known):
        get_planner("utility", **{"stop.etta": 0.7})
    # the paper's rule and nothing else: no mass stop, no deadline
    for key in ("stop.mass_radius_m", "weights.source_radius_m", "deadline.margin_s"):
        with pytest.raises(InputDataError, match=rf"option\(s\) {key}; known"):
            get_planner("utility", **{key: 1.0})
    with pytest.raises(InputDataError, match=r"option stop\.eta='high' must be a number"):
        get_planner("utility", **{"stop.eta": "high"})
    with pytest.raises(InputDataError, match=r"stop\.eta must lie in \[0, 1\]"):
        get_planner("utility", **{"stop.eta": 1.5})
    with pytest.raises(InputDataError, match=r"stop\.eta"):
        UtilityPlanner(stop=StopRule(eta=1.5))
    with pytest.raises(InputDataError, match="stop must be a StopRule"):
        UtilityPlanner(stop={"eta": 0.5})

    class Stay(PlannerBase):
        name = "test-stay"

        def should_stop(self, belief, history) -> bool:
            return False

        def next_goal(self, belief, robot_cell, distances, history):
            return None

    register_planner("test-stay", Stay)
    register_planner("test-stay", Stay)  # the same factory again: fine
    assert isinstance(get_planner("test-stay"), Planner)
    with pytest.raises(InputDataError, match="already registered"):
        register_planner("test-stay", UtilityPlanner)
    register_planner("test-lazy", "dgse.planning.planners:UtilityPlanner")
    assert get_planner("test-lazy", **{"weights.w_d": 0.2}).weights.w_d == 0.2
