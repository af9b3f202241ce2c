"""Real floor plans: ROS ``map_server`` maps and plain images, resampled to the grid.

Reading:

* :func:`load_ros_map` reads a ROS map_server YAML (``image``, ``resolution``,
  ``origin``, ``negate``, ``occupied_thresh``, ``free_thresh``, ``mode``) and its
  PGM/PNG image.  A pixel's occupancy is ``(255 - v) / 255`` (``v / 255`` when
  ``negate``), ``v`` the pixel value (the mean of the colour channels); above
  ``occupied_thresh`` it is occupied, below ``free_thresh`` free, otherwise
  unknown.  Unknown pixels (and fully transparent ones) count as solid.  The
  map is cropped to the bounding box of known (free or occupied) pixels.
* :func:`load_png_map` reads a plain image: dark (grey level below
  ``threshold``) is solid, transparent pixels count as white (free).

Image row 0 is the *top* of the map; our row 0 is the bottom (spec section 1),
so images are flipped vertically.

Resampling (:func:`resample_occupancy`) works on areas: every output cell's
solid fraction is the share of its area covered by solid pixels (or lying
outside the map).  The default rule ``"any"`` makes a cell solid when any
positive part of it is solid, so walls one pixel thin never vanish; walls can
grow by up to one cell.  ``"majority"`` makes it solid when at least half is
solid, ``"all"`` only when all of it is.

:func:`layout_from_floorplan` turns an occupancy map plus user-given inlets and
outlets into a :class:`~dgse.world.layout.Layout`; its ``walls`` are an exact
rectangle cover of the solid cells (:func:`occupancy_rectangles`).

Writing: :func:`export_ros_map` writes a layout's occupancy as a ROS map_server
map (YAML + PGM, one pixel per cell) that :func:`load_ros_map` reads back
exactly.  The map_server format has no inlets or outlets: they are written as
YAML comments only, and an import takes them from the user.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

import numpy as np
from scipy import ndimage, sparse

from dgse.errors import InputDataError
from dgse.files import write_bytes
from dgse.world.grid import DEFAULT_RESOLUTION, Grid
from dgse.world.layout import Layout, Opening

_T = TypeVar("_T")

__all__ = [
    "FloorPlan",
    "export_ros_map",
    "layout_from_floorplan",
    "load_png_map",
    "load_ros_map",
    "occupancy_rectangles",
    "resample_occupancy",
]

_FOUR = ndimage.generate_binary_structure(2, 1)
_RULES = ("any", "majority", "all")
_ROS_MODES = ("trinary", "scale", "raw")


class FloorPlan(NamedTuple):
    """A floor plan on our grid.

    Attributes:
        occupancy: ``uint8 (H, W)``, 1 solid, 0 free; row 0 is the bottom (south).
        origin: ``(x, y)`` in m, in the map's own frame, of the lower-left corner
            of cell ``(0, 0)``: a map point ``(X, Y)`` lies at grid coordinates
            ``(X - origin[0], Y - origin[1])``.
        resolution: cell size in m.
    """

    occupancy: np.ndarray
    origin: tuple[float, float]
    resolution: float

    @property
    def grid(self) -> Grid:
        return Grid(self.occupancy.shape, self.resolution)


# -- resampling ----------------------------------------------------------------------------
def _overlap_matrix(n_out: int, out_size: float, n_in: int, in_size: float) -> sparse.csr_matrix:
    """``(n_out, n_in)`` overlap lengths in m of output cells with input pixels (1-D)."""
    rows, cols, vals = [], [], []
    for p in range(n_in):
        a, b = p * in_size, (p + 1) * in_size
        k0 = max(0, math.floor(a / out_size))
        k1 = min(n_out - 1, math.ceil(b / out_size) - 1)
        for k in range(k0, k1 + 1):
            ov = min(b, (k + 1) * out_size) - max(a, k * out_size)
            if ov > 0:
                rows.append(k)
                cols.append(p)
                vals.append(ov)
    return sparse.csr_matrix((vals, (rows, cols)), shape=(n_out, n_in))


def resample_occupancy(
    solid: np.ndarray,
    pixel_size: float,
    resolution: float = DEFAULT_RESOLUTION,
    rule: str = "any",
) -> np.ndarray:
    """Resample a solid mask of square pixels to cells of ``resolution`` m.

    Args:
        solid: ``(h, w)`` bool (or solid fraction in ``[0, 1]``) per pixel, row 0
            at the bottom; pixel ``(p, q)`` covers ``[q s, (q + 1) s] x [p s, (p + 1) s]``
            with ``s = pixel_size`` m.
        pixel_size: pixel side in m.
        resolution: output cell side in m.
        rule: ``"any"`` (solid if any part of the cell is solid), ``"majority"``
            (at least half) or ``"all"`` (all of it).

    Returns:
        ``uint8 (H, W)`` occupancy with ``H = ceil(h s / resolution)`` (likewise
        ``W``), the grid starting at the lower-left corner of pixel ``(0, 0)``.
        The part of a last row/column beyond the map counts as solid.
    """
    if rule not in _RULES:
        raise InputDataError(f"unknown resampling rule {rule!r}: use one of {', '.join(_RULES)}")
    if not (pixel_size > 0 and resolution > 0):
        raise InputDataError(f"pixel size {pixel_size} and resolution {resolution} must be > 0")
    s = np.asarray(solid, dtype=float)
    if s.ndim != 2 or s.size == 0:
        raise InputDataError(f"floor plan image must be a non-empty 2-D array, got {s.shape}")
    h, w = s.shape
    H = max(1, math.ceil(h * pixel_size / resolution - 1e-6))
    W = max(1, math.ceil(w * pixel_size / resolution - 1e-6))
    Ay = _overlap_matrix(H, resolution, h, pixel_size)
    Ax = _overlap_matrix(W, resolution, w, pixel_size)
    free_area = np.asarray(Ax @ np.asarray(Ay @ (1.0 - s)).T).T  # (H, W) free area, m^2
    frac_solid = 1.0 - free_area / resolution**2
    tol = 1e-6
    if rule == "any":
        out = frac_solid > tol
    elif rule == "majority":
        out = frac_solid >= 0.5 - tol
    else:
        out = frac_solid >= 1.0 - tol
    return out.astype(np.uint8)


# -- image reading -----------------------------------------------------------------------------
def _read_file(
    path: Path, what: str, load: Callable[[Path], _T], errors: tuple[type[Exception], ...], verb: str = "read"
) -> _T:
    """``load(path)``: a missing file, or one that ``load`` fails on with one of ``errors``
    ("cannot VERB WHAT PATH: ..."), is an :class:`~dgse.errors.InputDataError`."""
    if not path.is_file():
        raise InputDataError(f"{what} {path} does not exist")
    try:
        return load(path)
    except InputDataError:
        raise
    except errors as e:
        raise InputDataError(f"cannot {verb} {what} {path}: {e}") from e


def _image_array(path: Path) -> np.ndarray:
    """The pixels of an image file: 8-bit grey+alpha or RGBA ``(h, w, c)``, or a 16/32-bit
    grey ``(h, w)`` scaled to ``[0, 255]``."""
    from PIL import Image

    with Image.open(path) as im:
        im.load()
        mode = im.mode
        if mode in ("I;16", "I;16B", "I;16L", "I"):
            a = np.asarray(im, dtype=np.float64)
            top = 65535.0 if a.max(initial=0) > 255 else 255.0
            return a * (255.0 / top)
        if mode == "P":
            im = im.convert("RGBA")
            mode = "RGBA"
        if mode in ("1", "L", "LA", "RGB", "RGBA"):
            return np.asarray(im.convert("LA" if mode in ("1", "L", "LA") else "RGBA"))
        return np.asarray(im.convert("RGBA"))


def _read_image(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Grey level ``(h, w)`` in ``[0, 255]`` (mean of colour channels) and alpha or None."""
    # PIL raises many kinds (UnidentifiedImageError, OSError, ...)
    a = _read_file(path, "floor plan image", _image_array, (Exception,)).astype(np.float64)
    if a.ndim == 2:
        return a, None
    grey = a[..., :-1].mean(axis=-1)
    alpha = a[..., -1]
    if grey.size == 0:
        raise InputDataError(f"floor plan image {path} is empty")
    return grey, (alpha if (alpha < 255).any() else None)


