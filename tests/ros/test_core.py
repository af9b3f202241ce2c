"""dgse.ros without ROS: maps to occupancy, the reading bookkeeping, the decisions, bad input."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.ros.core import MapGrid, MethodSetup, SearchCore, method_occupancy
from dgse.ros.messages import gas_reading, map_grid, pose_xy, scaled_grid, wind_reading
from dgse.ros.sim import SimRobot
from tests.ros import METHOD, ORIGIN, SEED
from tests.search import solved_two_rooms


def _setup(**kw) -> MethodSetup:
    return MethodSetup.create(METHOD, seed=SEED, case_name="two_rooms", **kw)


def _drive(core: SearchCore, robot: SimRobot, origin=ORIGIN, max_steps: int = 40) -> None:
    """The loop of ``dgse ros sim`` + ``dgse ros run`` as plain calls: events into the core,
    its goals back to the robot."""
    case = robot.case
    core.set_map(MapGrid.from_occupancy(case.occupancy, case.resolution, origin))
    for _ in range(max_steps):
        for e in robot.due(math.inf):
            x, y = robot.position(e.cell)
            x, y = x + origin[0], y + origin[1]
            if e.kind == "pose":
                core.set_pose(x, y, 100.0 + e.time_s)
            else:
                core.set_wind(*e.wind, 100.0 + e.time_s)
                d = core.add_gas(e.gas, 100.0 + e.time_s)
                if d is not None and d.goal is not None:
                    assert robot.go_to(d.goal)
        if core.stopped:
            return
    raise AssertionError("the search did not stop")


def test_the_core_takes_the_readings_and_decisions_of_dgse_search():
    """Fed by the simulated robot, the core makes dgse search's decisions on the same case,
    seed and start, in a map frame whose origin is not the grid's corner."""
    from dgse.search.campaign import run_trials

    case = solved_two_rooms()
    ref = run_trials([("two_rooms.npz", case)], METHOD, METHOD, 1, SEED, estimator_options={"seed": SEED},
                     min_start_distance=1.0, steps=True)["per_case"][0]["trials"][0]  # fmt: skip
    core = SearchCore(_setup())
    robot = SimRobot(case, seed=SEED, case_name="two_rooms", min_start_distance=1.0)
    assert list(robot.robot.start) == ref["start_cell"]
    _drive(core, robot)
    got = [d.to_dict() for d in core.decisions]
    assert [d["cell"] for d in got] == [s["cell"] for s in ref["steps"]]
    assert [d["gas"] for d in got] == [s["gas"] for s in ref["steps"]]
    assert [d["goal"] for d in got] == [s["goal"] for s in ref["steps"]]
    assert core.reason == ref["reason"]
    declared = np.subtract(core.declared_xy, ORIGIN)
    assert np.allclose(declared, ref["estimate_xy"])
    assert math.dist(declared, case.source) < 2.0


def test_readings_on_the_way_go_in_with_the_goals_as_in_dgse_search():
    """With a sample rate, the simulated robot publishes the readings of each drive and the core
    gives them to the estimator with the goal's reading: the same readings, estimates and
    goals as ``dgse search --sample-rate``; without one, the drive's readings are not used."""
    from dgse.search.campaign import run_trials

    case = solved_two_rooms()
    ref = run_trials([("two_rooms.npz", case)], METHOD, METHOD, 1, SEED, estimator_options={"seed": SEED},
                     min_start_distance=1.0, steps=True, sample_rate_hz=2.0)  # fmt: skip
    ref = ref["per_case"][0]["trials"][0]
    core = SearchCore(_setup(sample_rate_hz=2.0))
    robot = SimRobot(case, seed=SEED, case_name="two_rooms", min_start_distance=1.0, sample_rate_hz=2.0)
    _drive(core, robot)
    got = [d.to_dict() for d in core.decisions]
    per_step = np.diff([0] + [d["step"] for d in got])
    assert per_step.max() > 1  # some drives were read on the way
    assert list(per_step) == [s["n_readings"] for s in ref["steps"]]
    assert [d["goal"] for d in got] == [s["goal"] for s in ref["steps"]]
    assert [d["cell"] for d in got] == [s["cell"] for s in ref["steps"]]
    assert [d["gas"] for d in got] == [s["gas"] for s in ref["steps"]]
    mean_xy = np.array([d["declared_xy"] for d in got[:-1]]) - ORIGIN  # the beliefs' means, grid frame
    assert np.allclose(mean_xy, [s["estimate_xy"] for s in ref["steps"][:-1]])
    assert core.reason == ref["reason"]
    # the paper's protocol: the same robot's drive readings are left out
    plain = SearchCore(_setup())
    _drive(
        plain, SimRobot(case, seed=SEED, case_name="two_rooms", min_start_distance=1.0, sample_rate_hz=2.0)
    )
    assert [d.step for d in plain.decisions] == list(range(1, len(plain.decisions) + 1))


