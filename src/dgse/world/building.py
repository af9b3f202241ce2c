"""Building-scale scenarios: random office floors of 20-40 m per side.

:func:`random_office_floor` draws one floor of an office building on the
default 0.1 m grid (200-400 cells per side):

* a rectangle ``W, H ~ U[20, 40] m`` snapped to whole cells;
* one or two corridors (1.5-2.5 m wide) running the floor's longer side from
  outer boundary to outer boundary; two corridors are joined by one
  connecting corridor (two on floors of 30 m or more) across the band of
  rooms between them;
* rooms on both sides of every corridor, each with its own doorway
  (0.8-1.2 m) onto the corridor: the bands of rooms between a corridor and
  the outer boundary (or the other corridor) are cut into rooms 2.5-6 m wide
  by cross walls; the middle band of a two-corridor floor is split
  lengthwise into two rows of rooms, one facing each corridor, when it is
  deep enough.  A band deeper than ``room_depth_range``'s high end is split
  into a front room (with the corridor door) and back rooms reached through
  it;
* walls 0.1-0.2 m thick, as in :mod:`dgse.world.generate`; doorways leave wall
  stubs that are absent or at least 0.3 m long;
* 2-4 inlets and 2-4 outlets (0.6-1.5 m) on free cells of the outer boundary,
  pairwise at least 2 m apart (the gap of :func:`dgse.world.generate.opening_gap`),
  drawn by the same routine as the paper-size generators.

As in the spec (section 1) the outer boundary is the domain edge, not a row
of solid cells: rooms and corridor ends touch it, and the openings lie there.

Everything is in whole cells; the layout's ``walls`` are an exact rectangle
cover of the solid cells (:func:`dgse.world.floorplan.occupancy_rectangles`),
so ``rasterize_walls(grid, layout.walls)`` equals ``layout.occupancy``.  The
free cells are one 4-connected region holding every opening.  The generator
is deterministic given its seed; a draw that breaks a rule is redrawn with
the same generator, and after ``max_attempts`` failures an
:class:`~dgse.errors.InputDataError` is raised.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from dgse.errors import InputDataError
from dgse.world.floorplan import occupancy_rectangles
from dgse.world.generate import (
    RngLike,
    _cells_range,
    _check_range,
    _connected,
    _door_offset,
    _draw_openings,
    _grid_size,
    _int_range,
    _rects_m,
    _seed_name,
    as_generator,
)
from dgse.world.grid import DEFAULT_RESOLUTION
from dgse.world.layout import Layout

__all__ = ["OfficePlan", "random_office_floor", "random_office_floor_with_plan"]

_EPS = 1e-9
Rect = tuple[float, float, float, float]
_Cells = tuple[int, int, int, int]  # rows [r0, r1), columns [c0, c1)


class OfficePlan(NamedTuple):
    """What an office floor is made of, as rectangles ``(x0, y0, x1, y1)`` in m.

    Attributes:
        corridors: free rectangles of the corridors and their connectors.
        rooms: free rectangles of the rooms (front and back rooms apart).
        doors: the doorways cut through the walls (free cells; filling them
            separates every room from the corridors and from each other).
    """

    corridors: tuple[Rect, ...]
    rooms: tuple[Rect, ...]
    doors: tuple[Rect, ...]


@dataclass(frozen=True)
class _Params:
    """Sizes in cells."""

    corridor: tuple[int, int]
    room_width: tuple[int, int]
    room_depth: tuple[int, int]
    thickness: tuple[int, int]
    door: tuple[int, int]
    margin: int
    long_floor: int  # floors at least this long get two connectors


def _draw(rng: np.random.Generator, r: tuple[int, int]) -> int:
    return int(rng.integers(r[0], r[1] + 1))


class _Plan:
    """A floor in the making, in the canonical frame: rows across the corridors."""

    def __init__(self, depth: int, length: int) -> None:
        self.occ = np.zeros((depth, length), dtype=np.uint8)
        self.corridors: list[_Cells] = []
        self.rooms: list[_Cells] = []
        self.doors: list[_Cells] = []

    def wall(self, r0: int, r1: int, c0: int, c1: int) -> None:
        self.occ[r0:r1, c0:c1] = 1

    def door(self, rng, wall_rows: tuple[int, int], c0: int, c1: int, p: _Params) -> None:
        """A doorway through ``wall_rows`` within columns ``[c0, c1)`` (stubs 0 or >= margin)."""
        d = min(_draw(rng, p.door), c1 - c0)
        off = _door_offset(rng, c1 - c0, d, p.margin)
        cells = (wall_rows[0], wall_rows[1], c0 + off, c0 + off + d)
        self.occ[cells[0] : cells[1], cells[2] : cells[3]] = 0
        self.doors.append(cells)


def _split_run(rng, n: int, p: _Params) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Rooms ``[a, b)`` and cross walls ``[a, b)`` along a run of ``n`` cells."""
    lo, hi = p.room_width
    rooms: list[tuple[int, int]] = []
    walls: list[tuple[int, int]] = []
    j = 0
    while True:
        rem = n - j
        if rem <= hi:
            rooms.append((j, n))
            break
        w, t = _draw(rng, p.room_width), _draw(rng, p.thickness)
        if rem - w - t < lo:  # the rest would be too narrow: two rooms of about equal width
            w = (rem - t) // 2
            if w < lo:
                rooms.append((j, n))
                break
        rooms.append((j, j + w))
        walls.append((j + w, j + w + t))
        j += w + t
    return rooms, walls


