"""Random layouts, sources and inlet speeds (spec section 3)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import ndimage

from dgse.errors import InputDataError
from dgse.world.generate import (
    as_generator,
    free_components,
    opening_gap,
    random_inlet_velocity,
    random_layout,
    random_layout_with_rooms,
    random_ood_layout,
    random_sources,
    source_candidates,
)
from dgse.world.layout import Layout, Opening, rasterize_walls

N_SEEDS = 200


def _narrow_cells(free: np.ndarray) -> np.ndarray:
    """Free cells not inside any 3 x 3 all-free block (outside the map counts as free)."""
    p = np.pad(free, 2, constant_values=True)
    box = np.ones((3, 3), dtype=bool)
    opened = ndimage.binary_dilation(ndimage.binary_erosion(p, box), box)
    return (p & ~opened)[2:-2, 2:-2]


def _check_common(lay: Layout) -> None:
    occ, free, g = lay.occupancy, lay.free, lay.grid
    assert occ.dtype == np.uint8
    # the wall rectangles are the occupancy, snapped to the grid
    assert np.array_equal(rasterize_walls(g, lay.walls), occ)
    for w in lay.walls:
        for v in w:
            assert abs(v / g.resolution - round(v / g.resolution)) < 1e-6
    # one 4-connected free region holding every opening cell
    labels, n = free_components(occ)
    assert n == 1
    openings = lay.inlets + lay.outlets
    for o in openings:
        rows, cols = o.cells(g)
        assert 0.6 - 1e-9 <= o.width_m <= 1.5 + 1e-9
        assert rows.size == round(o.width_m / g.resolution)
        assert free[rows, cols].all(), "an opening lies on a wall end"
        assert (labels[rows, cols] == 1).all()
    for a, b in itertools.combinations(openings, 2):
        assert opening_gap(a, b, g.width_m, g.height_m) >= 2.0 - 1e-9
        if a.side == b.side:  # not overlapping, >= 2 m apart along the side
            assert a.end_m + 2.0 <= b.start_m + 1e-9 or b.end_m + 2.0 <= a.start_m + 1e-9
    # no free passage narrower than 0.3 m
    assert not _narrow_cells(free).any()


def _wall_cells(w, res):
    x0, y0, x1, y1 = w
    return round((x1 - x0) / res), round((y1 - y0) / res)


def test_seeded_determinism():
    a, b = random_layout(7), random_layout(7)
    assert np.array_equal(a.occupancy, b.occupancy)
    assert a.inlets == b.inlets and a.outlets == b.outlets and a.walls == b.walls
    assert a.name == "random-7"
    g1, g2 = np.random.default_rng(11), np.random.default_rng(11)
    c, d = random_layout(g1), random_layout(g2)
    assert np.array_equal(c.occupancy, d.occupancy) and c.walls == d.walls
    assert g1.random() == g2.random()  # the generator was advanced the same way
    others = {random_layout(s).occupancy.tobytes() for s in range(5)}
    assert len(others) == 5


def test_training_layouts_over_many_seeds():
    n_rooms_seen, widths, heights = set(), set(), set()
    for seed in range(N_SEEDS):
        lay = random_layout(seed)
        H, W = lay.occupancy.shape
        assert 50 <= H <= 100 and 50 <= W <= 100
        assert lay.grid.width_m == pytest.approx(W * 0.1)
        widths.add(W)
        heights.add(H)
        assert len(lay.inlets) == 1 and len(lay.outlets) == 1
        assert lay.walls, "a training layout has several rooms"
        for w in lay.walls:
            cw, ch = _wall_cells(w, lay.resolution)
            thickness, length = min(cw, ch), max(cw, ch)
            assert thickness in (1, 2)
            assert length >= 3 or length == thickness  # stubs are 0 or >= 0.3 m
        # doorways: the wall segments leave the interior connected (checked in common)
        _check_common(lay)
        n_rooms_seen.add(len(lay.walls))
    assert min(widths) < 60 and max(widths) > 90 and min(heights) < 60 and max(heights) > 90
    assert len(n_rooms_seen) > 3


def test_walls_along_both_directions():
    vertical = horizontal = 0
    for seed in range(50):
        lay = random_layout(seed)
        for w in lay.walls:
            cw, ch = _wall_cells(w, lay.resolution)
            vertical += ch > cw
            horizontal += cw > ch
    assert vertical > 20 and horizontal > 20


def _free_run(occ: np.ndarray, band: slice, start: int, step: int, vertical: bool):
    """Free cells along a wall's line from ``start`` and whether solid or the edge ends them."""
    line = occ[:, band] if vertical else occ[band, :].T
    k, n = start, 0
    while 0 <= k < line.shape[0] and not line[k].any():
        k += step
        n += 1
    return n, (not 0 <= k < line.shape[0]) or bool(line[k].all())


