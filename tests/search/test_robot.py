"""The simulated robot: never in a wall, one clock for travel and dwell, Table I readings, frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.planning.paths import graph_for
from dgse.search.robot import Robot, check_sample_rate, path_samples, random_start_cell
from dgse.sensing.noise import NoiseModel, NoiseParams
from tests.search import corridor_case


def _walled_case():
    occ = np.zeros((12, 30), np.uint8)
    occ[:, 10] = 1
    occ[5:7, 10] = 0  # a door
    occ[:, 20] = 1
    occ[9:11, 20] = 0
    occ[3:5, 3:6] = 1  # an obstacle
    return corridor_case(occ, source_cell=(2, 27))


def test_robot_never_enters_a_wall():
    case = _walled_case()
    rng = np.random.default_rng(0)
    robot = Robot(case, start=(1, 1), rng=1)
    free = np.argwhere(case.free)
    for goal in free[rng.choice(len(free), 12, replace=False)]:
        assert robot.move_to(goal)
        assert robot.cell == (int(goal[0]), int(goal[1]))
    cells = robot.trajectory_cells
    assert (case.occupancy[cells[:, 0], cells[:, 1]] == 0).all()
    steps = np.abs(np.diff(cells, axis=0))
    assert (steps.max(axis=1) == 1).all()  # neighbouring cells, one move at a time
    diag = (steps == 1).all(axis=1)
    a, b = cells[:-1][diag], cells[1:][diag]
    assert (case.occupancy[a[:, 0], b[:, 1]] == 0).all() and (case.occupancy[b[:, 0], a[:, 1]] == 0).all()
    assert robot.distance_m == pytest.approx(graph_for(case.occupancy, 0.1).path_length(cells))
    with pytest.raises(InputDataError, match="wall"):
        robot.move_to((0, 10))


def test_clock_adds_travel_and_dwell():
    case = corridor_case()
    robot = Robot(case, start=(5, 0), rng=0, speed=0.5, dwell=3.0, noise_model=NoiseModel.noiseless())
    assert robot.move_to((5, 10))  # 1.0 m straight
    assert robot.distance_m == pytest.approx(1.0)
    assert robot.clock == pytest.approx(2.0)
    np.testing.assert_allclose(robot.trajectory_times, np.arange(11) * 0.2)
    obs = robot.sense()
    assert robot.clock == pytest.approx(5.0) and obs.times[0] == pytest.approx(5.0)
    assert obs.gas[0] == pytest.approx(case.concentration[5, 10])  # noiseless: the truth
    np.testing.assert_allclose(obs.wind[0], case.wind[:, 5, 10])
    robot.move_to((6, 11))  # one diagonal step
    assert robot.clock == pytest.approx(5.0 + math.sqrt(2) * 0.1 / 0.5)
    robot.wait(0.25)
    assert robot.clock == pytest.approx(5.25 + math.sqrt(2) * 0.2)
    # stopping at a time limit part-way: the distance covered so far counts
    t0, d0 = robot.clock, robot.distance_m
    assert not robot.move_to((6, 29), until=t0 + 1.1)
    assert robot.clock == pytest.approx(t0 + 1.1)
    assert robot.distance_m - d0 == pytest.approx(0.55)
    assert robot.cell == (6, 16)  # the last cell fully reached
    assert len(robot.observations) == 1


def test_noise_drawn_once_per_episode():
    case = corridor_case()
    robot = Robot(case, start=(5, 3), rng=3)
    p = robot.noise_params
    assert p != NoiseParams.zero() and p.sigma_env <= 0.5 * float(case.concentration[case.free].mean())
    readings = [robot.sense() for _ in range(5)]
    assert all(o.noise == p for o in readings)
    assert len({float(o.gas[0]) for o in readings}) == 5  # fresh noise per reading
    again = Robot(case, start=(5, 3), rng=3)
    assert again.noise_params == p and float(again.sense().gas[0]) == float(readings[0].gas[0])


def test_frames_read_at_the_reading_time():
    frames = np.zeros((4, 10, 30), np.float32)
    for k in range(4):
        frames[k] = 10.0 * (k + 1)
    case = corridor_case(frames=frames, frame_dt=2.0)
    robot = Robot(case, start=(5, 5), rng=0, dwell=3.0, noise_params=NoiseParams.zero())
    assert robot.sense().gas[0] == pytest.approx(20.0)  # t = 3 s: frame 1
    assert robot.sense().gas[0] == pytest.approx(40.0)  # t = 6 s: frame 3
    assert robot.sense().gas[0] == pytest.approx(10.0)  # t = 9 s: frame 4 mod 4 = 0
    steady = Robot(case, start=(5, 5), rng=0, noise_params=NoiseParams.zero(), use_frames=False)
    obs = steady.sense()
    assert obs.gas[0] == pytest.approx(case.concentration[5, 5]) and obs.times[0] == 3.0


def test_random_start_is_seeded_connected_and_far():
    case = _walled_case()
    g = graph_for(case.occupancy, case.resolution)
    starts = {random_start_cell(g, np.random.default_rng(s), case.source_cell, 2.0) for s in range(20)}
    assert len(starts) > 5
    for s in starts:
        assert g.distance(s, case.source_cell) >= 2.0
    assert random_start_cell(g, np.random.default_rng(4), case.source_cell) == random_start_cell(
        g, np.random.default_rng(4), case.source_cell
    )
    # no cell that far: the farthest half instead of failing
    far = random_start_cell(g, np.random.default_rng(0), case.source_cell, 1e6)
    assert np.isfinite(g.distance(far, case.source_cell))
    robot = Robot(case, rng=5, min_start_distance=2.0)
    assert g.distance(robot.start, case.source_cell) >= 2.0 and robot.trajectory_cells.tolist() == [
        list(robot.start)
    ]


# -- readings on the way (sample_rate_hz) ----------------------------------------------------------
def _noiseless(case, **kw):
    return Robot(case, rng=0, noise_model=NoiseModel.noiseless(), **kw)


def test_readings_on_the_way_along_a_corridor():
    """A straight 2 m drive at 0.5 m/s (4 s): a reading every 1/f s before the arrival, at the
    cell the robot is in; the clock, distance and trajectory as without sampling."""
    case = corridor_case()
    plain = _noiseless(case, start=(5, 0))
    robot = _noiseless(case, start=(5, 0), sample_rate_hz=1.5)
    assert plain.move_to((5, 20)) and robot.move_to((5, 20))
    assert robot.clock == plain.clock == pytest.approx(4.0) and robot.distance_m == plain.distance_m
    np.testing.assert_array_equal(robot.trajectory_cells, plain.trajectory_cells)
    np.testing.assert_array_equal(robot.trajectory_times, plain.trajectory_times)
    obs = robot.observations
    # 4 s x 1.5 Hz = 6 intervals; the 6th reading would fall on the arrival: the goal's reading
    np.testing.assert_allclose(obs.times, np.arange(1, 6) / 1.5)
    # at x = 0.5 t m: cells 3.3, 6.7, 10, 13.3, 16.7 -> the nearest centres
    np.testing.assert_array_equal(obs.cells, [[5, 3], [5, 7], [5, 10], [5, 13], [5, 17]])
    np.testing.assert_allclose(obs.gas, case.concentration[obs.cells[:, 0], obs.cells[:, 1]])
    np.testing.assert_allclose(obs.wind, case.wind[:, obs.cells[:, 0], obs.cells[:, 1]].T)
    assert len(plain.observations) == 0
    # the goal's reading after the dwell comes on top; readings_since gives what is new
    goal = robot.sense()
    assert goal.times[0] == pytest.approx(7.0) and robot.n_readings == 6
    np.testing.assert_array_equal(robot.readings_since(5).cells, [[5, 20]])
    np.testing.assert_allclose(robot.readings_since(3).times, [4 / 1.5, 5 / 1.5, 7.0])
    # n = ceil(T f) - 1 readings for other rates: 2 Hz has one exactly half-way through a step
    for rate, cells in ((2.0, [3, 5, 8, 10, 13, 15, 18]), (1.0, [5, 10, 15]), (0.2, [])):
        r = _noiseless(case, start=(5, 0), sample_rate_hz=rate)
        r.move_to((5, 20))
        assert list(r.observations.cells[:, 1]) == cells, rate
        assert list(r.observations.cells[:, 0]) == [5] * len(cells)


def test_readings_on_the_way_follow_a_winding_path_and_stop_at_the_limit():
    case = _walled_case()
    robot = _noiseless(case, start=(1, 1), sample_rate_hz=1.3)
    assert robot.move_to((10, 27))  # through both doors, with diagonal steps
    obs, t, cells = robot.observations, robot.trajectory_times, robot.trajectory_cells
    assert len(obs) == math.ceil(robot.clock * 1.3) - 1
    np.testing.assert_allclose(obs.times, np.arange(1, len(obs) + 1) / 1.3)
    # each at the trajectory's cell whose centre the robot is nearest (constant speed: in time)
    nearest = np.abs(t[None, :] - obs.times[:, None]).argmin(axis=1)
    np.testing.assert_array_equal(obs.cells, cells[nearest])
    assert (case.occupancy[obs.cells[:, 0], obs.cells[:, 1]] == 0).all()
    # a drive stopped by a time limit reads up to it, and not at the cell it was going to
    robot = _noiseless(corridor_case(), start=(5, 0), sample_rate_hz=2.0)
    assert not robot.move_to((5, 29), until=1.1)
    np.testing.assert_allclose(robot.observations.times, [0.5, 1.0])
    np.testing.assert_array_equal(robot.observations.cells, [[5, 3], [5, 5]])
    assert robot.clock == pytest.approx(1.1) and robot.distance_m == pytest.approx(0.55)
    # a goal where the robot stands: no drive, no reading
    robot.move_to(robot.cell)
    assert robot.n_readings == 2


def test_readings_on_the_way_read_the_frame_of_their_time():
    base = corridor_case()
    frames = np.stack([np.full(base.occupancy.shape, 10.0 * (k + 1)) for k in range(4)]) * base.free
    case = corridor_case(frames=frames, frame_dt=1.0)
    robot = _noiseless(case, start=(5, 0), sample_rate_hz=2.0)
    robot.move_to((5, 20))
    robot.sense()
    obs = robot.observations
    np.testing.assert_allclose(obs.times, [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 7.0])
    np.testing.assert_allclose(obs.gas, 10.0 * (np.floor(obs.times) % 4 + 1))  # frame floor(t) mod 4
    steady = _noiseless(case, start=(5, 0), sample_rate_hz=2.0, use_frames=False)
    steady.move_to((5, 20))
    c = steady.observations.cells
    np.testing.assert_allclose(steady.observations.gas, case.concentration[c[:, 0], c[:, 1]])
    np.testing.assert_allclose(steady.observations.times, obs.times[:-1])


@pytest.mark.parametrize("rate", [0, 0.0, -1.0, math.nan, math.inf, "fast", True])
def test_a_bad_sample_rate_is_refused(rate):
    with pytest.raises(
        InputDataError, match="sample_rate_hz must be a positive number of readings per second"
    ):
        Robot(corridor_case(), start=(5, 0), sample_rate_hz=rate)


def test_path_samples_without_a_robot():
    path = np.array([[0, 0], [0, 1], [1, 2]])
    arrivals = np.array([10.0, 10.2, 10.2 + 0.2 * math.sqrt(2)])
    cells, times = path_samples(path, arrivals, 0.1)
    np.testing.assert_allclose(times, [10.1, 10.2, 10.3, 10.4])
    # 10.1: half of the first step (the cell entered); 10.3: a third into the diagonal one
    np.testing.assert_array_equal(cells, [[0, 1], [0, 1], [0, 1], [1, 2]])
    assert len(path_samples(path[:1], arrivals[:1], 0.1)[1]) == 0
    assert check_sample_rate(None) is None and check_sample_rate(2) == 2.0