def test_method_occupancy_resamples_by_whole_factors_and_refuses_others():
    v = np.zeros((4, 6), np.int8)
    v[0, :2] = 100  # a 2 x 2 block half solid: stays free at 0.1 m
    v[2:, 4:] = 100  # a full block: solid
    v[1, 5] = -1
    occ, res = method_occupancy(MapGrid(v, 0.05), 0.1)
    assert res == 0.1 and occ.tolist() == [[0, 0, 0], [0, 0, 1]]
    fine, res = method_occupancy(MapGrid(v, 0.05), 0.025)
    assert fine.shape == (8, 12) and res == 0.025 and fine[3, 11] == 1  # the unknown cell is solid
    same, _ = method_occupancy(MapGrid(v, 0.05), None, unknown_solid=False, occupied_threshold=101)
    assert not same.any()
    with pytest.raises(InputDataError, match="cannot be resampled"):
        method_occupancy(MapGrid(v, 0.05), 0.07)


def test_messages_read_by_field_names():
    info = NS(width=3, height=2, resolution=np.float32(0.1),
              origin=NS(position=NS(x=-1.0, y=2.0), orientation=NS(x=0.0, y=0.0, z=0.0, w=1.0)))  # fmt: skip
    grid = map_grid(NS(info=info, data=[0, 0, 100, -1, 0, 0], header=NS(frame_id="map")))
    assert grid.resolution == 0.1 and grid.origin == (-1.0, 2.0) and grid.values[0, 2] == 100
    info.origin.orientation.z = 0.5
    with pytest.raises(InputDataError, match="rotated"):
        map_grid(NS(info=info, data=[0] * 6))
    stamp = NS(header=NS(stamp=NS(sec=5, nanosec=500_000_000)))
    assert pose_xy(NS(pose=NS(pose=NS(position=NS(x=1.0, y=2.0))), **vars(stamp))) == (1.0, 2.0, 5.5)
    assert gas_reading(NS(raw=2000.0, raw_units=4, **vars(stamp))) == (2.0, 5.5)  # ppb
    assert gas_reading(NS(data=3.5)) == (3.5, None)
    with pytest.raises(InputDataError, match="units 1"):
        gas_reading(NS(raw=1.0, raw_units=1, **vars(stamp)))
    u, v, t = wind_reading(NS(wind_speed=2.0, wind_direction=math.pi / 2, **vars(stamp)))
    assert abs(u) < 1e-12 and v == pytest.approx(2.0) and t == 5.5
    data, scale = scaled_grid(np.array([[1.0, 4.0], [2.0, 9.0]]), np.array([[True, True], [True, False]]))
    assert data == [25, 100, 50, -1] and scale == 4.0


def _started(core: SearchCore, case) -> None:
    core.set_map(MapGrid.from_occupancy(case.occupancy, case.resolution, ORIGIN))
    core.set_pose(ORIGIN[0] + 0.55, ORIGIN[1] + 0.55, 10.0)


def test_a_reading_counts_after_the_dwell_and_waits_for_its_wind():
    case = solved_two_rooms()
    core = SearchCore(_setup(dwell=3.0))
    _started(core, case)
    core.set_wind(0.5, 0.0, 12.0)
    assert core.add_gas(5.0, 12.0) is None  # within the dwell
    assert core.add_gas(5.0, 13.0) is None and core.pending == (5.0, 13.0)  # its wind is older
    d = core.set_wind(0.4, 0.1, 13.0)
    assert d is not None and d.step == 1 and d.cell == (5, 5) and d.wind == (0.4, 0.1) and d.time_s == 3.0
    assert core.add_gas(5.0, 13.0) is None  # the same reading again
    assert d.goal is not None and core.target == d.goal