def test_every_wall_segment_has_a_doorway():
    """Beside one end of each wall segment, along its line: a 0.8-1.2 m doorway.

    The doorway is a free gap of the wall's full thickness ending at solid (the
    other segment or a crossing wall) or at the outer boundary.
    """
    for seed in range(N_SEEDS):
        lay = random_layout(seed)
        occ, res = lay.occupancy, lay.resolution
        for x0, y0, x1, y1 in lay.walls:
            j0, j1, i0, i1 = (round(v / res) for v in (x0, x1, y0, y1))
            vertical = (i1 - i0) > (j1 - j0)
            band = slice(j0, j1) if vertical else slice(i0, i1)
            lo, hi = (i0, i1) if vertical else (j0, j1)
            runs = [
                _free_run(occ, band, hi, 1, vertical),
                _free_run(occ, band, lo - 1, -1, vertical),
            ]
            assert any(8 <= n <= 12 and closed for n, closed in runs), (seed, (x0, y0, x1, y1))


def test_rooms_partition_the_free_space():
    counts = []
    for seed in range(50):
        lay, rooms = random_layout_with_rooms(seed)
        assert np.array_equal(lay.occupancy, random_layout(seed).occupancy)
        assert 2 <= len(rooms) <= 6
        counts.append(len(rooms))
        room_cells = rasterize_walls(lay.grid, rooms)
        assert not (room_cells & lay.occupancy).any()
        for x0, y0, x1, y1 in rooms:
            assert x1 - x0 >= 1.5 - 1e-9 and y1 - y0 >= 1.5 - 1e-9
        # rooms + walls + doorways fill the domain; doorways are small
        doorway_cells = (lay.occupancy == 0) & (room_cells == 0)
        assert doorway_cells.sum() <= (len(rooms) - 1) * 12 * 2
    assert len(set(counts)) == 5


def test_custom_ranges_and_resolution():
    lay = random_layout(3, width_range=(6.0, 6.0), height_range=(8.0, 8.0))
    assert lay.occupancy.shape == (80, 60)
    fine = random_layout(4, resolution=0.05)
    assert 100 <= fine.occupancy.shape[0] <= 200
    for w in fine.walls:
        assert min(_wall_cells(w, 0.05)) in (2, 3, 4)
    _check_common(fine)
    single = random_layout(5, n_rooms=1)
    assert single.walls == () and (single.occupancy == 0).all()


def test_impossible_parameters_raise():
    with pytest.raises(InputDataError, match="could not draw"):
        random_layout(0, min_opening_gap_m=50.0, max_attempts=3)
    with pytest.raises(InputDataError, match="door_width_range"):
        random_layout(0, door_width_range=(0.82, 0.88))
    with pytest.raises(InputDataError, match="width_range"):
        random_layout(0, width_range=(10.0, 5.0))
    with pytest.raises(InputDataError):
        as_generator("seed")  # type: ignore[arg-type]


def test_sources_far_from_walls_and_rates_in_range():
    for seed in range(40):
        lay = random_layout(seed)
        rng = np.random.default_rng(seed)
        sources = random_sources(lay, rng)
        assert len(sources) == 4
        g = lay.grid
        solid = np.argwhere(lay.occupancy == 1)
        lo = solid[:, ::-1] * g.resolution  # (x0, y0) of each solid cell
        hi = lo + g.resolution
        positions = set()
        for (x, y), q in sources:
            assert 0.01 <= q <= 5.0
            i, j = g.cell_of(x, y)
            assert lay.occupancy[i, j] == 0
            assert (x, y) == pytest.approx(g.center_of(i, j))
            positions.add((i, j))
            d_boundary = min(x, g.width_m - x, y, g.height_m - y)
            dx = np.maximum(np.maximum(lo[:, 0] - x, x - hi[:, 0]), 0.0)
            dy = np.maximum(np.maximum(lo[:, 1] - y, y - hi[:, 1]), 0.0)
            d_solid = np.hypot(dx, dy).min() if len(solid) else np.inf
            assert min(d_boundary, d_solid) >= 0.3 - 1e-9
        assert len(positions) == 4
    a = random_sources(random_layout(1), 5)
    b = random_sources(random_layout(1), 5)
    assert a == b


