"""The one grid type every module uses.

Cell ``(i, j)`` of an ``(H, W)`` map has its centre at
``x = (j + 0.5) * resolution``, ``y = (i + 0.5) * resolution``; row ``i``
grows with ``y`` (plot with ``origin="lower"``).  See spec section 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dgse.errors import InputDataError

DEFAULT_RESOLUTION = 0.1

#: A coordinate within this fraction of a cell of a cell edge lies on that edge, and an edge
#: belongs to the cell above it (to the right of it): a case file keeps its source as float32,
#: which moves a position by up to 6e-8 of its value (6e-5 cells at 100 m on 0.1 m cells), and
#: ``0.3 / 0.1`` is 2.9999999999999996 in float64 but 3.0000001 from float32 0.3, so a plain
#: ``floor`` puts a source on an edge in one cell before saving and in the next one after.
EDGE_TOLERANCE_CELLS = 1e-3


def cell_index(coordinate: float, resolution: float) -> int:
    """The index along one axis of the cell holding ``coordinate`` m on cells of ``resolution`` m.

    ``floor(coordinate / resolution)``, except that a coordinate within
    :data:`EDGE_TOLERANCE_CELLS` of a cell edge is on the edge and in the cell that starts there,
    whatever the rounding of its float32 or float64 value.  The one definition of a point's cell:
    :meth:`Grid.cell_of` (the cell a solver releases a source in, a case's ``source_cell``)
    and every check of a source position use it.
    """
    k = float(coordinate) / float(resolution)
    edge = round(k)
    return int(edge) if abs(k - edge) <= EDGE_TOLERANCE_CELLS else math.floor(k)


@dataclass(frozen=True)
class Grid:
    """A uniform Cartesian grid of ``shape = (H, W)`` cells of side ``resolution`` m.

    Example:
        >>> g = Grid((98, 76))
        >>> g.width_m, g.height_m
        (7.6, 9.8)
        >>> g.cell_of(0.05, 0.15)
        (1, 0)
    """

    shape: tuple[int, int]
    resolution: float = DEFAULT_RESOLUTION

    def __post_init__(self) -> None:
        if len(self.shape) != 2 or min(self.shape) < 1:
            raise InputDataError(f"grid shape must be two positive ints, got {self.shape}")
        object.__setattr__(self, "shape", (int(self.shape[0]), int(self.shape[1])))
        if not (self.resolution > 0 and math.isfinite(self.resolution)):
            raise InputDataError(f"grid resolution must be positive, got {self.resolution}")
        object.__setattr__(self, "resolution", float(self.resolution))

    @classmethod
    def from_size(cls, width_m: float, height_m: float, resolution: float = DEFAULT_RESOLUTION):
        """The grid covering a ``width_m x height_m`` rectangle, snapped to whole cells."""
        return cls((round(height_m / resolution), round(width_m / resolution)), resolution)

    @property
    def height(self) -> int:
        return self.shape[0]

    @property
    def width(self) -> int:
        return self.shape[1]

    @property
    def width_m(self) -> float:
        return round(self.width * self.resolution, 9)

    @property
    def height_m(self) -> float:
        return round(self.height * self.resolution, 9)

    @property
    def x(self) -> np.ndarray:
        """Cell-centre x coordinates, shape ``(W,)``."""
        return (np.arange(self.width) + 0.5) * self.resolution

    @property
    def y(self) -> np.ndarray:
        """Cell-centre y coordinates, shape ``(H,)``."""
        return (np.arange(self.height) + 0.5) * self.resolution

    def meshgrid(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates ``(X, Y)``, each of shape ``(H, W)``."""
        return np.meshgrid(self.x, self.y)

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """The ``(i, j)`` of the cell containing point ``(x, y)`` (:func:`cell_index`); raises if outside."""
        j = cell_index(x, self.resolution)
        i = cell_index(y, self.resolution)
        if not (0 <= i < self.height and 0 <= j < self.width):
            raise InputDataError(
                f"point ({x:.3f}, {y:.3f}) m lies outside the {self.width_m} x {self.height_m} m map"
            )
        return i, j

    def center_of(self, i: int, j: int) -> tuple[float, float]:
        """The ``(x, y)`` centre of cell ``(i, j)`` in metres."""
        return (j + 0.5) * self.resolution, (i + 0.5) * self.resolution

    def centers_of(self, cells: np.ndarray) -> np.ndarray:
        """Centres ``(n, 2)`` as ``(x, y)`` of ``(n, 2)`` integer cells ``(i, j)``."""
        cells = np.asarray(cells)
        return np.stack([(cells[:, 1] + 0.5), (cells[:, 0] + 0.5)], axis=1) * self.resolution

    # -- canvas embedding (network inputs, spec section 6) -------------------------------
    def canvas_shape(self, minimum: int = 100, stride: int = 1) -> tuple[int, int]:
        """Square canvas side: at least ``minimum`` and the map, a multiple of ``stride``."""
        side = max(minimum, self.height, self.width)
        side = int(math.ceil(side / stride) * stride)
        return side, side

    def embed(self, field: np.ndarray, canvas: tuple[int, int], fill: float = 0.0) -> np.ndarray:
        """Place ``field`` (``(..., H, W)``) at the lower-left corner of a ``canvas``."""
        if canvas[0] < self.height or canvas[1] < self.width:
            raise InputDataError(f"canvas {canvas} is smaller than the map {self.shape}")
        out = np.full((*field.shape[:-2], *canvas), fill, dtype=field.dtype)
        out[..., : self.height, : self.width] = field
        return out

    def crop(self, canvas_field: np.ndarray) -> np.ndarray:
        """The map part (``(..., H, W)``) of a canvas-sized field."""
        return canvas_field[..., : self.height, : self.width]

    def valid_mask(self, canvas: tuple[int, int]) -> np.ndarray:
        """Boolean canvas mask, true on the map's cells."""
        return self.embed(np.ones(self.shape, dtype=bool), canvas, fill=False)


# -- integer refinement (a coarse map on a network's finer cells) ------------------------
class OnGrid:
    """What a map derives from its ``occupancy`` (``uint8 (H, W)``, 1 solid, 0 free) and its
    ``resolution`` (m), for the classes that hold both (a case, a layout)."""

    occupancy: np.ndarray
    resolution: float

    @property
    def grid(self) -> Grid:
        """The map's :class:`Grid`."""
        return Grid(self.occupancy.shape, self.resolution)

    @property
    def free(self) -> np.ndarray:
        """Boolean ``(H, W)`` mask of free cells."""
        return self.occupancy == 0


def refinement_factor(resolution: float, target: float) -> int | None:
    """``f`` with ``resolution == f * target`` (``f >= 1`` an integer, to 1e-6), else ``None``."""
    f = float(resolution) / float(target)
    k = round(f)
    if k >= 1 and math.isclose(f, k, rel_tol=1e-6):
        return int(k)
    return None


def refine_occupancy(occupancy: np.ndarray, factor: int) -> np.ndarray:
    """Each cell of ``occupancy`` ``(H, W)`` as a ``factor x factor`` block: ``(f H, f W)``."""
    occ = np.asarray(occupancy)
    return np.kron(occ, np.ones((factor, factor), dtype=occ.dtype))


def refine_cells(cells: np.ndarray, factor: int) -> np.ndarray:
    """The fine cell nearest the centre of each coarse cell ``(i, j)`` (at the centre for odd ``factor``)."""
    return np.asarray(cells, dtype=np.int64) * factor + factor // 2


def coarsen(field: np.ndarray, factor: int, how: str = "mean") -> np.ndarray:
    """Block sums or means (``how``: ``"sum"``, ``"mean"``) of ``(..., f H, f W)``: ``(..., H, W)``."""
    a = np.asarray(field)
    *lead, fh, fw = a.shape
    if fh % factor or fw % factor:
        raise InputDataError(f"a field of {fh} x {fw} cells is not made of {factor} x {factor} blocks")
    blocks = a.reshape(*lead, fh // factor, factor, fw // factor, factor)
    if how == "sum":
        return blocks.sum(axis=(-3, -1))
    if how == "mean":
        return blocks.mean(axis=(-3, -1))
    raise ValueError(f"unknown block reduction {how!r}: use sum or mean")