def _bbox(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    rows = np.nonzero(mask.any(axis=1))[0]
    cols = np.nonzero(mask.any(axis=0))[0]
    if rows.size == 0:
        return None
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _float_key(
    meta: Mapping[str, Any],
    key: str,
    path: Path,
    default: float | None = None,
    lo: float | None = None,
    hi: float | None = None,
) -> float:
    if key not in meta:
        if default is None:
            raise InputDataError(f"map YAML {path} has no {key!r} key")
        return default
    try:
        v = float(meta[key])
    except (TypeError, ValueError):
        raise InputDataError(f"map YAML {path}: {key!r} must be a number, got {meta[key]!r}") from None
    if not math.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
        raise InputDataError(f"map YAML {path}: {key!r} = {v} is out of range [{lo}, {hi}]")
    return v


def _read_ros_yaml(yaml_path: Path) -> dict[str, Any]:
    import yaml

    errors = (yaml.YAMLError, UnicodeDecodeError)
    meta = _read_file(yaml_path, "map YAML", lambda p: yaml.safe_load(p.read_text()), errors, verb="parse")
    if not isinstance(meta, dict):
        raise InputDataError(
            f"map YAML {yaml_path} must be a mapping with image, resolution, origin, ...; "
            f"got {type(meta).__name__}"
        )
    return meta


def load_ros_map(
    yaml_path: str | Path,
    resolution: float = DEFAULT_RESOLUTION,
    *,
    rule: str = "any",
    crop: bool = True,
    unknown_is_solid: bool = True,
) -> FloorPlan:
    """Read a ROS map_server map (YAML + PGM/PNG) onto a grid of ``resolution`` m.

    Args:
        yaml_path: the map's YAML file.  Keys: ``image`` (path, relative to the
            YAML's folder), ``resolution`` (m per pixel), ``origin``
            (``[x, y, yaw]`` of the lower-left pixel, m; a nonzero yaw is ignored
            with a warning) are required; ``negate`` (0), ``occupied_thresh``
            (0.65), ``free_thresh`` (0.196) and ``mode`` (``trinary``; ``scale``
            is read the same way; ``raw`` takes pixel values as occupancy in
            percent, 0-100) default as given.
        resolution: output cell size in m.
        rule: resampling rule, see :func:`resample_occupancy`.
        crop: crop to the bounding box of known (free or occupied) pixels.
        unknown_is_solid: unknown pixels are solid (default); else free.

    Returns:
        :class:`FloorPlan` with ``occupancy`` ``uint8 (H, W)`` (row 0 = bottom),
        ``origin`` the map-frame ``(x, y)`` m of its lower-left corner, and
        ``resolution``.

    Raises:
        InputDataError: missing YAML or image, bad or missing keys, an
            unreadable image, a map with no free space.
    """
    path = Path(yaml_path)
    meta = _read_ros_yaml(path)
    if "image" not in meta or not isinstance(meta["image"], str) or not meta["image"]:
        raise InputDataError(f"map YAML {path} has no 'image' key naming the map image")
    image = Path(meta["image"])
    if not image.is_absolute():
        image = path.parent / image
    pix = _float_key(meta, "resolution", path)
    if pix <= 0:
        raise InputDataError(f"map YAML {path}: 'resolution' must be positive, got {pix}")
    origin = meta.get("origin")
    if origin is None:
        raise InputDataError(f"map YAML {path} has no 'origin' key ([x, y, yaw] in m)")
    try:
        ox, oy, *rest = (float(v) for v in origin)
    except (TypeError, ValueError):
        raise InputDataError(f"map YAML {path}: 'origin' must be [x, y, yaw] in m, got {origin!r}") from None
    if len(rest) > 1 or not all(math.isfinite(v) for v in (ox, oy, *rest)):
        raise InputDataError(f"map YAML {path}: 'origin' must be [x, y, yaw] in m, got {origin!r}")
    if rest and abs(rest[0]) > 1e-9:
        warnings.warn(
            f"map {path}: origin yaw {rest[0]} rad is ignored (the map is used unrotated)",
            stacklevel=2,
        )
    negate = meta.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise InputDataError(f"map YAML {path}: 'negate' must be 0 or 1, got {negate!r}")
    occ_th = _float_key(meta, "occupied_thresh", path, 0.65, 0.0, 1.0)
    free_th = _float_key(meta, "free_thresh", path, 0.196, 0.0, 1.0)
    if free_th > occ_th:
        raise InputDataError(f"map YAML {path}: free_thresh {free_th} is above occupied_thresh {occ_th}")
    mode = str(meta.get("mode", "trinary")).lower()
    if mode not in _ROS_MODES:
        raise InputDataError(
            f"map YAML {path}: unknown mode {meta.get('mode')!r} (use {', '.join(_ROS_MODES)})"
        )

    grey, alpha = _read_image(image)
    if negate:
        grey = 255.0 - grey
    if mode == "raw":
        v = np.rint(grey)
        known = v <= 100
        p = np.where(known, v / 100.0, 0.5)
    else:
        p = (255.0 - grey) / 255.0
        known = np.ones(p.shape, dtype=bool)
    occupied = known & (p > occ_th)
    free = known & (p < free_th)
    if alpha is not None:
        occupied &= alpha > 0
        free &= alpha > 0
    occupied, free = np.flipud(occupied), np.flipud(free)  # row 0 = bottom
    if not free.any():
        raise InputDataError(f"map {path} has no free space (image {image})")
    r0, c0 = 0, 0
    if crop:
        r0, r1, c0, c1 = _bbox(occupied | free)  # type: ignore[misc]
        occupied, free = occupied[r0:r1, c0:c1], free[r0:r1, c0:c1]
    solid = ~free if unknown_is_solid else occupied
    occ = resample_occupancy(solid, pix, resolution, rule)
    if not (occ == 0).any():
        raise InputDataError(
            f"map {path} has no free cell at {resolution} m with rule {rule!r} "
            "(free space narrower than a cell?)"
        )
    return FloorPlan(occ, (round(ox + c0 * pix, 9), round(oy + r0 * pix, 9)), float(resolution))


def load_png_map(
    path: str | Path,
    resolution: float = DEFAULT_RESOLUTION,
    *,
    pixel_size: float | None = None,
    width_m: float | None = None,
    threshold: float = 0.5,
    rule: str = "any",
) -> FloorPlan:
    """Read a plain floor plan image (PNG, PGM, ...): dark is solid.

    Args:
        path: the image; grey level (mean of the colour channels, transparent
            pixels count as white) below ``threshold * 255`` is solid.
        resolution: output cell size in m.
        pixel_size: pixel side in m; or
        width_m: the image's width in m (pixel size = ``width_m / image width``).
            Give at most one; with neither, one pixel is one cell.
        threshold: grey-level fraction below which a pixel is solid.
        rule: resampling rule, see :func:`resample_occupancy`.

    Returns:
        :class:`FloorPlan` (row 0 = bottom of the image, origin ``(0, 0)``).
    """
    if pixel_size is not None and width_m is not None:
        raise InputDataError("give pixel_size or width_m, not both")
    if not 0.0 < threshold <= 1.0:
        raise InputDataError(f"threshold must be in (0, 1], got {threshold}")
    p = Path(path)
    grey, alpha = _read_image(p)
    if alpha is not None:  # composite over white
        grey = grey * (alpha / 255.0) + 255.0 * (1.0 - alpha / 255.0)
    if width_m is not None:
        if not width_m > 0:
            raise InputDataError(f"width_m must be positive, got {width_m}")
        pixel_size = width_m / grey.shape[1]
    if pixel_size is None:
        pixel_size = resolution
    if not pixel_size > 0:
        raise InputDataError(f"pixel_size must be positive, got {pixel_size}")
    solid = np.flipud(grey < threshold * 255.0)
    if solid.all():
        raise InputDataError(f"floor plan image {p} has no free (light) pixel")
    occ = resample_occupancy(solid, float(pixel_size), resolution, rule)
    if not (occ == 0).any():
        raise InputDataError(f"floor plan image {p} has no free cell at {resolution} m")
    return FloorPlan(occ, (0.0, 0.0), float(resolution))


# -- layouts --------------------------------------------------------------------------------
def occupancy_rectangles(occupancy: np.ndarray) -> list[tuple[int, int, int, int]]:
    """An exact cover of the solid cells by disjoint rectangles ``(r0, r1, c0, c1)``.

    Horizontal runs of solid cells are merged with identical runs in the rows
    above (half-open row/column ranges).
    """
    occ = np.asarray(occupancy) != 0
    H, _ = occ.shape
    active: dict[tuple[int, int], int] = {}
    out: list[tuple[int, int, int, int]] = []
    for i in range(H + 1):
        runs: set[tuple[int, int]] = set()
        if i < H:
            d = np.diff(np.concatenate([[0], occ[i].astype(np.int8), [0]]))
            runs = set(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist(), strict=True))
        for run in [r for r in active if r not in runs]:
            out.append((active.pop(run), i, run[0], run[1]))
        for run in runs:
            active.setdefault(run, i)
    return sorted(out)


