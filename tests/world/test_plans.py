"""Drawn floor plans: seeded, furnished, openings in the outer wall, imported as the CLI does."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.world.floorplan import load_png_map
from dgse.world.generate import free_components
from dgse.world.plans import PIXEL_SIZES, draw_house, draw_office, draw_plan, import_plan


def test_a_plan_is_a_function_of_its_seed():
    a, b, c = draw_house(5), draw_house(5), draw_house(6)
    assert np.array_equal(a.solid, b.solid) and (a.inlets, a.outlets) == (b.inlets, b.outlets)
    assert a.inlet_velocity == b.inlet_velocity
    assert a.solid.shape != c.solid.shape or not np.array_equal(a.solid, c.solid)
    assert draw_plan("office", 2).name == "office-2"
    with pytest.raises(InputDataError, match="kind"):
        draw_plan("castle", 1)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_house_plans_are_drawn_at_fine_pixels_with_whole_decimetre_sides(seed):
    plan = draw_house(seed)
    assert plan.pixel_size in PIXEL_SIZES
    w, h = plan.size_m
    assert 8.0 <= w <= 14.0 and 8.0 <= h <= 14.0
    assert abs(w * 10 - round(w * 10)) < 1e-6 and abs(h * 10 - round(h * 10)) < 1e-6
    assert 1 <= len(plan.inlets) <= 3 and 1 <= len(plan.outlets) <= 3
    assert 0.2 <= plan.inlet_velocity <= 3.0


def test_the_outer_wall_is_solid_but_for_the_openings():
    plan = draw_house(4, pixel_size=0.025)
    s, ps = plan.solid, plan.pixel_size
    edges = {"west": s[:, 0], "east": s[:, -1], "south": s[0, :], "north": s[-1, :]}
    open_px = {side: np.zeros(line.size, dtype=bool) for side, line in edges.items()}
    for o in plan.inlets + plan.outlets:
        centres = (np.arange(open_px[o.side].size) + 0.5) * ps
        inside = (centres > o.start_m) & (centres < o.end_m)
        assert not edges[o.side][inside].any(), o  # the gap is open
        open_px[o.side] |= inside
    for side, line in edges.items():
        assert line[~open_px[side]].all(), side  # everywhere else the wall


def test_houses_have_rooms_furniture_and_narrow_doorways():
    """Across a few seeds: several rooms, free-standing furniture (solid pieces apart from the
    walls), and doorways or gaps a few cells wide after the import at 0.1 m."""
    rooms, pieces = [], []
    for seed in range(6):
        plan = draw_house(seed)
        _, n = free_components(plan.solid.astype(np.uint8) ^ 1)  # solid parts
        pieces.append(n - 1)  # everything but the wall structure
        layout = _imported_in_memory(plan)
        # closing every free cell within 0.3 m of a wall splits the floor into rooms
        from scipy import ndimage

        core = ndimage.binary_erosion(layout.free, iterations=3)
        rooms.append(ndimage.label(core)[1])
    assert max(rooms) >= 4 and sum(p > 0 for p in pieces) >= 3


def _imported_in_memory(plan, resolution=0.1):
    from dgse.world.floorplan import layout_from_floorplan, resample_occupancy

    occ = resample_occupancy(plan.solid, plan.pixel_size, resolution)
    return layout_from_floorplan(occ, resolution, plan.inlets, plan.outlets, name=plan.name)


def test_import_reads_the_png_back_through_the_floor_plan_import(tmp_path):
    plan = draw_house(7, pixel_size=0.02)
    png = plan.save_png(tmp_path / "h.png")
    fp = load_png_map(png, 0.1, pixel_size=0.02)
    assert fp.occupancy.shape == (round(plan.size_m[1] / 0.1), round(plan.size_m[0] / 0.1))
    layout = import_plan(png, plan)
    assert layout.name == "h" and layout.inlets == plan.inlets and layout.outlets == plan.outlets
    np.testing.assert_array_equal(layout.occupancy, _imported_in_memory(plan).occupancy)
    # every opening has free cells behind it, and the air of every inlet reaches an outlet
    for o in plan.inlets + plan.outlets:
        r, c = o.cells(layout.grid)
        assert (layout.occupancy[r, c] == 0).any()
    assert free_components(layout.occupancy)[1] == 1


def test_a_30_m_office_floor_has_a_corridor_with_rooms_on_both_sides():
    plan = draw_office(0, size=(30.0, 30.0), pixel_size=0.05)
    assert plan.size_m == (30.0, 30.0) and plan.solid.shape == (600, 600)
    layout = _imported_in_memory(plan)
    free = layout.free
    # a corridor: rows free across the whole interior (outer wall of at most 3 cells)
    through = np.nonzero(free[:, 3:-3].all(axis=1))[0]
    assert through.size >= 10
    lo, hi = through.min(), through.max()
    below, above = free[: lo - 1], free[hi + 2 :]
    assert below.sum() > 0.2 * free.sum() and above.sum() > 0.2 * free.sum()
    # rooms: cross walls cut each side into several parts once the doorways are closed
    from scipy import ndimage

    for band in (below[2:-2], above[2:-2]):
        assert ndimage.label(band[:, 3:-3])[1] >= 3


def test_bad_pixel_sizes_are_refused():
    with pytest.raises(InputDataError, match="pixel_size"):
        draw_house(1, pixel_size=0.03)