def test_bad_input_is_logged_and_the_search_goes_on():
    case = solved_two_rooms()
    logged: list[tuple[str, str]] = []
    core = SearchCore(_setup(), lambda level, m: logged.append((level, m)))
    assert core.add_gas(1.0, 1.0) is None and "before any map" in logged[-1][1]
    _started(core, case)
    core.set_pose(50.0, 50.0, 11.0)
    assert "outside the map" in logged[-1][1] and core.cell == (5, 5)
    core.set_pose(ORIGIN[0] + 1.55, ORIGIN[1] + 0.15, 11.0)
    assert "in a wall" in logged[-1][1]
    core.set_wind(0.5, 0.0, 20.0)
    assert core.add_gas(float("nan"), 20.0) is None and "non-finite" in logged[-1][1]
    first = core.add_gas(3.0, 20.0)
    assert first is not None and first.goal is not None
    # the navigation refuses the goal: another one, and the refused one is not chosen again
    again = core.goal_rejected()
    assert again is not None and again.goal not in (None, first.goal) and again.step == 1
    assert "refused" in logged[-1][1] and core.target == again.goal
    # a map of another shape: a warning, and the search starts again on it
    wider = np.pad(case.occupancy, ((0, 0), (0, 10)), constant_values=0)
    assert core.set_map(MapGrid.from_occupancy(wider, case.resolution, ORIGIN))
    assert logged[-2][0] == "warning" and "starts again" in logged[-2][1]
    assert core.restarts == 1 and not core.decisions and core.occupancy.shape == (20, 40)
    assert not core.set_map(MapGrid.from_occupancy(wider, case.resolution, ORIGIN))  # the same map again
    core.set_pose(ORIGIN[0] + 0.55, ORIGIN[1] + 0.55, 30.0)
    core.set_wind(0.5, 0.0, 33.0)
    assert core.add_gas(3.0, 33.0) is not None  # running on the new map


def test_a_knowledge_file_must_fit_the_map(tmp_path):
    case = solved_two_rooms()
    path = case.save(tmp_path / "told.npz")
    setup = MethodSetup.create(METHOD, "wind", knowledge_file=path)
    told = setup.knowledge(case.occupancy, case.resolution)
    assert told.level == "wind" and told.wind.shape == (2, 20, 30)
    with pytest.raises(InputDataError, match="robot's map"):
        setup.knowledge(np.zeros((10, 10), np.uint8), case.resolution)


def test_the_animation_has_a_frame_per_reading(tmp_path):
    from PIL import Image

    from dgse.viz.belief import animate_beliefs

    occ = solved_two_rooms().occupancy
    probs = np.stack([np.where(occ == 0, 1.0 + k * np.eye(20, 30), 0.0) for k in range(3)])
    path = animate_beliefs(probs / probs.sum(axis=(1, 2), keepdims=True), occ, 0.1, [(5, 5), (6, 6), (7, 7)],
                           tmp_path / "a.gif")  # fmt: skip
    with Image.open(path) as im:
        assert im.n_frames == 3 and im.size[0] > 100
    with pytest.raises(InputDataError, match="do not make an animation"):
        animate_beliefs(probs, occ, 0.1, [(5, 5)], tmp_path / "b.gif")


def test_the_time_limit_ends_the_search_on_the_messages_clock():
    case = solved_two_rooms()
    logged: list[tuple[str, str]] = []
    core = SearchCore(_setup(time_limit=20.0), lambda level, m: logged.append((level, m)))
    _started(core, case)
    core.set_wind(0.5, 0.0, 13.0)
    d = core.add_gas(3.0, 13.0)
    assert d is not None and d.goal is not None
    assert core.check_time(25.0) is None  # 15 s into the search: a reading still fits
    assert core.check_time(1e9) is None and "sim-time" in logged[-1][1]  # wall time beside sim stamps
    assert core.check_time(28.5) == "time_limit" and core.stopped and core.declared_xy is not None
    assert core.add_gas(3.0, 40.0) is None
