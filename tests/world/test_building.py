"""Office floors (world/building.py) and their round trip through a ROS map_server map."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.world.building import random_office_floor, random_office_floor_with_plan
from dgse.world.floorplan import FloorPlan, export_ros_map, layout_from_floorplan, load_ros_map
from dgse.world.generate import free_components, opening_gap
from dgse.world.layout import rasterize_walls

SEEDS = range(6)
FLOORPLANS = Path(__file__).resolve().parents[2] / "benchmarks" / "floorplans"


def _cells(rect, res=0.1):
    x0, y0, x1, y1 = (round(v / res) for v in rect)
    return slice(y0, y1), slice(x0, x1)


@pytest.fixture(scope="module")
def floors():
    return {s: random_office_floor_with_plan(s) for s in SEEDS}


def test_same_seed_same_floor_other_seed_other_floor():
    a, b = random_office_floor(11), random_office_floor(11)
    assert np.array_equal(a.occupancy, b.occupancy)
    assert (a.inlets, a.outlets, a.walls, a.name) == (b.inlets, b.outlets, b.walls, "office-11")
    c = random_office_floor(np.random.default_rng(11))
    assert np.array_equal(c.occupancy, a.occupancy) and c.name == "office"
    other = random_office_floor(12)
    assert other.occupancy.shape != a.occupancy.shape or not np.array_equal(other.occupancy, a.occupancy)


def test_sizes_walls_and_connectivity(floors):
    for layout, _ in floors.values():
        H, W = layout.occupancy.shape
        assert 200 <= H <= 400 and 200 <= W <= 400 and layout.resolution == 0.1
        assert np.array_equal(rasterize_walls(layout.grid, layout.walls), layout.occupancy)
        labels, n = free_components(layout.occupancy)
        assert n == 1
        for o in layout.inlets + layout.outlets:
            rows, cols = o.cells(layout.grid)
            assert (labels[rows, cols] == 1).all()  # every cell under an opening is free


def test_openings_counts_lengths_and_gaps(floors):
    for layout, _ in floors.values():
        assert 2 <= len(layout.inlets) <= 4 and 2 <= len(layout.outlets) <= 4
        g = layout.grid
        openings = layout.inlets + layout.outlets
        for o in openings:
            assert 0.6 - 1e-9 <= o.width_m <= 1.5 + 1e-9
        for a, b in itertools.combinations(openings, 2):
            assert opening_gap(a, b, g.width_m, g.height_m) >= 2.0 - 1e-9
    fixed = random_office_floor(3, n_inlets=3, n_outlets=2)
    assert (len(fixed.inlets), len(fixed.outlets)) == (3, 2)


def test_corridors_rooms_and_doors(floors):
    for layout, plan in floors.values():
        assert plan.corridors and len(plan.rooms) > 2
        occ = layout.occupancy.copy()
        for door in plan.doors:
            i, j = _cells(door)
            assert (occ[i, j] == 0).all()
            w = max(j.stop - j.start, i.stop - i.start)
            assert 8 <= w <= 12  # 0.8-1.2 m along the wall
            occ[i, j] = 1
        # doors closed: every room on its own, the corridors (with connectors) one region
        _, n = free_components(occ)
        assert n == len(plan.rooms) + 1 > 2
        for room in plan.rooms:
            i, j = _cells(room)
            assert (layout.occupancy[i, j] == 0).all()
            assert min(i.stop - i.start, j.stop - j.start) >= 25  # 2.5 m
    one = random_office_floor_with_plan(5, n_corridors=1)[1]
    two = random_office_floor_with_plan(5, n_corridors=2)[1]
    assert len(one.corridors) == 1 and len(two.corridors) >= 3  # two corridors and connectors


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_corridors": 3}, "n_corridors must be 1 or 2"),
        ({"n_corridors": 0}, "n_corridors"),
        ({"n_inlets": 0}, "n_inlets"),
        ({"width_range": (0.0, 30.0)}, "width_range"),
        ({"height_range": (30.0, 20.0)}, "height_range"),
        ({"resolution": -0.1}, "resolution must be positive"),
        ({"room_width_range": (1.0, 6.0)}, "room_width_range must start at 1.8 m"),
        ({"room_width_range": (3.0, 4.0)}, "too narrow"),
        ({"door_width_range": (0.01, 0.02)}, "door_width_range"),
        ({"max_attempts": 0}, "max_attempts"),
        ({"width_range": (5.0, 6.0), "height_range": (5.0, 6.0)}, "could not draw a valid office floor"),
    ],
)
def test_bad_parameters_are_input_errors(kwargs, message):
    with pytest.raises(InputDataError, match=message):
        random_office_floor(0, **kwargs)


def test_bad_seed_is_an_input_error():
    with pytest.raises(InputDataError, match="seed"):
        random_office_floor("three")  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", [1, 4])  # one corridor; two corridors with connectors
def test_ros_map_round_trip(tmp_path, floors, seed):
    layout, _ = floors[seed]
    yaml_path, pgm_path = export_ros_map(layout, tmp_path / "maps" / "floor.yaml")
    assert pgm_path == tmp_path / "maps" / "floor.pgm"
    H, W = layout.occupancy.shape
    assert pgm_path.read_bytes().startswith(f"P5\n{W} {H}\n255\n".encode())
    # what dgse import-floorplan does: load_ros_map, then layout_from_floorplan with openings
    fp = load_ros_map(yaml_path, layout.resolution)
    assert isinstance(fp, FloorPlan) and fp.origin == (0.0, 0.0)
    assert np.array_equal(fp.occupancy, layout.occupancy)
    # the map carries no openings: only as YAML comments; the import is given them
    text = yaml_path.read_text()
    first_inlet = layout.inlets[0]
    assert f"# inlets:  {first_inlet.side} {first_inlet.start_m:g} {first_inlet.end_m:g}" in text
    back = layout_from_floorplan(fp, None, layout.inlets, layout.outlets, name=layout.name)
    assert np.array_equal(back.occupancy, layout.occupancy) and back.walls == layout.walls
    assert (back.inlets, back.outlets) == (layout.inlets, layout.outlets)


@pytest.mark.parametrize("seed", [3, 6])
def test_committed_floorplans_are_the_generated_floors(seed):
    """benchmarks/floorplans/ is what scripts/make_floorplans.py makes with today's generator."""
    fp = load_ros_map(FLOORPLANS / f"office-{seed}.yaml")
    assert np.array_equal(fp.occupancy, random_office_floor(seed).occupancy)
    assert (FLOORPLANS / f"office-{seed}.pgm").stat().st_size < 200_000