def _fill_row(
    rng,
    plan: _Plan,
    rows: tuple[int, int],
    front_high: bool,
    door_wall: tuple[int, int],
    cols: tuple[int, int],
    p: _Params,
) -> None:
    """Rooms in rows ``[r0, r1)`` x columns ``cols``, with doors through ``door_wall``.

    ``front_high``: the corridor lies above ``r1`` (else below ``r0``).  Rooms
    deeper than ``room_depth[1]`` are split into a front room and back rooms,
    each back room with a doorway into the room in front of it.
    """
    r0, r1 = rows
    pieces, walls = _split_run(rng, cols[1] - cols[0], p)
    for a, b in walls:
        plan.wall(r0, r1, cols[0] + a, cols[0] + b)
    dmin, dmax = p.room_depth
    for a, b in pieces:
        c0, c1 = cols[0] + a, cols[0] + b
        plan.door(rng, door_wall, c0, c1, p)
        lo, hi = r0, r1  # the part not yet given to a room
        while True:
            depth = hi - lo
            t = _draw(rng, p.thickness)
            if depth <= dmax or depth - dmin - t < dmin:
                plan.rooms.append((lo, hi, c0, c1))
                break
            f = int(rng.integers(dmin, min(dmax, depth - dmin - t) + 1))
            if front_high:  # front room at the top, wall below it
                wall = (hi - f - t, hi - f)
                plan.rooms.append((hi - f, hi, c0, c1))
                hi = wall[0]
            else:
                wall = (lo + f, lo + f + t)
                plan.rooms.append((lo, lo + f, c0, c1))
                lo = wall[1]
            plan.wall(wall[0], wall[1], c0, c1)
            plan.door(rng, wall, c0, c1, p)


def _band_depths(rng, free: int, n_bands: int, lo: int) -> list[int] | None:
    """Depths of ``n_bands`` bands of rooms sharing ``free`` rows, each at least ``lo``.

    The middle band of three (two rows of rooms) gets about twice the share.
    """
    extra = free - n_bands * lo
    if extra < 0:
        return None
    weights = np.array([2.0 if 0 < k < n_bands - 1 else 1.0 for k in range(n_bands)])
    share = weights * rng.uniform(0.5, 1.5, size=n_bands)
    depths = [lo + int(extra * s) for s in share / share.sum()]
    depths[-1] += free - sum(depths)
    return depths


