"""Network inputs and targets on a fixed square canvas (spec section 6, paper Sec. IV).

A map of ``(H, W)`` cells is embedded at the lower-left corner of a canvas
(rows ``0..H-1``, columns ``0..W-1``; row ``i`` along y, column ``j`` along x,
as everywhere in DGSE).  Canvas size (:func:`canvas_shape_for`): the paper's
``100 x 100`` for every map that fits in it; a larger map gets a square canvas
whose side is the map's larger side rounded up to a multiple of the network
stride (default 16): ``102 x 102 -> 112``, ``150 x 50 -> 160``.  The 100 canvas
is kept as the paper's even though 100 is not a multiple of 16; a network
that needs a multiple of its stride pads it itself (or pass ``minimum=112``).

Input channels of :func:`rasterize` (``float32 (5, S, S)``):

====  ==================  ====================================================
ch    name                value
====  ==================  ====================================================
0     gas                 ``log(z + 1)`` (``z`` in ppm) at observed cells, -1 elsewhere
1     wind x              ``u_x`` reading (m/s) at observed cells, 0 elsewhere
2     wind y              ``u_y`` reading (m/s) at observed cells, 0 elsewhere
3     occupancy           1 solid, 0 free; 1 on the padded canvas area (outside
                          the map counts as solid)
4     valid               1 on the map's cells (walls included), 0 on the padding
====  ==================  ====================================================

Several readings at the same cell (a robot passing twice) are averaged: the
raw gas readings in ppm are averaged before the log, the wind readings
component-wise.

Targets (:func:`targets`): the true wind ``(2, S, S)``, ``log(c + 1)`` ``(S, S)``,
a one-hot source map ``(S, S)`` and its flat index, and the valid mask; every
target is 0 on the padding.  Losses and metrics use valid cells only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgse.errors import InputDataError
from dgse.sensing.sensors import Observations, check_sensor_cells
from dgse.world.case import Case
from dgse.world.grid import Grid

__all__ = [
    "CHANNELS",
    "CH_GAS",
    "CH_OCCUPANCY",
    "CH_VALID",
    "CH_WIND_X",
    "CH_WIND_Y",
    "DEFAULT_CANVAS",
    "DEFAULT_STRIDE",
    "N_CHANNELS",
    "UNOBSERVED_GAS",
    "Sample",
    "Targets",
    "canvas_shape_for",
    "cell_to_index",
    "crop",
    "crop_posterior",
    "index_to_cell",
    "log_to_ppm",
    "make_sample",
    "ppm_to_log",
    "rasterize",
    "targets",
]

CH_GAS, CH_WIND_X, CH_WIND_Y, CH_OCCUPANCY, CH_VALID = range(5)
CHANNELS = ("gas", "wind_x", "wind_y", "occupancy", "valid")
N_CHANNELS = len(CHANNELS)
#: Gas channel value at cells without a sensor.
UNOBSERVED_GAS = -1.0
#: The paper's canvas side for the training distribution (maps up to 10 x 10 m).
DEFAULT_CANVAS = 100
#: Default total down-sampling factor of the U-Net; larger canvases are multiples of it.
DEFAULT_STRIDE = 16


def canvas_shape_for(
    map_shape: tuple[int, int], minimum: int = DEFAULT_CANVAS, stride: int = DEFAULT_STRIDE
) -> tuple[int, int]:
    """The square canvas ``(S, S)`` for a map of ``map_shape = (H, W)`` cells.

    ``(minimum, minimum)`` when the map fits in it, else
    ``Grid.canvas_shape(minimum, stride)``: the larger side rounded up to a
    multiple of ``stride``.

    Example:
        >>> canvas_shape_for((100, 100)), canvas_shape_for((102, 102)), canvas_shape_for((50, 150))
        ((100, 100), (112, 112), (160, 160))
    """
    H, W = int(map_shape[0]), int(map_shape[1])
    if stride < 1 or minimum < 1:
        raise InputDataError(f"canvas minimum and stride must be >= 1, got {minimum}, {stride}")
    if max(H, W) <= minimum:
        return int(minimum), int(minimum)
    return Grid((H, W)).canvas_shape(minimum, stride)


def ppm_to_log(c: np.ndarray) -> np.ndarray:
    """``log(c + 1)`` of a concentration in ppm (the network's gas scale)."""
    return np.log1p(c)


def log_to_ppm(z: np.ndarray) -> np.ndarray:
    """Inverse of :func:`ppm_to_log`: ``exp(z) - 1`` in ppm."""
    return np.expm1(z)


def _grid_for(occupancy: np.ndarray, canvas_shape: tuple[int, int]) -> Grid:
    occ = np.asarray(occupancy)
    if occ.ndim != 2:
        raise InputDataError(f"occupancy must be 2-D, got shape {occ.shape}")
    g = Grid(occ.shape)
    canvas = (int(canvas_shape[0]), int(canvas_shape[1]))
    if canvas[0] < g.height or canvas[1] < g.width:
        raise InputDataError(f"canvas {canvas} is smaller than the map {g.shape}")
    return g


def rasterize(occupancy: np.ndarray, obs: Observations, canvas_shape: tuple[int, int]) -> np.ndarray:
    """The five-channel network input (see the module docstring for the channels).

    Args:
        occupancy: ``(H, W)`` map, 1 solid, 0 free.
        obs: observations at free cells of that map; repeated cells are averaged.
        canvas_shape: ``(S_h, S_w)`` canvas, at least the map (usually
            :func:`canvas_shape_for`).

    Returns:
        ``float32 (5, S_h, S_w)``.

    Raises:
        InputDataError: an observation outside the map or in a wall, or a
            canvas smaller than the map.
    """
    g = _grid_for(occupancy, canvas_shape)
    occ = np.asarray(occupancy)
    S = (int(canvas_shape[0]), int(canvas_shape[1]))
    cells = check_sensor_cells(occ, obs.cells)
    x = np.zeros((N_CHANNELS, *S), dtype=np.float32)
    x[CH_GAS] = UNOBSERVED_GAS
    x[CH_OCCUPANCY] = 1.0
    x[CH_OCCUPANCY, : g.height, : g.width] = occ != 0
    x[CH_VALID, : g.height, : g.width] = 1.0
    if len(cells):
        flat = cells[:, 0] * S[1] + cells[:, 1]
        uniq, inv, count = np.unique(flat, return_inverse=True, return_counts=True)
        gas = np.bincount(inv, weights=obs.gas, minlength=uniq.size) / count
        wx = np.bincount(inv, weights=obs.wind[:, 0], minlength=uniq.size) / count
        wy = np.bincount(inv, weights=obs.wind[:, 1], minlength=uniq.size) / count
        x[CH_GAS].flat[uniq] = ppm_to_log(np.maximum(gas, 0.0))
        x[CH_WIND_X].flat[uniq] = wx
        x[CH_WIND_Y].flat[uniq] = wy
    return x


@dataclass(frozen=True, eq=False)
class Targets:
    """Training targets on the canvas (0 on the padding).

    Attributes:
        wind: ``float32 (2, S_h, S_w)`` true ``[u_x, u_y]`` in m/s.
        log_concentration: ``float32 (S_h, S_w)`` ``log(c + 1)``, ``c`` in ppm.
        source: ``float32 (S_h, S_w)`` one-hot map of the source cell.
        source_index: flat canvas index ``i * S_w + j`` of the source cell.
        valid: ``bool (S_h, S_w)``, true on the map's cells.
    """

    wind: np.ndarray
    log_concentration: np.ndarray
    source: np.ndarray
    source_index: int
    valid: np.ndarray

    @property
    def canvas_shape(self) -> tuple[int, int]:
        return (int(self.valid.shape[0]), int(self.valid.shape[1]))

    @property
    def source_cell(self) -> tuple[int, int]:
        """``(i, j)`` of the source cell (same on the canvas and on the map)."""
        return index_to_cell(self.source_index, self.canvas_shape)


def targets(case: Case, canvas_shape: tuple[int, int]) -> Targets:
    """The targets of ``case`` on a canvas of ``canvas_shape`` (see :class:`Targets`)."""
    g = _grid_for(case.occupancy, canvas_shape)
    S = (int(canvas_shape[0]), int(canvas_shape[1]))
    wind = g.embed(case.wind.astype(np.float32), S, fill=0.0)
    logc = g.embed(ppm_to_log(case.concentration.astype(np.float32)), S, fill=0.0)
    i, j = case.source_cell
    src = np.zeros(S, dtype=np.float32)
    src[i, j] = 1.0
    return Targets(wind, logc, src, cell_to_index((i, j), S), g.valid_mask(S))


@dataclass(frozen=True, eq=False)
class Sample:
    """One training pair: input, targets and the map's shape on the canvas.

    Attributes:
        inputs: ``float32 (5, S, S)`` from :func:`rasterize`.
        targets: :class:`Targets` on the same canvas.
        map_shape: ``(H, W)`` of the map at the canvas' lower-left corner.
    """

    inputs: np.ndarray
    targets: Targets
    map_shape: tuple[int, int]

    @property
    def canvas_shape(self) -> tuple[int, int]:
        return (int(self.inputs.shape[-2]), int(self.inputs.shape[-1]))


def make_sample(
    case: Case,
    obs: Observations,
    canvas_shape: tuple[int, int] | None = None,
    stride: int = DEFAULT_STRIDE,
) -> Sample:
    """Input and targets of ``case`` observed by ``obs``.

    ``canvas_shape`` defaults to :func:`canvas_shape_for` ``(case map, stride=stride)``.
    """
    S = canvas_shape or canvas_shape_for(case.occupancy.shape, stride=stride)
    return Sample(rasterize(case.occupancy, obs, S), targets(case, S), case.occupancy.shape)


# -- back from the canvas to the map ----------------------------------------------------
def crop(canvas_field: np.ndarray, map_shape: tuple[int, int]) -> np.ndarray:
    """The map part ``(..., H, W)`` of a canvas field ``(..., S_h, S_w)`` (a view)."""
    H, W = int(map_shape[0]), int(map_shape[1])
    if canvas_field.shape[-2] < H or canvas_field.shape[-1] < W:
        raise InputDataError(f"field {canvas_field.shape} is smaller than the map {(H, W)}")
    return canvas_field[..., :H, :W]


def crop_posterior(prob: np.ndarray, map_shape: tuple[int, int], renormalize: bool = True) -> np.ndarray:
    """A source posterior ``(..., S_h, S_w)`` cropped to the map ``(..., H, W)``.

    With ``renormalize`` the cropped probabilities are rescaled to sum to 1
    over the map (mass a network put on the padding is dropped).
    """
    p = np.array(crop(prob, map_shape), dtype=np.float64)
    if renormalize:
        total = p.sum(axis=(-2, -1), keepdims=True)
        if np.any(total <= 0):
            raise InputDataError("source posterior has no mass on the map")
        p = p / total
    return p


def cell_to_index(cell: tuple[int, int], canvas_shape: tuple[int, int]) -> int:
    """Flat canvas index ``i * S_w + j`` of cell ``(i, j)``."""
    i, j = int(cell[0]), int(cell[1])
    if not (0 <= i < canvas_shape[0] and 0 <= j < canvas_shape[1]):
        raise InputDataError(f"cell ({i}, {j}) lies outside the canvas {tuple(canvas_shape)}")
    return i * int(canvas_shape[1]) + j


def index_to_cell(index: int, canvas_shape: tuple[int, int]) -> tuple[int, int]:
    """Cell ``(i, j)`` of a flat canvas index (inverse of :func:`cell_to_index`)."""
    index = int(index)
    if not (0 <= index < canvas_shape[0] * canvas_shape[1]):
        raise InputDataError(f"index {index} lies outside the canvas {tuple(canvas_shape)}")
    return divmod(index, int(canvas_shape[1]))
