"""The search loop: termination, time limit, clock bookkeeping, records, seeding, a real DGSE network."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

from dgse.errors import InputDataError
from dgse.estimators.dgse import DGSEEstimator
from dgse.planning.information import InformationPlanner, InformationStop
from dgse.planning.paths import graph_for
from dgse.planning.planners import Deadline, PlannerBase, StopRule, UtilityPlanner
from dgse.search.episode import run_episode
from dgse.search.metrics import episode_metrics
from dgse.sensing.noise import NoiseParams
from tests.models.helpers import tiny_model
from tests.search import PeakEstimator, UniformEstimator, corridor_case, solved_two_rooms

torch.set_num_threads(1)


def test_entropy_termination_ends_the_search():
    case = corridor_case()
    est = PeakEstimator(sigma=0.05)
    r = run_episode(case, est, UtilityPlanner(), start=(5, 2), rng=0, noise_params=NoiseParams.zero())
    assert r.reason == "converged" and r.terminated
    # the posterior is a narrow peak at the first (highest) reading: it stops at once, where it stands
    assert r.n_steps == 1 and est.calls == 1
    last = r.steps[-1]
    assert last.normalized_entropy <= 0.65 and last.goal is None
    assert r.search_time_s == pytest.approx(3.0) and r.distance_m == 0.0
    assert r.estimate_xy == pytest.approx(((2 + 0.5) * 0.1, (5 + 0.5) * 0.1))


def test_search_climbs_to_the_source_and_succeeds():
    case = corridor_case()  # source at (5, 25)
    est = PeakEstimator(adaptive=True)  # wide and exploring until it smells a lot of gas
    r = run_episode(
        case,
        est,
        UtilityPlanner(stop=StopRule(eta=0.4)),
        start=(5, 2),
        rng=1,
        noise_params=NoiseParams.zero(),
        time_limit=400,
    )
    assert r.reason == "converged", (r.reason, r.n_steps)
    assert r.n_steps > 2 and r.distance_m > 1.0 and r.error_m < 0.45
    # the goal is never the cell the robot stands on; each step measures where the last goal was
    for a, b in zip(r.steps[:-1], r.steps[1:], strict=True):
        assert a.goal != a.cell and b.cell == a.goal
    # the clock is travel + dwell (no computation time)
    assert r.search_time_s == pytest.approx(r.n_steps * 3.0 + r.distance_m / 0.5)
    assert r.shortest_path_m == pytest.approx(2.3)
    assert r.settings["noise"] == NoiseParams.zero().to_dict()
    times = [s.time_s for s in r.steps]
    assert times == sorted(times) and r.trajectory_times[-1] <= r.search_time_s


def test_no_gas_ends_at_the_time_limit():
    case = corridor_case(gas=False)
    r = run_episode(case, UniformEstimator(), UtilityPlanner(), rng=2, time_limit=40.0)
    assert r.reason == "time_limit" and not r.terminated
    assert r.search_time_s == 40.0 and r.n_steps >= 5
    assert all(s.gas == 0.0 for s in r.steps)
    assert r.steps[-1].time_s <= 40.0 and r.trajectory_times[-1] <= 40.0
    i, j = np.nonzero(case.free)
    assert r.estimate_xy == pytest.approx(((j + 0.5).mean() * 0.1, (i + 0.5).mean() * 0.1))
    assert r.recorded and r.steps[0].wind_mean is None and r.steps[0].source_probs.shape == (10, 30)
    # shorter than one dwell: no measurement at all, the estimate is the free-cell centroid
    none = run_episode(case, UniformEstimator(), UtilityPlanner(), rng=2, time_limit=2.0)
    assert none.n_steps == 0 and none.reason == "time_limit" and none.end_errors_m == {}
    assert none.estimate_xy == pytest.approx(r.estimate_xy)


def _deadline_only(**deadline) -> InformationPlanner:
    """The information planner with a stop that never passes: only its deadline ends a search."""
    return InformationPlanner(stop=InformationStop(radius_m=0.01, level=1.0), deadline=Deadline(**deadline))


def test_deadline_stop_ends_before_the_limit():
    """deadline.margin_s: the search that would time out declares its estimate instead."""
    case = corridor_case(gas=False)
    r = run_episode(case, UniformEstimator(), _deadline_only(margin_s=10.0), rng=2, time_limit=100.0)
    assert r.reason == "deadline" and r.terminated
    assert 90.0 <= r.search_time_s < 100.0
    # deadline.estimate_radius_m: the declared source, not the belief's mean (which the steps keep)
    planner = _deadline_only(margin_s=10.0, estimate_radius_m=0.3)
    d = run_episode(case, UniformEstimator(), planner, rng=2, time_limit=100.0)
    assert d.reason == "deadline" and d.steps[-1].estimate_xy == pytest.approx(r.estimate_xy)
    assert d.estimate_xy != pytest.approx(r.estimate_xy)
    sx, sy = d.source_xy
    assert d.error_m == pytest.approx(math.hypot(d.estimate_xy[0] - sx, d.estimate_xy[1] - sy))
    # both record every point estimate's error (the mean's is the plain run's)
    assert r.end_errors_m["mean"] == pytest.approx(r.error_m) == pytest.approx(d.end_errors_m["mean"])
    assert {"mean", "mode", "disk0.5m", "local1m"} <= set(d.end_errors_m)
    assert d.to_dict()["end_errors_m"] == d.end_errors_m


def test_seeding_compute_time_and_downsampled_records():
    case = corridor_case(gas=False)
    a = run_episode(case, UniformEstimator(), UtilityPlanner(), rng=7, time_limit=30.0, record=False)
    b = run_episode(case, PeakEstimator(), UtilityPlanner(), rng=7, time_limit=30.0, record_max_cells=40)
    assert a.start_cell == b.start_cell  # the start depends on the seed only
    assert a.settings["noise"] == b.settings["noise"]
    assert not a.recorded and b.recorded and b.record_factor == 3
    assert b.steps[0].source_probs.shape == (4, 10)
    assert b.steps[0].source_probs.sum() == pytest.approx(1, abs=1e-5)
    assert b.steps[0].wind_mean.shape == (2, 4, 10)
    again = run_episode(case, UniformEstimator(), UtilityPlanner(), rng=7, time_limit=30.0, record=False)
    np.testing.assert_array_equal(a.trajectory_cells, again.trajectory_cells)
    assert [s.gas for s in a.steps] == [s.gas for s in again.steps]

    slow = PeakEstimator(sleep=0.02)
    c = run_episode(case, slow, UtilityPlanner(), rng=7, time_limit=30.0, include_compute_time=True)
    compute = sum(s.compute_s for s in c.steps)
    assert compute >= 0.02 * c.n_steps
    assert all(s.inference_s >= 0.02 and s.preprocessing_s >= 0 and s.planning_s > 0 for s in c.steps)
    # the clock at the last reading: dwells + travel + the computation of the steps before it
    t_last = c.steps[-1].time_s
    k = int(np.searchsorted(c.trajectory_times, t_last, side="right"))
    travel = graph_for(case.occupancy, 0.1).path_length(c.trajectory_cells[:k]) / 0.5
    assert t_last == pytest.approx(c.n_steps * 3.0 + travel + sum(s.compute_s for s in c.steps[:-1]))


def test_on_step_reports_every_step_as_it_happens():
    case = corridor_case(gas=False)
    seen = []
    r = run_episode(case, UniformEstimator(), UtilityPlanner(), rng=2, time_limit=40.0, on_step=seen.append)
    assert seen == r.steps  # the same records, in order, one per step
    clock = [s.time_s for s in seen]
    assert [s.step for s in seen] == list(range(1, r.n_steps + 1))
    assert all(b > a for a, b in itertools.pairwise(clock)) and clock[-1] <= 40.0
    assert all(0.0 <= s.normalized_entropy <= 1.0 and math.isfinite(s.error_m) for s in seen)
    # an exception from the callback (Ctrl-C) ends the episode at once
    calls = []

    def stop_at_third(rec):
        calls.append(rec.step)
        if rec.step == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_episode(case, UniformEstimator(), UtilityPlanner(), rng=2, time_limit=40.0, on_step=stop_at_third)
    assert calls == [1, 2, 3]


def test_planner_stop_signal():
    class OneStep(UtilityPlanner):
        def next_goal(self, belief, robot_cell, distances, history):
            return None if history.step >= 2 else super().next_goal(belief, robot_cell, distances, history)

    r = run_episode(corridor_case(gas=False), UniformEstimator(), OneStep(), rng=0, time_limit=100.0)
    assert r.reason == "planner_stop" and r.terminated and r.n_steps == 2 and r.search_time_s < 100.0


def test_dgse_network_in_the_loop():
    case = solved_two_rooms()
    est = DGSEEstimator(tiny_model("dgse-s"), K=2, T=1, seed=0, canvas_minimum=32)
    r = run_episode(case, est, UtilityPlanner(), rng=0, time_limit=25.0)
    assert r.method == "dgse-s" and r.planner == "utility"
    assert 1 <= r.n_steps <= 8 and math.isfinite(r.error_m)
    s = r.steps[0]
    assert s.wind_mean.shape == (2, 20, 30) and s.log_conc_mean.shape == (20, 30)
    assert (case.occupancy[r.trajectory_cells[:, 0], r.trajectory_cells[:, 1]] == 0).all()


# -- readings on the way (sample_rate_hz) ----------------------------------------------------------
class Scripted(PlannerBase):
    """Goes to ``goals`` in turn, never stops by itself; records what it is told each decision."""

    name = "scripted"

    def __init__(self, goals):
        self.goals, self.seen = list(goals), []

    def reset(self):
        self.left, self.seen = list(self.goals), []

    def should_stop(self, belief, history):
        return False

    def next_goal(self, belief, robot_cell, distances, history):
        self.seen.append((history.step, len(history.observations), history.time_s))
        return self.left.pop(0) if self.left else None


def test_without_a_sample_rate_the_episode_is_the_papers():
    case = solved_two_rooms()
    runs = [
        run_episode(
            case,
            PeakEstimator(adaptive=True),
            UtilityPlanner(stop=StopRule(eta=0.2)),
            rng=0,
            time_limit=60.0,
            **kw,
        )
        for kw in ({}, {"sample_rate_hz": None})
    ]
    a, b = runs
    np.testing.assert_array_equal(a.trajectory_cells, b.trajectory_cells)
    np.testing.assert_array_equal(a.trajectory_times, b.trajectory_times)
    assert [s.goal for s in a.steps] == [s.goal for s in b.steps] and a.n_steps > 2
    assert [(s.cell, s.gas, s.wind, s.time_s) for s in a.steps] == [
        (s.cell, s.gas, s.wind, s.time_s) for s in b.steps
    ]
    np.testing.assert_array_equal(a.readings.gas, b.readings.gas)
    assert a.n_readings == a.n_steps == len(a.readings) and all(s.n_readings == 1 for s in a.steps)
    assert "sample_rate_hz" not in a.settings and a.to_dict()["n_readings"] == a.n_steps


def test_readings_on_the_way_go_into_the_estimate_and_the_planner_decides_at_goals():
    """There and back along a 2 m corridor at 0.5 m/s, 2 Hz: 7 readings on each 4 s drive."""
    case = corridor_case()
    est, planner = PeakEstimator(), Scripted([(5, 20), (5, 0)])
    kw = {"start": (5, 0), "rng": 0, "noise_params": NoiseParams.zero(), "time_limit": 100.0}
    r = run_episode(case, est, planner, sample_rate_hz=2.0, **kw)
    assert r.reason == "planner_stop" and r.n_steps == 3 and est.calls == 3  # one estimate per step
    assert [s.n_readings for s in r.steps] == [1, 8, 8] and r.n_readings == 17 == len(r.readings)
    way = np.arange(1, 8) * 0.5
    np.testing.assert_allclose(r.readings.times, [3.0, *(3.0 + way), 10.0, *(10.0 + way), 17.0])
    there = [0, 3, 5, 8, 10, 13, 15, 18, 20]
    np.testing.assert_array_equal(r.readings.cells[:, 1], [*there, *(20 - np.array(there[1:]))])
    np.testing.assert_allclose(
        r.readings.gas, case.concentration[r.readings.cells[:, 0], r.readings.cells[:, 1]]
    )
    # the planner is asked at the goals only, told every reading so far
    assert [(n, m) for n, m, _ in planner.seen] == [(1, 1), (9, 9), (17, 17)]
    assert [t for _, _, t in planner.seen] == pytest.approx([3.0, 10.0, 17.0])
    # sampling takes no time: the clock and distance of the plain episode
    plain = run_episode(case, PeakEstimator(), Scripted([(5, 20), (5, 0)]), **kw)
    assert r.search_time_s == plain.search_time_s == pytest.approx(3 * 3.0 + 4.0 / 0.5)
    assert r.distance_m == plain.distance_m == pytest.approx(4.0)
    np.testing.assert_array_equal(r.trajectory_cells, plain.trajectory_cells)
    assert [s.time_s for s in r.steps] == [s.time_s for s in plain.steps]
    assert r.settings["sample_rate_hz"] == 2.0 and "sample_rate_hz" not in plain.settings
    m = episode_metrics(r)
    assert m["n_steps"] == 3 and m["n_readings"] == 17 and episode_metrics(plain)["n_readings"] == 3
    assert r.to_dict(steps=True)["steps"][1]["n_readings"] == 8
    # a drive the time limit cuts short: its readings reach no estimate
    cut = run_episode(
        case, PeakEstimator(), Scripted([(5, 20), (5, 0)]), sample_rate_hz=2.0, **{**kw, "time_limit": 12.0}
    )
    assert cut.reason == "time_limit" and cut.n_steps == 2 and cut.n_readings == 9 == len(cut.readings)


def test_readings_on_the_way_with_the_utility_planner_and_bad_rates():
    case = corridor_case()
    kw = {"start": (5, 2), "rng": 1, "time_limit": 200.0}
    r = run_episode(
        case, PeakEstimator(adaptive=True), UtilityPlanner(stop=StopRule(eta=0.4)), sample_rate_hz=1.0, **kw
    )
    assert r.n_readings > r.n_steps and r.readings.times.tolist() == sorted(r.readings.times.tolist())
    assert r.search_time_s == pytest.approx(r.n_steps * 3.0 + r.distance_m / 0.5)
    # every reading on the way lies on the trajectory, between the goals it was taken between
    on_path = {tuple(c) for c in r.trajectory_cells.tolist()}
    assert all(tuple(c) in on_path for c in r.readings.cells.tolist())
    for bad in (0.0, -2.0, math.nan):
        with pytest.raises(InputDataError, match="sample_rate_hz must be a positive number"):
            run_episode(case, UniformEstimator(), UtilityPlanner(), sample_rate_hz=bad, **kw)


@pytest.mark.parametrize(
    ("method", "cells", "estimate"),
    [
        ("dgse-s", [(5, 2), (1, 2), (3, 5), (3, 9), (0, 7), (0, 11), (1, 13), (1, 15)], (1.55, 0.286465)),
        ("dgse-phys", [(5, 2), (4, 2), (3, 2), (2, 2), (1, 2)], (0.486049, 0.515778)),
    ],
)
def test_the_presets_planners_keep_their_searches(method, cells, estimate):
    """Each preset's planner with its options on a fixed noise-free search: the cells measured
    and the declared source are pinned, so a change of the utility planner's entropy rule or of
    the information planner's choice or stop shows here."""
    from dgse.planning.planners import get_planner
    from dgse.presets import resolve

    run = resolve(method, "openings", search=True)
    planner = get_planner(run.planner, **run.planner_options)
    r = run_episode(
        corridor_case(),
        PeakEstimator(adaptive=True),
        planner,
        start=(5, 2),
        rng=4,
        noise_params=NoiseParams.zero(),
        time_limit=400,
    )
    assert r.reason == "converged"
    assert [tuple(int(v) for v in s.cell) for s in r.steps] == cells
    assert r.estimate_xy == pytest.approx(estimate, abs=1e-6)