def _connectors(rng, length: int, width: int, t: int, k: int, p: _Params) -> list[int] | None:
    """First columns of ``k`` connecting corridors, leaving runs of rooms >= the least width."""
    need = p.room_width[0]
    lo, hi = need + t, length - need - t - width  # first column of a connector, inclusive
    if hi < lo:
        return None
    for _ in range(20):
        xs = sorted(int(x) for x in rng.integers(lo, hi + 1, size=k))
        edges = [0] + [v for x in xs for v in (x - t, x + width + t)] + [length]
        if all(b - a >= need for a, b in zip(edges[::2], edges[1::2], strict=True)):
            return xs
    return None


def _office_plan(rng, depth: int, length: int, n_corridors: int, p: _Params) -> _Plan | None:
    """A floor of ``depth x length`` cells with corridors along the length; ``None`` if it does not fit."""
    widths = [_draw(rng, p.corridor) for _ in range(n_corridors)]
    ts = [_draw(rng, p.thickness) for _ in range(2 * n_corridors)]
    depths = _band_depths(rng, depth - sum(widths) - sum(ts), n_corridors + 1, p.room_depth[0])
    if depths is None:
        return None
    plan = _Plan(depth, length)
    # rows from south to north: band, wall, corridor, wall, band, ...
    bands: list[tuple[int, int]] = []
    corridor_walls: list[tuple[tuple[int, int], tuple[int, int]]] = []  # (below, above)
    i = 0
    for k in range(n_corridors):
        bands.append((i, i + depths[k]))
        i += depths[k]
        below = (i, i + ts[2 * k])
        i = below[1]
        plan.corridors.append((i, i + widths[k], 0, length))
        i += widths[k]
        above = (i, i + ts[2 * k + 1])
        i = above[1]
        plan.wall(below[0], below[1], 0, length)
        plan.wall(above[0], above[1], 0, length)
        corridor_walls.append((below, above))
    bands.append((i, depth))
    # outer bands: one row of rooms each
    _fill_row(rng, plan, bands[0], True, corridor_walls[0][0], (0, length), p)
    _fill_row(rng, plan, bands[-1], False, corridor_walls[-1][1], (0, length), p)
    if n_corridors == 1:
        return plan
    # the middle band: connectors, then one or two rows of rooms in each run between them
    r0, r1 = bands[1]
    wall_lo, wall_hi = corridor_walls[0][1], corridor_walls[1][0]
    width, t = _draw(rng, p.corridor), _draw(rng, p.thickness)
    k = 2 if length >= p.long_floor else 1
    xs = _connectors(rng, length, width, t, k, p)
    if xs is None:
        return None
    runs, a = [], 0
    for x in xs:
        plan.wall(r0, r1, x - t, x)
        plan.wall(r0, r1, x + width, x + width + t)
        plan.occ[wall_lo[0] : wall_lo[1], x : x + width] = 0
        plan.occ[wall_hi[0] : wall_hi[1], x : x + width] = 0
        plan.corridors.append((wall_lo[0], wall_hi[1], x, x + width))
        runs.append((a, x - t))
        a = x + width + t
    runs.append((a, length))
    dmin = p.room_depth[0]
    t_mid = _draw(rng, p.thickness)
    two_rows = r1 - r0 >= 2 * dmin + t_mid
    split = int(rng.integers(r0 + dmin, r1 - dmin - t_mid + 1)) if two_rows else 0
    face_high = bool(rng.integers(2))
    for run in runs:
        if two_rows:
            plan.wall(split, split + t_mid, *run)
            _fill_row(rng, plan, (r0, split), False, wall_lo, run, p)
            _fill_row(rng, plan, (split + t_mid, r1), True, wall_hi, run, p)
        elif face_high:
            _fill_row(rng, plan, (r0, r1), True, wall_hi, run, p)
        else:
            _fill_row(rng, plan, (r0, r1), False, wall_lo, run, p)
    return plan