def _as_openings(items: Opening | Mapping | Iterable, kind: str) -> tuple[Opening, ...]:
    if isinstance(items, Opening | Mapping):
        items = [items]
    out = []
    for k, o in enumerate(items):
        if isinstance(o, Opening):
            out.append(o)
        elif isinstance(o, Mapping):
            out.append(Opening.from_dict(dict(o)))
        elif isinstance(o, list | tuple) and len(o) == 3:
            out.append(Opening(str(o[0]), float(o[1]), float(o[2])))
        else:
            raise InputDataError(
                f"{kind} {k}: {o!r} is not an Opening, a dict with side, start_m and end_m "
                "or a (side, start_m, end_m) tuple"
            )
    if not out:
        raise InputDataError(f"a floor plan layout needs at least one {kind}")
    return tuple(out)


def _carve(occ: np.ndarray, grid: Grid, o: Opening, depth: int) -> None:
    """Clear solid cells under ``o`` from the boundary inward up to the first free cell.

    Only where a free cell lies within ``depth`` cells of the boundary.
    """
    rows, cols = o.cells(grid)
    di, dj = {"west": (0, 1), "east": (0, -1), "south": (1, 0), "north": (-1, 0)}[o.side]
    H, W = occ.shape
    for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
        for d in range(depth + 1):
            i, j = r + d * di, c + d * dj
            if not (0 <= i < H and 0 <= j < W):
                break
            if occ[i, j] == 0:
                for e in range(d):
                    occ[r + e * di, c + e * dj] = 0
                break