def test_source_candidates_and_errors():
    occ = np.zeros((10, 10), dtype=np.uint8)
    lay = Layout(occ, (Opening("west", 0, 1),), (Opening("east", 0, 1),))
    cand = source_candidates(lay, 0.3)
    # 0.3 m from the boundary: the cell centres at 0.35 m and beyond
    assert cand[3:7, 3:7].all() and cand.sum() == 16
    assert cand.sum() == source_candidates(lay, 0.35).sum()
    with pytest.raises(InputDataError, match="sources requested"):
        random_sources(lay, 0, n=17)
    srcs = random_sources(lay, 0, n=3, rate_range=(1.0, 2.0))
    assert all(1.0 <= q <= 2.0 for _, q in srcs)


def test_inlet_velocity():
    rng = np.random.default_rng(0)
    v = [random_inlet_velocity(rng) for _ in range(200)]
    assert all(0.5 <= x <= 5.0 for x in v)
    assert random_inlet_velocity(3) == random_inlet_velocity(3)
    assert 1.0 <= random_inlet_velocity(1, (1.0, 1.5)) <= 1.5
    with pytest.raises(InputDataError):
        random_inlet_velocity(0, (5.0, 1.0))


def test_opening_gap_definitions():
    W, H = 8.0, 6.0
    a = Opening("south", 1.0, 2.0)
    assert opening_gap(a, Opening("south", 4.0, 5.0), W, H) == pytest.approx(2.0)
    assert opening_gap(a, Opening("south", 1.5, 3.0), W, H) == 0.0
    # around the corner: Euclidean distance between nearest end points
    assert opening_gap(a, Opening("west", 1.0, 2.0), W, H) == pytest.approx(np.hypot(1, 1))
    assert opening_gap(a, Opening("north", 1.0, 2.0), W, H) == pytest.approx(6.0)


def test_ood_layouts():
    with_obstacles = multi = 0
    for seed in range(40):
        lay = random_ood_layout(seed)
        H, W = lay.occupancy.shape
        assert 50 <= H <= 100 and 50 <= W <= 150
        assert 1 <= len(lay.inlets) <= 3 and 1 <= len(lay.outlets) <= 3
        multi += len(lay.inlets) + len(lay.outlets) > 2
        _check_common(lay)
        with_obstacles += _free_standing(lay) > 0
    assert with_obstacles > 10 and multi > 20


def _free_standing(lay: Layout) -> int:
    """Number of solid components that touch neither the boundary nor another one."""
    labels, n = ndimage.label(lay.occupancy == 1)
    count = 0
    for k in range(1, n + 1):
        comp = labels == k
        rows, cols = np.nonzero(comp)
        if rows.min() == 0 or cols.min() == 0:
            continue
        if rows.max() == comp.shape[0] - 1 or cols.max() == comp.shape[1] - 1:
            continue
        count += 1
    return count


def test_ood_large_domain_with_obstacles():
    lay = random_ood_layout(
        2,
        min_width=15,
        max_width=15,
        min_height=10,
        max_height=10,
        n_obstacles=4,
        n_inlets=3,
        n_outlets=3,
    )
    assert lay.occupancy.shape == (100, 150)
    assert len(lay.inlets) == 3 and len(lay.outlets) == 3
    _check_common(lay)
    obstacles = lay.walls[-4:]
    g = lay.grid
    for x0, y0, x1, y1 in obstacles:
        # a free ring of 0.5 m around each obstacle, inside the domain
        i0, i1 = round(y0 / g.resolution), round(y1 / g.resolution)
        j0, j1 = round(x0 / g.resolution), round(x1 / g.resolution)
        assert i0 >= 5 and j0 >= 5 and i1 <= g.height - 5 and j1 <= g.width - 5
        ring = lay.occupancy[i0 - 5 : i1 + 5, j0 - 5 : j1 + 5].copy()
        ring[5:-5, 5:-5] = 0
        assert not ring.any()
        assert 3 <= i1 - i0 <= 15 and 3 <= j1 - j0 <= 15
    assert random_ood_layout(2).name == "ood-2"
    a, b = random_ood_layout(9), random_ood_layout(9)
    assert np.array_equal(a.occupancy, b.occupancy) and a.inlets == b.inlets
