"""The simulated robot: never in a wall, one clock for travel and dwell, Table I readings, frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.planning.paths import graph_for
from dgse.search.robot import Robot, random_start_cell
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
