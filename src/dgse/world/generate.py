"""Random indoor layouts, sources and inlet speeds (spec section 3, paper Sec. IV and App. D).

Training distribution (:func:`random_layout`):

* a rectangle ``W, H ~ U[5, 10] m`` snapped to whole cells;
* partitioned into rooms by recursive splits (a binary space partition): a
  straight wall 0.1-0.2 m thick crosses one room from wall (or outer boundary)
  to wall, along either direction, splitting it into two rooms at least
  ``min_room_m`` wide; every wall gets one doorway of 0.8-1.2 m, so the rooms
  form a tree of doorways and all free space is connected.  A wall's ends butt
  against solid at least 0.3 m away from any doorway (it never blocks or
  narrows one), and the wall stubs beside a doorway are absent or at least
  0.3 m long, so no free passage is narrower than 0.3 m;
* one inlet and one outlet on the outer boundary, each 0.6-1.5 m long, lying on
  free cells only (never on a wall end) and at least ``min_opening_gap_m`` apart.

Everything is done in whole cells: wall rectangles, doorways and openings all
start and end on cell faces, so ``rasterize_walls(grid, layout.walls)`` equals
``layout.occupancy`` exactly.

**Distance between openings** is the *gap*: the shortest Euclidean distance
between any point of one boundary segment and any point of the other (0 when
they touch or overlap).  It is the strictest of the usual definitions: a gap of
at least 2 m implies centres at least 2 m apart and an along-the-boundary
distance of at least 2 m.

Out-of-domain variants (:func:`random_ood_layout`, paper App. D): larger
domains (up to 15 x 10 m), several inlets and outlets, free-standing
rectangular obstacles with a free ring around them.

Sources (:func:`random_sources`) sit on free cell centres whose exact distance
to the nearest point of any solid cell or of the outer boundary is at least
``min_wall_distance`` (0.3 m).

Every generator takes a seed or a :class:`numpy.random.Generator` and is
deterministic given it.  A draw that breaks a rule (no room for an opening, a
disconnected free space) is redrawn with the same generator; after
``max_attempts`` failed draws an :class:`~dgse.errors.InputDataError` is
raised.  Nothing here imports the physics.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from dgse.errors import InputDataError
from dgse.world.grid import DEFAULT_RESOLUTION, Grid
from dgse.world.layout import SIDES, Layout, Opening

__all__ = [
    "RngLike",
    "as_generator",
    "free_components",
    "opening_gap",
    "random_inlet_velocity",
    "random_layout",
    "random_layout_with_rooms",
    "random_ood_layout",
    "random_sources",
    "source_candidates",
]

RngLike = int | np.random.Generator | np.random.SeedSequence | None

#: 4-connectivity structure for flood fills over free cells.
_FOUR = ndimage.generate_binary_structure(2, 1)
_EPS = 1e-9


def as_generator(rng_or_seed: RngLike) -> np.random.Generator:
    """A numpy Generator: ``rng_or_seed`` itself, or ``default_rng(rng_or_seed)``."""
    if isinstance(rng_or_seed, np.random.Generator):
        return rng_or_seed
    if isinstance(rng_or_seed, bool):
        raise InputDataError(f"a seed must be an int or a numpy Generator, got {rng_or_seed!r}")
    try:
        return np.random.default_rng(rng_or_seed)
    except (TypeError, ValueError) as e:
        raise InputDataError(f"bad seed {rng_or_seed!r}: {e}") from e


def _seed_name(prefix: str, rng_or_seed: RngLike, name: str | None) -> str:
    if name is not None:
        return name
    if isinstance(rng_or_seed, int | np.integer) and not isinstance(rng_or_seed, bool):
        return f"{prefix}-{int(rng_or_seed)}"
    return prefix


def _cells_range(lo_m: float, hi_m: float, res: float, what: str) -> tuple[int, int]:
    """Whole-cell counts ``[lo, hi]`` of lengths in ``[lo_m, hi_m]`` metres."""
    if not (0 < lo_m <= hi_m and math.isfinite(hi_m)):
        raise InputDataError(f"{what} range must be 0 < low <= high, got ({lo_m}, {hi_m})")
    lo = max(1, math.ceil(lo_m / res - _EPS))
    hi = math.floor(hi_m / res + _EPS)
    if hi < lo:
        raise InputDataError(f"{what} range ({lo_m}, {hi_m}) m holds no whole number of {res} m cells")
    return lo, hi


def _check_range(r: Sequence[float], what: str) -> tuple[float, float]:
    if len(r) != 2 or not (0 < r[0] <= r[1]) or not math.isfinite(r[1]):
        raise InputDataError(f"{what} must be (low, high) with 0 < low <= high, got {tuple(r)}")
    return float(r[0]), float(r[1])


def _int_range(r: int | Sequence[int], what: str, minimum: int = 0) -> tuple[int, int]:
    lo, hi = (int(r), int(r)) if isinstance(r, int | np.integer) else (int(r[0]), int(r[1]))
    if not (minimum <= lo <= hi):
        raise InputDataError(f"{what} must be (low, high) with {minimum} <= low <= high, got {r}")
    return lo, hi


# -- connectivity ------------------------------------------------------------------------
def free_components(occupancy: np.ndarray) -> tuple[np.ndarray, int]:
    """4-connected components of the free cells: labels ``(H, W)`` (0 on solid) and count."""
    labels, n = ndimage.label(np.asarray(occupancy) == 0, structure=_FOUR)
    return labels, int(n)


def ventilated_cells(layout: Layout) -> np.ndarray:
    """``bool (H, W)``: the free cells an inlet's air reaches (their 4-connected part holds an
    inlet cell).

    The others (a closed room, a walled-in cell, a part with outlets only) hold air at rest and
    no gas in the steady solution (spec section 4); a solver leaves them out or holds them there.

    Raises:
        InputDataError: an inlet opening into a part that no outlet reaches (its air has
            nowhere to go: no steady flow).
    """
    labels, _ = free_components(layout.occupancy)
    with_in = np.unique(labels[layout.opening_mask("inlet")])
    with_out = np.unique(labels[layout.opening_mask("outlet")])
    dead = np.setdiff1d(with_in[with_in > 0], with_out)
    if dead.size:
        i, j = (int(v[0]) for v in np.nonzero(labels == dead[0]))
        raise InputDataError(
            f"layout {layout.name!r}: an inlet opens into a free region that no outlet reaches "
            f"(the region of cell ({i}, {j})): its air has nowhere to go"
        )
    return np.isin(labels, with_in[with_in > 0])


def _connected(layout: Layout) -> bool:
    """True when the free cells form one 4-connected region holding every opening cell."""
    labels, n = free_components(layout.occupancy)
    if n != 1:
        return False
    for o in layout.inlets + layout.outlets:
        rows, cols = o.cells(layout.grid)
        if rows.size == 0 or (labels[rows, cols] != 1).any():
            return False
    return True


# -- recursive partition ------------------------------------------------------------------
@dataclass(frozen=True)
class _Room:
    """A free rectangle of cells: rows ``[r0, r1)``, columns ``[c0, c1)``."""

    r0: int
    r1: int
    c0: int
    c1: int

    @property
    def height(self) -> int:
        return self.r1 - self.r0

    @property
    def width(self) -> int:
        return self.c1 - self.c0


@dataclass(frozen=True)
class _PartitionParams:
    min_room: int  # cells
    thickness: tuple[int, int]  # cells
    door: tuple[int, int]  # cells
    margin: int  # cells: wall stubs and clearance of a wall end from a doorway


def _wall_positions(occ: np.ndarray, room: _Room, vertical: bool, t: int, p: _PartitionParams):
    """Valid first rows/columns of a wall of thickness ``t`` across ``room``.

    A vertical wall occupies columns ``[q, q + t)`` for all of the room's rows.
    Both rooms it leaves are at least ``min_room`` cells wide, and each of its two
    ends butts against solid cells (or the outer boundary) that extend ``margin``
    cells beyond it on either side, so the new wall never blocks or narrows an
    existing doorway.
    """
    H, W = occ.shape
    if vertical:
        lo, hi = room.c0 + p.min_room, room.c1 - p.min_room - t
        ends = [r for r in (room.r0 - 1, room.r1) if 0 <= r < H]
    else:
        lo, hi = room.r0 + p.min_room, room.r1 - p.min_room - t
        ends = [c for c in (room.c0 - 1, room.c1) if 0 <= c < W]
    if hi < lo:
        return np.zeros(0, dtype=int)
    q = np.arange(lo, hi + 1)
    ok = np.ones(q.size, dtype=bool)
    n = W if vertical else H
    for e in ends:
        line = occ[e, :] if vertical else occ[:, e]
        # solid[k] for k in [0, n); count solid in windows [q - margin, q + t + margin)
        csum = np.concatenate([[0], np.cumsum(line, dtype=np.int64)])
        a = np.clip(q - p.margin, 0, n)
        b = np.clip(q + t + p.margin, 0, n)
        ok &= (csum[b] - csum[a]) == (b - a)
    return q[ok]


def _door_offset(rng: np.random.Generator, length: int, door: int, margin: int) -> int:
    """Offset of a doorway of ``door`` cells in a wall of ``length`` cells.

    The wall stubs on either side are either absent or at least ``margin`` cells.
    """
    slack = length - door
    offs = np.arange(slack + 1)
    ok = ((offs == 0) | (offs >= margin)) & ((slack - offs == 0) | (slack - offs >= margin))
    return int(rng.choice(offs[ok]))


def _split(rng, occ, room: _Room, p: _PartitionParams):
    """Split ``room`` by one wall with a doorway; ``None`` when it cannot be split.

    Returns the two new rooms and the wall segments ``(r0, r1, c0, c1)`` in cells;
    ``occ`` is updated in place.
    """
    t = int(rng.integers(p.thickness[0], p.thickness[1] + 1))
    options = []
    for vertical in (True, False):
        pos = _wall_positions(occ, room, vertical, t, p)
        if pos.size:
            options.append((vertical, pos))
    if not options:
        return None
    # Split across the longer side more often: weight by the length being cut.
    weights = np.array([room.width if v else room.height for v, _ in options], dtype=float)
    vertical, pos = options[int(rng.choice(len(options), p=weights / weights.sum()))]
    q = int(rng.choice(pos))
    length = room.height if vertical else room.width
    door = int(rng.integers(p.door[0], p.door[1] + 1))
    door = min(door, length)
    d0 = _door_offset(rng, length, door, p.margin)
    segments = []
    if vertical:
        for a, b in ((room.r0, room.r0 + d0), (room.r0 + d0 + door, room.r1)):
            if b > a:
                segments.append((a, b, q, q + t))
        rooms = (_Room(room.r0, room.r1, room.c0, q), _Room(room.r0, room.r1, q + t, room.c1))
    else:
        for a, b in ((room.c0, room.c0 + d0), (room.c0 + d0 + door, room.c1)):
            if b > a:
                segments.append((q, q + t, a, b))
        rooms = (_Room(room.r0, q, room.c0, room.c1), _Room(q + t, room.r1, room.c0, room.c1))
    for r0, r1, c0, c1 in segments:
        occ[r0:r1, c0:c1] = 1
    return rooms, segments


def _partition(rng, shape: tuple[int, int], n_rooms: int, p: _PartitionParams):
    """Occupancy ``(H, W)``, wall segments (cells) and rooms of a recursive partition.

    Up to ``n_rooms - 1`` splits; each picks a splittable room with probability
    proportional to its area.  Fewer rooms result when no room can be split.
    """
    occ = np.zeros(shape, dtype=np.uint8)
    rooms = [_Room(0, shape[0], 0, shape[1])]
    segments: list[tuple[int, int, int, int]] = []
    blocked: set[_Room] = set()
    while len(rooms) < n_rooms:
        cand = [r for r in rooms if r not in blocked]
        if not cand:
            break
        area = np.array([r.width * r.height for r in cand], dtype=float)
        room = cand[int(rng.choice(len(cand), p=area / area.sum()))]
        out = _split(rng, occ, room, p)
        if out is None:
            blocked.add(room)
            continue
        rooms.remove(room)
        rooms.extend(out[0])
        segments.extend(out[1])
    return occ, segments, rooms


def _rects_m(segments, res: float) -> list[tuple[float, float, float, float]]:
    """Cell rectangles ``(r0, r1, c0, c1)`` as ``(x0, y0, x1, y1)`` in metres."""
    return [
        (round(c0 * res, 9), round(r0 * res, 9), round(c1 * res, 9), round(r1 * res, 9))
        for r0, r1, c0, c1 in segments
    ]


# -- openings ------------------------------------------------------------------------------
def _segment_points(side: str, start: np.ndarray, end: np.ndarray, W: float, H: float):
    """End points ``(x0, y0, x1, y1)`` of boundary segments along ``side``."""
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    if side == "west":
        return np.zeros_like(start), start, np.zeros_like(start), end
    if side == "east":
        return np.full_like(start, W), start, np.full_like(start, W), end
    if side == "south":
        return start, np.zeros_like(start), end, np.zeros_like(start)
    return start, np.full_like(start, H), end, np.full_like(start, H)


def _point_segment_distance(px, py, ax, ay, bx, by):
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = np.where(L2 > 0, ((px - ax) * dx + (py - ay) * dy) / np.where(L2 > 0, L2, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.hypot(px - (ax + t * dx), py - (ay + t * dy))


def _segments_gap(s1, s2):
    """Shortest distance between segments ``s1``, ``s2`` (tuples of end-point arrays).

    The least of the four end-point-to-segment distances: exact for segments that
    do not cross, as segments on a rectangle's boundary never do (overlapping or
    touching ones get 0 through an end point lying on the other segment).
    """
    ax, ay, bx, by = s1
    cx, cy, dx, dy = s2
    d = np.minimum.reduce(
        [
            _point_segment_distance(ax, ay, cx, cy, dx, dy),
            _point_segment_distance(bx, by, cx, cy, dx, dy),
            _point_segment_distance(cx, cy, ax, ay, bx, by),
            _point_segment_distance(dx, dy, ax, ay, bx, by),
        ]
    )
    return d


def opening_gap(a: Opening, b: Opening, width_m: float, height_m: float) -> float:
    """The gap in m between two openings of a ``width_m x height_m`` domain.

    The shortest Euclidean distance between any point of one segment and any
    point of the other; 0 when they touch or overlap.
    """
    s1 = _segment_points(a.side, np.array([a.start_m]), np.array([a.end_m]), width_m, height_m)
    s2 = _segment_points(b.side, np.array([b.start_m]), np.array([b.end_m]), width_m, height_m)
    return float(_segments_gap(s1, s2)[0])


def _boundary_free(occ: np.ndarray, side: str) -> np.ndarray:
    """Free flags of the boundary cells along ``side`` (in the side's along-order)."""
    line = {"west": occ[:, 0], "east": occ[:, -1], "south": occ[0, :], "north": occ[-1, :]}[side]
    return line == 0


def _draw_opening(
    rng,
    occ: np.ndarray,
    res: float,
    length_cells: tuple[int, int],
    existing: list[Opening],
    min_gap: float,
    tries: int = 8,
) -> Opening | None:
    """One opening on free boundary cells, at least ``min_gap`` m from ``existing``.

    The length is drawn uniformly from whole cells in ``length_cells``; then the
    position uniformly over every valid (side, start) of the whole perimeter.
    """
    H, W = occ.shape
    Wm, Hm = W * res, H * res
    for _ in range(tries):
        n = int(rng.integers(length_cells[0], length_cells[1] + 1))
        cands: list[tuple[str, np.ndarray]] = []
        for side in SIDES:
            free = _boundary_free(occ, side).astype(np.int64)
            if free.size < n:
                continue
            csum = np.concatenate([[0], np.cumsum(free)])
            starts = np.nonzero(csum[n:] - csum[:-n] == n)[0]
            if starts.size and existing:
                seg = _segment_points(side, starts * res, (starts + n) * res, Wm, Hm)
                ok = np.ones(starts.size, dtype=bool)
                for o in existing:
                    s2 = _segment_points(o.side, np.array([o.start_m]), np.array([o.end_m]), Wm, Hm)
                    ok &= _segments_gap(seg, s2) >= min_gap - _EPS
                starts = starts[ok]
            if starts.size:
                cands.append((side, starts))
        total = sum(s.size for _, s in cands)
        if total == 0:
            continue
        k = int(rng.integers(total))
        for side, starts in cands:
            if k < starts.size:
                s = int(starts[k])
                return Opening(side, round(s * res, 9), round((s + n) * res, 9))
            k -= starts.size
    return None


def _draw_openings(rng, occ, res, n_in: int, n_out: int, length_cells, min_gap):
    """Inlets and outlets (in that drawing order) or ``None`` when they do not fit."""
    placed: list[Opening] = []
    for _ in range(n_in + n_out):
        o = _draw_opening(rng, occ, res, length_cells, placed, min_gap)
        if o is None:
            return None
        placed.append(o)
    return tuple(placed[:n_in]), tuple(placed[n_in:])


# -- obstacles -------------------------------------------------------------------------------
def _draw_obstacle(
    rng, occ: np.ndarray, size_cells: tuple[int, int], clearance: int, tries: int = 8
) -> tuple[int, int, int, int] | None:
    """A free-standing rectangle ``(r0, r1, c0, c1)`` with ``clearance`` free cells around it.

    The ring of ``clearance`` cells around it is free and inside the domain, so
    it touches no wall, obstacle or outer boundary and cannot cut the free space.
    """
    H, W = occ.shape
    sat = np.zeros((H + 1, W + 1), dtype=np.int64)
    sat[1:, 1:] = np.cumsum(np.cumsum(occ, axis=0, dtype=np.int64), axis=1)
    for _ in range(tries):
        h, w = (int(v) for v in rng.integers(size_cells[0], size_cells[1] + 1, size=2))
        bh, bw = h + 2 * clearance, w + 2 * clearance  # box with its free ring
        if bh > H or bw > W:
            continue
        # boxes with lower-left (i, j), i in [0, H - bh], j in [0, W - bw]
        s = sat[bh:, bw:] - sat[:-bh, bw:] - sat[bh:, :-bw] + sat[:-bh, :-bw]
        ii, jj = np.nonzero(s == 0)
        if ii.size == 0:
            continue
        k = int(rng.integers(ii.size))
        r0, c0 = int(ii[k]) + clearance, int(jj[k]) + clearance
        return r0, r0 + h, c0, c0 + w
    return None


# -- public generators ------------------------------------------------------------------------
def _grid_size(rng, width_range, height_range, res) -> tuple[int, int]:
    """``(H, W)`` cells of a rectangle with sides drawn uniformly in metres, snapped."""
    wlo, whi = _check_range(width_range, "width_range")
    hlo, hhi = _check_range(height_range, "height_range")
    W = round(float(rng.uniform(wlo, whi)) / res)
    H = round(float(rng.uniform(hlo, hhi)) / res)
    # keep the snapped size inside the range where the range allows it
    W = min(max(W, math.ceil(wlo / res - _EPS)), math.floor(whi / res + _EPS))
    H = min(max(H, math.ceil(hlo / res - _EPS)), math.floor(hhi / res + _EPS))
    return max(H, 1), max(W, 1)


def _generate(
    rng,
    *,
    width_range,
    height_range,
    resolution,
    n_rooms,
    min_room_m,
    wall_thickness_range,
    door_width_range,
    opening_length_range,
    min_opening_gap_m,
    n_inlets,
    n_outlets,
    n_obstacles,
    obstacle_size_range,
    obstacle_clearance_m,
    max_attempts,
    name,
    what,
):
    res = float(resolution)
    if not (res > 0 and math.isfinite(res)):
        raise InputDataError(f"resolution must be positive, got {resolution}")
    rooms_lo, rooms_hi = _int_range(n_rooms, "n_rooms", 1)
    nin = _int_range(n_inlets, "n_inlets", 1)
    nout = _int_range(n_outlets, "n_outlets", 1)
    nobs = _int_range(n_obstacles, "n_obstacles", 0)
    if min_room_m <= 0:
        raise InputDataError(f"min_room_m must be positive, got {min_room_m}")
    params = _PartitionParams(
        min_room=max(1, math.ceil(min_room_m / res - _EPS)),
        thickness=_cells_range(*wall_thickness_range, res, "wall_thickness_range"),
        door=_cells_range(*door_width_range, res, "door_width_range"),
        margin=max(1, math.ceil(0.3 / res - _EPS)),
    )
    length_cells = _cells_range(*opening_length_range, res, "opening_length_range")
    obs_cells = _cells_range(*obstacle_size_range, res, "obstacle_size_range")
    clearance = max(1, math.ceil(obstacle_clearance_m / res - _EPS))
    if max_attempts < 1:
        raise InputDataError(f"max_attempts must be at least 1, got {max_attempts}")

    for _ in range(int(max_attempts)):
        shape = _grid_size(rng, width_range, height_range, res)
        target = int(rng.integers(rooms_lo, rooms_hi + 1))
        occ, segments, rooms = _partition(rng, shape, target, params)
        obstacles = []
        for _k in range(int(rng.integers(nobs[0], nobs[1] + 1))):
            box = _draw_obstacle(rng, occ, obs_cells, clearance)
            if box is None:
                break
            occ[box[0] : box[1], box[2] : box[3]] = 1
            obstacles.append(box)
        k_in = int(rng.integers(nin[0], nin[1] + 1))
        k_out = int(rng.integers(nout[0], nout[1] + 1))
        openings = _draw_openings(rng, occ, res, k_in, k_out, length_cells, min_opening_gap_m)
        if openings is None:
            continue
        layout = Layout(
            occ,
            openings[0],
            openings[1],
            res,
            tuple(_rects_m(segments + obstacles, res)),
            name,
        )
        if _connected(layout):
            room_rects = [(r.r0, r.r1, r.c0, r.c1) for r in rooms]
            return layout, _rects_m(room_rects, res)
    raise InputDataError(
        f"could not draw a valid {what} in {max_attempts} attempts: the openings, rooms or "
        f"obstacles do not fit (width {width_range} m, height {height_range} m, "
        f"{n_inlets} inlets, {n_outlets} outlets, gap {min_opening_gap_m} m)"
    )


def random_layout_with_rooms(
    rng_or_seed: RngLike = None, **options: Any
) -> tuple[Layout, list[tuple[float, float, float, float]]]:
    """A random training layout (spec section 3) and its rooms.

    ``options`` are the keyword arguments of :func:`random_layout` (same defaults, same
    draws); this also returns the rooms: the free rectangles ``(x0, y0, x1, y1)`` in m of
    the partition (their number is the room count; doorways lie between them).
    """
    bound = inspect.signature(random_layout).bind(rng_or_seed, **options)
    bound.apply_defaults()
    return _random_training(**bound.arguments)


def random_layout(
    rng_or_seed: RngLike = None,
    *,
    width_range: tuple[float, float] = (5.0, 10.0),
    height_range: tuple[float, float] = (5.0, 10.0),
    resolution: float = DEFAULT_RESOLUTION,
    n_rooms: int | tuple[int, int] = (2, 6),
    min_room_m: float = 1.5,
    wall_thickness_range: tuple[float, float] = (0.1, 0.2),
    door_width_range: tuple[float, float] = (0.8, 1.2),
    opening_length_range: tuple[float, float] = (0.6, 1.5),
    min_opening_gap_m: float = 2.0,
    max_attempts: int = 100,
    name: str | None = None,
) -> Layout:
    """A random multi-room layout of the training distribution (spec section 3).

    Args:
        rng_or_seed: a seed or a numpy Generator (which is advanced).
        width_range, height_range: domain sides in m, drawn uniformly, snapped to
            whole cells (``W = round(U / resolution)`` cells, kept in the range).
        resolution: cell size in m.
        n_rooms: number of rooms ``(low, high)`` drawn uniformly (or one int);
            fewer when the rooms cannot be split any more.
        min_room_m: smallest width of a room in m (both directions).
        wall_thickness_range: wall thickness in m, whole cells (1-2 at 0.1 m).
        door_width_range: doorway width in m, whole cells; one doorway per wall,
            with wall stubs beside it either absent or at least 0.3 m long.
        opening_length_range: inlet/outlet length in m, whole cells.
        min_opening_gap_m: least gap (shortest distance between the segments) in m
            between the inlet and the outlet.
        max_attempts: redraws before giving up with :class:`InputDataError`.
        name: layout name; default ``"random-<seed>"`` (or ``"random"`` for a Generator).

    Returns:
        A :class:`Layout` with ``occupancy`` ``uint8 (H, W)``, one inlet, one
        outlet, and ``walls`` the wall rectangles ``(x0, y0, x1, y1)`` in m
        (``rasterize_walls`` of them gives the occupancy).  The free cells are
        one 4-connected region holding both openings.

    Example:
        >>> lay = random_layout(3)
        >>> 50 <= lay.occupancy.shape[0] <= 100 and len(lay.inlets) == 1
        True
    """
    layout, _ = _random_training(
        rng_or_seed,
        width_range=width_range,
        height_range=height_range,
        resolution=resolution,
        n_rooms=n_rooms,
        min_room_m=min_room_m,
        wall_thickness_range=wall_thickness_range,
        door_width_range=door_width_range,
        opening_length_range=opening_length_range,
        min_opening_gap_m=min_opening_gap_m,
        max_attempts=max_attempts,
        name=name,
    )
    return layout


def _random_training(rng_or_seed: RngLike, *, name: str | None, **kwargs):
    return _generate(
        as_generator(rng_or_seed),
        n_inlets=1,
        n_outlets=1,
        n_obstacles=0,
        obstacle_size_range=(0.3, 1.5),
        obstacle_clearance_m=0.5,
        name=_seed_name("random", rng_or_seed, name),
        what="layout",
        **kwargs,
    )


def random_ood_layout(
    rng_or_seed: RngLike = None,
    *,
    min_width: float = 5.0,
    max_width: float = 15.0,
    min_height: float = 5.0,
    max_height: float = 10.0,
    resolution: float = DEFAULT_RESOLUTION,
    n_inlets: int | tuple[int, int] = (1, 3),
    n_outlets: int | tuple[int, int] = (1, 3),
    n_obstacles: int | tuple[int, int] = (0, 4),
    n_rooms: int | tuple[int, int] = (1, 6),
    min_room_m: float = 1.5,
    wall_thickness_range: tuple[float, float] = (0.1, 0.2),
    door_width_range: tuple[float, float] = (0.8, 1.2),
    opening_length_range: tuple[float, float] = (0.6, 1.5),
    min_opening_gap_m: float = 2.0,
    obstacle_size_range: tuple[float, float] = (0.3, 1.5),
    obstacle_clearance_m: float = 0.5,
    max_attempts: int = 100,
    name: str | None = None,
) -> Layout:
    """A random out-of-domain layout (paper App. D).

    Like :func:`random_layout`, with a domain of ``U[min_width, max_width] x
    U[min_height, max_height]`` m, ``n_inlets`` inlets and ``n_outlets`` outlets
    (each ``(low, high)`` drawn uniformly, or one int) that are pairwise at least
    ``min_opening_gap_m`` apart, and ``n_obstacles`` free-standing rectangular
    obstacles with sides in ``obstacle_size_range`` m and a free ring of at least
    ``obstacle_clearance_m`` around them (they touch no wall, no other obstacle
    and not the outer boundary, so the flow passes around them).  Obstacles are
    appended to ``walls`` after the wall segments.  Fewer obstacles result where
    no free spot is left.  Same connectivity guarantee as :func:`random_layout`.
    """
    rng = as_generator(rng_or_seed)
    layout, _ = _generate(
        rng,
        width_range=(min_width, max_width),
        height_range=(min_height, max_height),
        resolution=resolution,
        n_rooms=n_rooms,
        min_room_m=min_room_m,
        wall_thickness_range=wall_thickness_range,
        door_width_range=door_width_range,
        opening_length_range=opening_length_range,
        min_opening_gap_m=min_opening_gap_m,
        n_inlets=n_inlets,
        n_outlets=n_outlets,
        n_obstacles=n_obstacles,
        obstacle_size_range=obstacle_size_range,
        obstacle_clearance_m=obstacle_clearance_m,
        max_attempts=max_attempts,
        name=_seed_name("ood", rng_or_seed, name),
        what="out-of-domain layout",
    )
    return layout


# -- sources and inlet speed ------------------------------------------------------------------
def source_candidates(layout: Layout, min_wall_distance: float = 0.3) -> np.ndarray:
    """Boolean ``(H, W)`` mask of free cells whose centre is far enough from solid.

    The distance is exact: from the cell centre to the nearest point of any solid
    cell (a square) or of the outer boundary; cells with distance
    ``>= min_wall_distance`` m qualify.
    """
    occ = layout.occupancy
    free = occ == 0
    reach = float(min_wall_distance) / layout.resolution  # in cells
    if reach <= 0:
        return free
    R = math.ceil(reach + 0.5)
    d = np.arange(-R, R + 1)
    near = np.maximum(np.abs(d) - 0.5, 0.0)
    # solid cell at offset (di, dj) lies closer than the limit: a dilation footprint
    footprint = np.hypot(near[:, None], near[None, :]) < reach - _EPS
    solid = np.pad(~free, R, constant_values=True)  # beyond the boundary is "solid"
    too_close = ndimage.binary_dilation(solid, structure=footprint)[R:-R, R:-R]
    return free & ~too_close


def random_sources(
    layout: Layout,
    rng: RngLike = None,
    n: int = 4,
    min_wall_distance: float = 0.3,
    rate_range: tuple[float, float] = (0.01, 5.0),
) -> list[tuple[tuple[float, float], float]]:
    """``n`` gas sources: ``((x, y) in m, release rate q in g/s)``.

    Positions are the centres of ``n`` distinct free cells drawn uniformly from
    :func:`source_candidates` (at least ``min_wall_distance`` m from any solid
    cell or the outer boundary); rates ``q ~ U[rate_range]`` g/s.
    """
    gen = as_generator(rng)
    lo, hi = _check_range(rate_range, "rate_range")
    if n < 0:
        raise InputDataError(f"number of sources must be >= 0, got {n}")
    cells = np.argwhere(source_candidates(layout, min_wall_distance))
    if len(cells) < n:
        raise InputDataError(
            f"layout {layout.name!r} has only {len(cells)} free cells at least "
            f"{min_wall_distance} m from walls, {n} sources requested"
        )
    pick = cells[gen.choice(len(cells), size=n, replace=False)]
    xy = Grid(layout.occupancy.shape, layout.resolution).centers_of(pick)
    rates = gen.uniform(lo, hi, size=n)
    return [((float(p[0]), float(p[1])), float(q)) for p, q in zip(xy, rates, strict=True)]


def random_inlet_velocity(rng: RngLike = None, velocity_range: tuple[float, float] = (0.5, 5.0)) -> float:
    """Inlet speed ``v_in ~ U[velocity_range]`` in m/s (normal into the domain)."""
    lo, hi = _check_range(velocity_range, "velocity_range")
    return float(as_generator(rng).uniform(lo, hi))