def layout_from_floorplan(
    occupancy: np.ndarray | FloorPlan,
    resolution: float | None,
    inlets: Opening | Mapping | Iterable,
    outlets: Opening | Mapping | Iterable,
    name: str = "floorplan",
    *,
    carve_depth_m: float = 0.0,
    fill_unreachable: bool = True,
) -> Layout:
    """A :class:`Layout` from a floor plan's occupancy and user-given openings.

    Args:
        occupancy: ``(H, W)`` 0/1 (row 0 = bottom) or a :class:`FloorPlan`.
        resolution: cell size in m (``None``: the FloorPlan's).
        inlets, outlets: :class:`Opening` objects, dicts ``{side, start_m, end_m}``
            or ``(side, start_m, end_m)`` tuples (one or a list), in the grid's
            frame (m from the lower-left corner of the map, not the ROS origin).
        name: the layout's name.
        carve_depth_m: when > 0, cut each opening through solid boundary cells
            (an outer wall) up to this depth where free space lies behind.
        fill_unreachable: make free cells that no opening can reach solid.  Every
            remaining free region must then hold an inlet and an outlet.

    Returns:
        The layout; ``walls`` is an exact rectangle cover of the solid cells.

    Raises:
        InputDataError: openings outside their side or touching no free cell,
            an inlet region without outlet (or vice versa), no free cell.
    """
    if isinstance(occupancy, FloorPlan):
        resolution = occupancy.resolution if resolution is None else resolution
        occupancy = occupancy.occupancy
    if resolution is None:
        raise InputDataError("resolution is needed for a bare occupancy array")
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or occ.size == 0:
        raise InputDataError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
    if not np.isin(occ, (0, 1)).all():
        raise InputDataError("occupancy must contain only 0 (free) and 1 (solid)")
    occ = occ.astype(np.uint8).copy()
    grid = Grid(occ.shape, resolution)
    ins = _as_openings(inlets, "inlet")
    outs = _as_openings(outlets, "outlet")
    depth = math.floor(carve_depth_m / grid.resolution + 1e-9) if carve_depth_m > 0 else 0
    for kind, group in (("inlet", ins), ("outlet", outs)):
        for o in group:
            length = grid.width_m if o.side in ("south", "north") else grid.height_m
            if o.start_m < -1e-9 or o.end_m > length + 1e-9:
                raise InputDataError(f"{o.describe(kind)} runs outside the {o.side} side (0 to {length:g} m)")
            rows, cols = o.cells(grid)
            if rows.size == 0:
                raise InputDataError(
                    f"{o.describe(kind)} covers no cell centre: make it at least one "
                    f"cell ({grid.resolution:g} m) long"
                )
            if depth:
                _carve(occ, grid, o, depth)
            if not (occ[rows, cols] == 0).any():
                hint = (
                    "; give {carve_depth_m} (e.g. 0.5 m) to cut it through an outer wall"
                    if not depth
                    else f" even after carving {carve_depth_m:g} m deep"
                )
                raise InputDataError(
                    f"{o.describe(kind)} touches no free cell: every boundary cell under it is solid{hint}",
                    names={"carve_depth_m": "carve_depth_m"},
                )
    if fill_unreachable:
        labels, _ = ndimage.label(occ == 0, structure=_FOUR)

        def comps(group: tuple[Opening, ...]) -> set[int]:
            s: set[int] = set()
            for o in group:
                r, c = o.cells(grid)
                s.update(int(v) for v in labels[r, c] if v)
            return s

        cin, cout = comps(ins), comps(outs)
        if cin - cout:
            raise InputDataError(
                "an inlet opens into a free region that no outlet reaches "
                f"(regions {sorted(cin - cout)} of the floor plan)"
            )
        if cout - cin:
            raise InputDataError(
                "an outlet opens into a free region that no inlet reaches "
                f"(regions {sorted(cout - cin)} of the floor plan)"
            )
        keep = np.isin(labels, sorted(cin))
        occ[(occ == 0) & ~keep] = 1
    r = grid.resolution
    walls = tuple(
        (round(c0 * r, 9), round(r0 * r, 9), round(c1 * r, 9), round(r1 * r, 9))
        for r0, r1, c0, c1 in occupancy_rectangles(occ)
    )
    return Layout(occ, ins, outs, r, walls, name)