def _transpose(rects: Sequence[_Cells], flip: bool) -> list[_Cells]:
    return [(c0, c1, r0, r1) for r0, r1, c0, c1 in rects] if flip else list(rects)


def random_office_floor_with_plan(
    rng_or_seed: RngLike = None,
    *,
    width_range: tuple[float, float] = (20.0, 40.0),
    height_range: tuple[float, float] = (20.0, 40.0),
    resolution: float = DEFAULT_RESOLUTION,
    n_corridors: int | tuple[int, int] = (1, 2),
    corridor_width_range: tuple[float, float] = (1.5, 2.5),
    room_width_range: tuple[float, float] = (2.5, 6.0),
    room_depth_range: tuple[float, float] = (3.0, 8.0),
    wall_thickness_range: tuple[float, float] = (0.1, 0.2),
    door_width_range: tuple[float, float] = (0.8, 1.2),
    opening_length_range: tuple[float, float] = (0.6, 1.5),
    min_opening_gap_m: float = 2.0,
    n_inlets: int | tuple[int, int] = (2, 4),
    n_outlets: int | tuple[int, int] = (2, 4),
    max_attempts: int = 50,
    name: str | None = None,
) -> tuple[Layout, OfficePlan]:
    """A random office floor (see :func:`random_office_floor`) and its plan.

    :func:`random_office_floor` returns the same layout without the plan: the
    :class:`OfficePlan`, the corridors, rooms and doorways as rectangles in m.

    Args:
        rng_or_seed: a seed or a numpy Generator (which is advanced).
        width_range, height_range: floor sides in m, drawn uniformly and snapped
            to whole cells (200-400 cells at 0.1 m by default).
        resolution: cell size in m.
        n_corridors: 1 or 2 corridors (``(low, high)`` drawn uniformly, or one
            int); they run along the longer side, boundary to boundary.
        corridor_width_range: corridor (and connector) width in m, whole cells.
        room_width_range: room width along its corridor in m; the high end must
            hold two rooms of the low end and a wall.
        room_depth_range: least depth of a band of rooms and greatest depth of
            one room, in m; deeper bands get back rooms behind the front rooms.
        wall_thickness_range: wall thickness in m, whole cells (1-2 at 0.1 m).
        door_width_range: doorway width in m, whole cells; stubs beside a
            doorway are absent or at least 0.3 m long.
        opening_length_range: inlet/outlet length in m, whole cells.
        min_opening_gap_m: least gap in m between any two openings.
        n_inlets, n_outlets: how many, ``(low, high)`` drawn uniformly, or one int.
        max_attempts: redraws before giving up with :class:`InputDataError`.
        name: layout name; default ``"office-<seed>"`` (``"office"`` for a Generator).

    Returns:
        ``(layout, plan)``; the :class:`Layout`: ``occupancy`` ``uint8 (H, W)``, the inlets and
        outlets on free boundary cells, ``walls`` an exact rectangle cover of
        the solid cells in m.  The free cells are one 4-connected region
        holding every opening.

    Raises:
        InputDataError: bad ranges or counts, rooms too small for a doorway,
            or no valid floor in ``max_attempts`` draws.
    """
    rng = as_generator(rng_or_seed)
    res = float(resolution)
    if not (res > 0 and math.isfinite(res)):
        raise InputDataError(f"resolution must be positive, got {resolution}")
    _check_range(width_range, "width_range")
    _check_range(height_range, "height_range")
    corr = _int_range(n_corridors, "n_corridors", 1)
    if corr[1] > 2:
        raise InputDataError(f"n_corridors must be 1 or 2 (or a range within them), got {n_corridors}")
    nin = _int_range(n_inlets, "n_inlets", 1)
    nout = _int_range(n_outlets, "n_outlets", 1)
    if not (min_opening_gap_m >= 0 and math.isfinite(min_opening_gap_m)):
        raise InputDataError(f"min_opening_gap_m must be >= 0, got {min_opening_gap_m}")
    if max_attempts < 1:
        raise InputDataError(f"max_attempts must be at least 1, got {max_attempts}")
    p = _Params(
        corridor=_cells_range(
            *_check_range(corridor_width_range, "corridor_width_range"), res, "corridor_width_range"
        ),
        room_width=_cells_range(*_check_range(room_width_range, "room_width_range"), res, "room_width_range"),
        room_depth=_cells_range(*_check_range(room_depth_range, "room_depth_range"), res, "room_depth_range"),
        thickness=_cells_range(
            *_check_range(wall_thickness_range, "wall_thickness_range"), res, "wall_thickness_range"
        ),
        door=_cells_range(*_check_range(door_width_range, "door_width_range"), res, "door_width_range"),
        margin=max(1, math.ceil(0.3 / res - _EPS)),
        long_floor=math.ceil(30.0 / res - _EPS),
    )
    length_cells = _cells_range(
        *_check_range(opening_length_range, "opening_length_range"), res, "opening_length_range"
    )
    least = p.door[1] + 2 * p.margin
    for key, cells in (("room_width_range", p.room_width), ("room_depth_range", p.room_depth)):
        if cells[0] < least:
            raise InputDataError(
                f"{key} must start at {least * res:g} m or more: the widest doorway "
                f"({door_width_range[1]} m) with 0.3 m of wall on either side"
            )
    if p.room_width[1] < 2 * p.room_width[0] + p.thickness[1]:
        raise InputDataError(
            f"room_width_range {tuple(room_width_range)} is too narrow: its high end must hold "
            "two rooms of its low end and a wall"
        )

    for _ in range(int(max_attempts)):
        H, W = _grid_size(rng, width_range, height_range, res)
        flip = H > W or (H == W and bool(rng.integers(2)))  # corridors along the longer side
        depth, length = (W, H) if flip else (H, W)
        plan = _office_plan(rng, depth, length, _draw(rng, corr), p)
        if plan is None:
            continue
        occ = plan.occ.T.copy() if flip else plan.occ
        k_in, k_out = _draw(rng, nin), _draw(rng, nout)
        openings = _draw_openings(rng, occ, res, k_in, k_out, length_cells, min_opening_gap_m)
        if openings is None:
            continue
        walls = tuple(_rects_m(occupancy_rectangles(occ), res))
        layout = Layout(occ, openings[0], openings[1], res, walls, _seed_name("office", rng_or_seed, name))
        if _connected(layout):
            parts = (plan.corridors, plan.rooms, plan.doors)
            office = OfficePlan(*(tuple(_rects_m(_transpose(x, flip), res)) for x in parts))
            return layout, office
    raise InputDataError(
        f"could not draw a valid office floor in {max_attempts} attempts: the corridors, rooms "
        f"or openings do not fit (width {tuple(width_range)} m, height {tuple(height_range)} m, "
        f"{n_corridors} corridors, rooms {tuple(room_depth_range)} m deep, {n_inlets} inlets, "
        f"{n_outlets} outlets, gap {min_opening_gap_m} m)"
    )


def random_office_floor(rng_or_seed: RngLike = None, **options: Any) -> Layout:
    """A random office floor: corridors, rooms on both sides with doors, several openings.

    ``options`` are the keyword arguments of :func:`random_office_floor_with_plan`
    (floor size, corridors, rooms, walls, doors, openings); this returns its layout only.

    Example:
        >>> lay = random_office_floor(1)
        >>> 200 <= min(lay.occupancy.shape) and max(lay.occupancy.shape) <= 400
        True
    """
    return random_office_floor_with_plan(rng_or_seed, **options)[0]
