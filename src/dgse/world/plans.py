"""Drawn floor plans: furnished houses and office floors as images, read by the floor-plan import.

Real floor plans reach the toolkit as images (``dgse import-floorplan``): walls
drawn at 0.01-0.05 m per pixel that do not line up with the 0.1 m cells, outer
walls with gaps for windows and doors, furniture in the rooms, doorways and
gaps between furniture a few cells wide.  The generators of
:mod:`dgse.world.generate` and :mod:`dgse.world.building` draw in whole cells,
so they never show what that resampling makes of a plan.  This module draws
such plans, seeded, so that the solver and the import can be tested and
benchmarked on them (``python benchmarks/solver.py floorplans``); it belongs to
the library, beside :mod:`dgse.world.floorplan`, because tests of every layer
use it.

* :func:`draw_house`: a house of 8-14 m per side (outer walls 0.15-0.3 m thick)
  cut into 4-9 rooms by binary space partition; every inner wall (0.08-0.15 m)
  has one doorway of 0.5-1.0 m (one in five 0.5-0.6 m: a narrow passage);
  every room gets 0-4 pieces of furniture (beds, sofas, tables, wardrobes,
  shelves, counters, columns) against a wall or free-standing, clear of the
  doorways.
* :func:`draw_office`: an office floor with one corridor (1.6-2.4 m wide) along
  its longer side, rooms 2.5-5 m wide on both sides, each with a door onto the
  corridor and desks and cabinets inside; ``size=(30, 30)`` gives a 30 x 30 m
  floor.
* Openings: 1-3 inlets and 1-3 outlets (0.4-1.2 m wide) are gaps in the outer
  wall, on the image's edge, with free floor behind them; pairwise at least
  1 m apart.  The inlet speed is drawn too: slow (0.2-0.5 m/s) in three draws
  of ten, else 0.5-3 m/s.

Sides are whole multiples of 0.1 m, so a plan imported at 0.1 m (or 0.05 m)
has no partial last row or column.  :meth:`DrawnPlan.save_png` writes the
image (dark solid, light free, row 0 at the top) and :func:`import_plan` reads
it back by the calls ``dgse import-floorplan PNG --pixel-size S --inlet ...
--outlet ...`` makes (:func:`~dgse.world.floorplan.load_png_map`, then
:func:`~dgse.world.floorplan.layout_from_floorplan`).  A draw whose openings
do not reach each other after the import (furniture closing a room) is drawn
again from the same generator.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dgse.errors import InputDataError
from dgse.world.floorplan import layout_from_floorplan, load_png_map
from dgse.world.generate import RngLike, as_generator, opening_gap
from dgse.world.grid import DEFAULT_RESOLUTION
from dgse.world.layout import Layout, Opening

__all__ = ["PIXEL_SIZES", "DrawnPlan", "draw_house", "draw_office", "draw_plan", "import_plan"]

#: the pixel sides a plan is drawn at, m (each divides 0.1 m)
PIXEL_SIZES = (0.01, 0.02, 0.025, 0.05)

Rect = tuple[float, float, float, float]  # (x0, y0, x1, y1) in m

#: furniture footprints (m): beds, sofas, tables, wardrobes, shelves, counters, a column
_FURNITURE = (
    (1.4, 2.0), (0.9, 2.0), (0.9, 2.1), (0.8, 1.2), (1.0, 1.0), (0.6, 1.2),
    (0.35, 1.0), (0.6, 2.4), (0.5, 0.5), (0.3, 0.3),
)  # fmt: skip
_OFFICE_FURNITURE = ((0.7, 1.4), (0.8, 1.6), (0.45, 1.0), (1.0, 2.0), (0.6, 0.6))


@dataclass(frozen=True)
class DrawnPlan:
    """A floor plan drawn as an image, with its openings.

    Attributes:
        name: e.g. ``house-3``.
        kind: ``"house"`` or ``"office"``.
        solid: ``bool (h, w)``, True where the plan is drawn dark; row 0 is the bottom.
        pixel_size: pixel side in m.
        inlets, outlets: the gaps of the outer wall, in m along each side from the
            lower-left corner (the frame of ``dgse import-floorplan --inlet``).
        inlet_velocity: a drawn inlet speed for the plan, m/s.
    """

    name: str
    kind: str
    solid: np.ndarray
    pixel_size: float
    inlets: tuple[Opening, ...]
    outlets: tuple[Opening, ...]
    inlet_velocity: float

    @property
    def size_m(self) -> tuple[float, float]:
        """``(width, height)`` in m."""
        h, w = self.solid.shape
        return round(w * self.pixel_size, 9), round(h * self.pixel_size, 9)

    def image(self) -> np.ndarray:
        """``uint8 (h, w)`` grey image, row 0 at the top: 0 solid, 255 free."""
        return np.where(np.flipud(self.solid), 0, 255).astype(np.uint8)

    def save_png(self, path: str | Path) -> Path:
        """Write :meth:`image` as a PNG; returns the path."""
        from PIL import Image

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(self.image(), mode="L").save(path)
        return path

    def import_args(self) -> list[str]:
        """The ``dgse import-floorplan`` options that read the saved PNG back."""
        args = ["--pixel-size", f"{self.pixel_size:g}"]
        for flag, group in (("--inlet", self.inlets), ("--outlet", self.outlets)):
            for o in group:
                args += [flag, o.side, f"{o.start_m:g}", f"{o.end_m:g}"]
        return args


class _Canvas:
    """A solid mask of square pixels drawn with rectangles in m (row 0 = bottom)."""

    def __init__(self, width_m: float, height_m: float, pixel_size: float) -> None:
        self.ps = pixel_size
        self.W, self.H = width_m, height_m
        self.solid = np.zeros((round(height_m / pixel_size), round(width_m / pixel_size)), dtype=bool)

    def _px(self, r: Rect) -> tuple[slice, slice]:
        h, w = self.solid.shape
        c0, c1 = (min(max(round(v / self.ps), 0), w) for v in (r[0], r[2]))
        r0, r1 = (min(max(round(v / self.ps), 0), h) for v in (r[1], r[3]))
        return slice(r0, r1), slice(c0, c1)

    def fill(self, r: Rect, value: bool = True) -> None:
        self.solid[self._px(r)] = value

    def free(self, r: Rect) -> bool:
        return not self.solid[self._px(r)].any()


def _overlaps(a: Rect, b: Rect, gap: float = 0.0) -> bool:
    return a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap


def _inside(a: Rect, room: Rect) -> bool:
    return a[0] >= room[0] and a[1] >= room[1] and a[2] <= room[2] and a[3] <= room[3]


def _door_width(rng: np.random.Generator) -> float:
    return float(rng.uniform(0.5, 0.6) if rng.random() < 0.2 else rng.uniform(0.7, 1.0))


def _split_rooms(rng: np.random.Generator, interior: Rect, n_rooms: int, min_room: float):
    """Binary space partition of ``interior`` into up to ``n_rooms`` rooms.

    Returns ``(rooms, walls, doors)``: room rectangles, inner wall rectangles and
    one doorway rectangle (through its wall) per wall.
    """
    rooms, walls, doors = [interior], [], []
    for _ in range(20 * n_rooms):
        if len(rooms) >= n_rooms:
            break
        k = int(rng.integers(len(rooms)))
        x0, y0, x1, y1 = rooms[k]
        t = float(rng.uniform(0.08, 0.15))
        vertical = (x1 - x0) > (y1 - y0) if rng.random() < 0.8 else bool(rng.random() < 0.5)
        lo, hi = (x0, x1) if vertical else (y0, y1)
        if hi - lo < 2 * min_room + t:
            continue
        pos = float(rng.uniform(lo + min_room, hi - min_room - t))
        a0, a1 = (y0, y1) if vertical else (x0, x1)  # along the new wall
        dw = min(_door_width(rng), a1 - a0 - 0.4)
        d0 = float(rng.uniform(a0 + 0.2, a1 - 0.2 - dw))
        if vertical:
            walls.append((pos, y0, pos + t, y1))
            doors.append((pos, d0, pos + t, d0 + dw))
            rooms[k : k + 1] = [(x0, y0, pos, y1), (pos + t, y0, x1, y1)]
        else:
            walls.append((x0, pos, x1, pos + t))
            doors.append((d0, pos, d0 + dw, pos + t))
            rooms[k : k + 1] = [(x0, y0, x1, pos), (x0, pos + t, x1, y1)]
    return rooms, walls, doors


def _clearance(door: Rect, depth: float = 0.7) -> Rect:
    """The floor a doorway needs kept free on both sides (``depth`` m deep)."""
    x0, y0, x1, y1 = door
    if x1 - x0 < y1 - y0:  # a doorway through a vertical wall
        return (x0 - depth, y0 - 0.1, x1 + depth, y1 + 0.1)
    return (x0 - 0.1, y0 - depth, x1 + 0.1, y1 + depth)


def _furnish(
    rng: np.random.Generator,
    canvas: _Canvas,
    room: Rect,
    keep_free: list[Rect],
    catalog,
    count: int,
) -> list[Rect]:
    """Up to ``count`` furniture blocks in ``room``, off ``keep_free`` and 0.3 m apart."""
    placed: list[Rect] = []
    for _ in range(12 * count):
        if len(placed) >= count:
            break
        a, b = catalog[int(rng.integers(len(catalog)))]
        if rng.random() < 0.5:
            a, b = b, a
        x0, y0, x1, y1 = room
        if x1 - x0 < a + 0.6 or y1 - y0 < b + 0.6:
            continue
        if rng.random() < 0.7:  # against a wall (touching it or a small gap off it)
            off = 0.0 if rng.random() < 0.6 else float(rng.uniform(0.05, 0.3))
            side = int(rng.integers(4))
            if side < 2:
                x = x0 + off if side == 0 else x1 - off - a
                y = float(rng.uniform(y0, y1 - b))
            else:
                y = y0 + off if side == 2 else y1 - off - b
                x = float(rng.uniform(x0, x1 - a))
        else:
            x = float(rng.uniform(x0 + 0.3, x1 - 0.3 - a))
            y = float(rng.uniform(y0 + 0.3, y1 - 0.3 - b))
        r = (x, y, x + a, y + b)
        if not _inside(r, room) or any(_overlaps(r, k) for k in keep_free):
            continue
        if any(_overlaps(r, p, 0.3) for p in placed):
            continue
        placed.append(r)
        canvas.fill(r)
    return placed


def _openings(
    rng: np.random.Generator, canvas: _Canvas, t_out: float, n_in: int, n_out: int
) -> tuple[tuple[Opening, ...], tuple[Opening, ...]] | None:
    """Gaps in the outer wall with free floor behind them (0.6 m deep), cut into ``canvas``."""
    W, H = canvas.W, canvas.H
    placed: list[Opening] = []
    for _ in range(60 * (n_in + n_out)):
        if len(placed) == n_in + n_out:
            break
        side = ("west", "east", "south", "north")[int(rng.integers(4))]
        length = H if side in ("west", "east") else W
        w = float(rng.uniform(0.4, 1.2))
        s = float(rng.uniform(t_out + 0.15, length - t_out - 0.15 - w))
        s, e = round(s, 3), round(s + w, 3)
        behind = {
            "west": (t_out, s, t_out + 0.6, e),
            "east": (W - t_out - 0.6, s, W - t_out, e),
            "south": (s, t_out, e, t_out + 0.6),
            "north": (s, H - t_out - 0.6, e, H - t_out),
        }[side]
        o = Opening(side, s, e)
        if not canvas.free(behind) or any(opening_gap(o, p, W, H) < 1.0 for p in placed):
            continue
        placed.append(o)
    if len(placed) < n_in + n_out:
        return None
    for o in placed:
        s, e = o.start_m, o.end_m
        gap = {
            "west": (0.0, s, t_out, e),
            "east": (W - t_out, s, W, e),
            "south": (s, 0.0, e, t_out),
            "north": (s, H - t_out, e, H),
        }[o.side]
        canvas.fill(gap, False)
    return tuple(placed[:n_in]), tuple(placed[n_in:])


def _velocity(rng: np.random.Generator) -> float:
    return round(float(rng.uniform(0.2, 0.5) if rng.random() < 0.3 else rng.uniform(0.5, 3.0)), 3)


def _pixel_size(rng: np.random.Generator, pixel_size: float | None) -> float:
    ps = PIXEL_SIZES[int(rng.integers(len(PIXEL_SIZES)))] if pixel_size is None else float(pixel_size)
    if not ps > 0 or abs(0.1 / ps - round(0.1 / ps)) > 1e-6:
        raise InputDataError(f"pixel_size must divide 0.1 m, got {pixel_size}")
    return ps


def _checked(plan: DrawnPlan, resolution: float) -> bool:
    """Whether the plan imports at ``resolution`` (every inlet's air reaches an outlet)."""
    from dgse.world.floorplan import resample_occupancy

    occ = resample_occupancy(plan.solid, plan.pixel_size, resolution)
    try:
        layout_from_floorplan(occ, resolution, plan.inlets, plan.outlets)
    except InputDataError:
        return False
    return True


def _retry(draw, rng: np.random.Generator, resolution: float, attempts: int, what: str) -> DrawnPlan:
    for _ in range(attempts):
        plan = draw(rng)
        if plan is not None and _checked(plan, resolution):
            return plan
    raise InputDataError(f"no valid {what} in {attempts} draws")


def _snap(v: float) -> float:
    return round(round(v / 0.1) * 0.1, 9)


def _start(
    rng_or_seed: RngLike, kind: str, pixel_size: float | None
) -> tuple[np.random.Generator, str, float]:
    """A plan's generator, its name (``<kind>-<seed>`` for an integer seed) and its pixel size."""
    rng = as_generator(rng_or_seed)
    name = f"{kind}-{rng_or_seed}" if isinstance(rng_or_seed, int) else kind
    return rng, name, _pixel_size(rng, pixel_size)


def _shell(rng: np.random.Generator, W: float, H: float, ps: float) -> tuple[_Canvas, float]:
    """A ``W x H`` m canvas whose outer wall, of a drawn thickness ``t``, is all that is solid."""
    canvas = _Canvas(W, H, ps)
    t = float(rng.uniform(0.15, 0.3))
    canvas.fill((0.0, 0.0, W, H))
    canvas.fill((t, t, W - t, H - t), False)
    return canvas, t


def draw_house(
    rng_or_seed: RngLike = None,
    *,
    pixel_size: float | None = None,
    size_range: tuple[float, float] = (8.0, 14.0),
    resolution: float = DEFAULT_RESOLUTION,
    max_attempts: int = 50,
) -> DrawnPlan:
    """A furnished house drawn at ``pixel_size`` m per pixel (module doc).

    Args:
        rng_or_seed: a seed or generator (the plan is a function of it).
        pixel_size: pixel side in m, one of :data:`PIXEL_SIZES` or any divisor of
            0.1 m (default: drawn from :data:`PIXEL_SIZES`).
        size_range: the range of both sides, m.
        resolution: the cell size the plan must import at with its openings connected.
        max_attempts: draws before giving up.
    """
    rng, name, ps = _start(rng_or_seed, "house", pixel_size)

    def draw(rng: np.random.Generator) -> DrawnPlan | None:
        W, H = (_snap(rng.uniform(*size_range)) for _ in range(2))
        canvas, t = _shell(rng, W, H, ps)
        rooms, walls, doors = _split_rooms(rng, (t, t, W - t, H - t), int(rng.integers(4, 10)), 1.8)
        for w in walls:
            canvas.fill(w)
        for d in doors:  # a later wall may end in an earlier doorway: the doorway stays open
            canvas.fill(d, False)
        keep = [_clearance(d) for d in doors]
        for room in rooms:
            _furnish(rng, canvas, room, keep, _FURNITURE, int(rng.integers(0, 5)))
        ins_outs = _openings(rng, canvas, t, int(rng.integers(1, 4)), int(rng.integers(1, 4)))
        if ins_outs is None:
            return None
        return DrawnPlan(name, "house", canvas.solid, ps, *ins_outs, _velocity(rng))

    return _retry(draw, rng, resolution, max_attempts, "house plan")


def draw_office(
    rng_or_seed: RngLike = None,
    *,
    pixel_size: float | None = None,
    size: tuple[float, float] | None = None,
    resolution: float = DEFAULT_RESOLUTION,
    max_attempts: int = 50,
) -> DrawnPlan:
    """An office floor, one corridor with furnished rooms on both sides (module doc).

    Args:
        rng_or_seed: a seed or generator.
        pixel_size: pixel side in m (default: drawn from :data:`PIXEL_SIZES`).
        size: ``(width, height)`` in m (snapped to 0.1 m); default ``W ~ U[14, 24]``,
            ``H ~ U[10, 18]``.
        resolution: the cell size the plan must import at with its openings connected.
        max_attempts: draws before giving up.
    """
    rng, name, ps = _start(rng_or_seed, "office", pixel_size)

    def draw(rng: np.random.Generator) -> DrawnPlan | None:
        if size is None:
            W, H = _snap(rng.uniform(14.0, 24.0)), _snap(rng.uniform(10.0, 18.0))
        else:
            W, H = _snap(size[0]), _snap(size[1])
        canvas, t = _shell(rng, W, H, ps)
        horizontal = W >= H  # the corridor runs along the longer side
        L, D = (W, H) if horizontal else (H, W)
        cw = float(rng.uniform(1.6, 2.4))
        c0 = float(rng.uniform(0.4 * D - cw / 2, 0.6 * D - cw / 2))
        tw = float(rng.uniform(0.1, 0.15))
        rects: list[Rect] = []  # in (along, across) coordinates
        walls: list[Rect] = [(t, c0 - tw, L - t, c0), (t, c0 + cw, L - t, c0 + cw + tw)]
        doors: list[Rect] = []
        for lo, hi, wall_y in ((t, c0 - tw, (c0 - tw, c0)), (c0 + cw + tw, D - t, (c0 + cw, c0 + cw + tw))):
            x = t
            while x < L - t - 0.1:
                wdt = float(rng.uniform(2.5, 5.0))
                x1 = L - t if L - t - (x + wdt) < 2.5 else x + wdt
                rects.append((x, lo, x1, hi))
                dw = float(rng.uniform(0.8, 1.0)) if rng.random() > 0.15 else float(rng.uniform(0.55, 0.65))
                d0 = float(rng.uniform(x + 0.2, x1 - 0.2 - dw))
                doors.append((d0, wall_y[0], d0 + dw, wall_y[1]))
                if x1 < L - t:
                    walls.append((x1, lo, x1 + tw, hi))
                x = x1 + tw

        def orient(r: Rect) -> Rect:
            return r if horizontal else (r[1], r[0], r[3], r[2])

        for w in walls:
            canvas.fill(orient(w))
        for d in doors:
            canvas.fill(orient(d), False)
        keep = [orient(_clearance(d)) for d in doors]
        for r in rects:
            _furnish(rng, canvas, orient(r), keep, _OFFICE_FURNITURE, int(rng.integers(1, 5)))
        n_in, n_out = int(rng.integers(1, 4)), int(rng.integers(1, 4))
        ins_outs = _openings(rng, canvas, t, n_in, n_out)
        if ins_outs is None:
            return None
        return DrawnPlan(name, "office", canvas.solid, ps, *ins_outs, _velocity(rng))

    return _retry(draw, rng, resolution, max_attempts, "office plan")


def draw_plan(kind: str, seed: int, **options) -> DrawnPlan:
    """:func:`draw_house` (``kind="house"``) or :func:`draw_office` (``"office"``) of ``seed``."""
    if kind == "house":
        return draw_house(seed, **options)
    if kind == "office":
        return draw_office(seed, **options)
    raise InputDataError(f"unknown plan kind {kind!r}: use house or office")


def import_plan(png: str | Path, plan: DrawnPlan, resolution: float = DEFAULT_RESOLUTION) -> Layout:
    """The layout ``dgse import-floorplan PNG -r RESOLUTION`` + :meth:`DrawnPlan.import_args` makes."""
    fp = load_png_map(png, resolution, pixel_size=plan.pixel_size)
    return layout_from_floorplan(fp, None, plan.inlets, plan.outlets, name=Path(png).stem)