# -- writing ----------------------------------------------------------------------------------
#: Pixel values of an exported ROS map (the map_server conventions: dark is occupied).
ROS_FREE, ROS_OCCUPIED = 254, 0


def _opening_args(layout: Layout) -> list[str]:
    def fmt(o: Opening) -> str:
        return f"{o.side} {o.start_m:g} {o.end_m:g}"

    return [
        f"# inlets:  {'; '.join(fmt(o) for o in layout.inlets)}",
        f"# outlets: {'; '.join(fmt(o) for o in layout.outlets)}",
    ]


def export_ros_map(
    layout: Layout, path: str | Path, origin: tuple[float, float] = (0.0, 0.0)
) -> tuple[Path, Path]:
    """Write ``layout``'s occupancy as a ROS map_server map: ``<stem>.yaml`` and ``<stem>.pgm``.

    The image has one pixel per cell (the YAML's ``resolution`` is the layout's,
    in m), image row 0 the layout's top (north) row; free cells are 254 and solid
    ones 0 (``mode: trinary``, ``negate: 0``, ``occupied_thresh: 0.65``,
    ``free_thresh: 0.196``); the YAML's ``origin`` is ``[x, y, 0.0]`` of ``origin``, the
    map-frame position of the layout's lower-left corner (default: the map frame's origin
    there).  :func:`load_ros_map` at the layout's resolution gives back the occupancy cell
    for cell.

    The format has no place for inlets and outlets: they are written as YAML
    comments (``# inlets: west 1.2 2.3; ...``), which readers ignore; give them
    to :func:`layout_from_floorplan` (or ``dgse import-floorplan --inlet/--outlet``)
    on import.

    Args:
        layout: the layout to write.
        path: the YAML path (``.yaml``/``.yml``), the image path (``.pgm``) or
            a stem; the image is written beside the YAML and named by it.
        origin: map-frame ``(x, y)`` of the layout's lower-left corner, m.

    Returns:
        ``(yaml_path, pgm_path)``.
    """
    path = Path(path)
    stem = path.with_suffix("") if path.suffix.lower() in (".yaml", ".yml", ".pgm") else path
    yaml_path = path if path.suffix.lower() in (".yaml", ".yml") else stem.with_name(stem.name + ".yaml")
    pgm_path = stem.with_name(stem.name + ".pgm")
    occ = np.flipud(layout.occupancy)  # image row 0 = north
    pixels = np.where(occ == 1, ROS_OCCUPIED, ROS_FREE).astype(np.uint8)
    H, W = pixels.shape
    g = layout.grid
    lines = [
        f"# {layout.name}: {g.width_m:g} x {g.height_m:g} m, {W} x {H} cells, written by dgse",
        "# ROS map_server maps carry no openings; these are the layout's (m along each side,",
        "# from the lower-left corner), for dgse import-floorplan --inlet/--outlet SIDE START END:",
        *_opening_args(layout),
        f"image: {pgm_path.name}",
        f"resolution: {float(layout.resolution)!r}",
        f"origin: [{float(origin[0])!r}, {float(origin[1])!r}, 0.0]",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
        "mode: trinary",
    ]
    yaml_path.parent.mkdir(parents=True, exist_ok=True)
    for target, data in (
        (pgm_path, f"P5\n{W} {H}\n255\n".encode("ascii") + pixels.tobytes()),
        (yaml_path, ("\n".join(lines) + "\n").encode("utf-8")),
    ):
        write_bytes(target, data)
    return yaml_path, pgm_path
