"""Layouts: the occupancy map plus the openings the air comes in and out through."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dgse.errors import InputDataError
from dgse.world.grid import DEFAULT_RESOLUTION, Grid, OnGrid

SIDES = ("west", "east", "south", "north")
_SIDE_ALIASES = {"left": "west", "right": "east", "bottom": "south", "top": "north"}
#: Inward unit normal ``(n_x, n_y)`` of each side.
INWARD_NORMAL = {"west": (1.0, 0.0), "east": (-1.0, 0.0), "south": (0.0, 1.0), "north": (0.0, -1.0)}


def canonical_side(side: str) -> str:
    """``west``/``east``/``south``/``north`` for a side name or its alias (left, right, ...)."""
    s = str(side).lower()
    s = _SIDE_ALIASES.get(s, s)
    if s not in SIDES:
        raise InputDataError(f"unknown boundary side {side!r}: use one of {', '.join(SIDES)}")
    return s


@dataclass(frozen=True)
class Opening:
    """A segment ``[start_m, end_m]`` of the outer boundary along ``side``.

    ``start_m``/``end_m`` run along x for south/north and along y for west/east.
    """

    side: str
    start_m: float
    end_m: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "side", canonical_side(self.side))
        if not self.end_m > self.start_m:
            raise InputDataError(f"opening on {self.side} has end {self.end_m} <= start {self.start_m}")

    @property
    def width_m(self) -> float:
        return float(self.end_m - self.start_m)

    def cells(self, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns of the boundary cells whose outer face lies in the opening."""
        r = grid.resolution
        n_along = grid.width if self.side in ("south", "north") else grid.height
        centers = (np.arange(n_along) + 0.5) * r
        along = np.nonzero((centers > self.start_m) & (centers < self.end_m))[0]
        if self.side == "west":
            return along, np.zeros_like(along)
        if self.side == "east":
            return along, np.full_like(along, grid.width - 1)
        if self.side == "south":
            return np.zeros_like(along), along
        return np.full_like(along, grid.height - 1), along

    def describe(self, kind: str = "opening") -> str:
        """``the west inlet at 0-0.1 m`` (``kind``: inlet, outlet or opening), for messages."""
        return f"the {self.side} {kind} at {self.start_m:g}-{self.end_m:g} m"

    def to_dict(self) -> dict:
        return {"side": self.side, "start_m": float(self.start_m), "end_m": float(self.end_m)}

    @classmethod
    def from_dict(cls, d: dict) -> Opening:
        try:
            return cls(d["side"], float(d["start_m"]), float(d["end_m"]))
        except (KeyError, TypeError, ValueError) as e:
            raise InputDataError(f"bad opening {d!r}: needs side, start_m, end_m ({e})") from e


@dataclass(frozen=True)
class Layout(OnGrid):
    """An indoor layout: occupancy (1 solid, 0 free) on a grid, inlets and outlets.

    ``walls`` are the generating rectangles ``(x0, y0, x1, y1)`` in metres, kept
    for the case file's ``meta``; the occupancy is what the physics uses.
    """

    occupancy: np.ndarray
    inlets: tuple[Opening, ...]
    outlets: tuple[Opening, ...]
    resolution: float = DEFAULT_RESOLUTION
    walls: tuple[tuple[float, float, float, float], ...] = field(default_factory=tuple)
    name: str = "layout"

    def __post_init__(self) -> None:
        occ = np.asarray(self.occupancy)
        if occ.ndim != 2:
            raise InputDataError(f"occupancy must be 2-D, got shape {occ.shape}")
        if occ.size and not np.isin(occ, (0, 1)).all():
            raise InputDataError("occupancy must contain only 0 (free) and 1 (solid)")
        object.__setattr__(self, "occupancy", occ.astype(np.uint8))
        object.__setattr__(self, "inlets", tuple(self.inlets))
        object.__setattr__(self, "outlets", tuple(self.outlets))
        object.__setattr__(self, "walls", tuple(tuple(map(float, w)) for w in self.walls))
        if not self.inlets or not self.outlets:
            raise InputDataError("a layout needs at least one inlet and one outlet")
        for kind, o in [("inlet", o) for o in self.inlets] + [("outlet", o) for o in self.outlets]:
            length = self.grid.width_m if o.side in ("south", "north") else self.grid.height_m
            if o.start_m < -1e-9 or o.end_m > length + 1e-9:
                raise InputDataError(f"{o.describe(kind)} runs outside the {o.side} side (0 to {length:g} m)")
            rows, cols = o.cells(self.grid)
            if rows.size == 0 or not (self.occupancy[rows, cols] == 0).any():
                raise InputDataError(f"{o.describe(kind)} touches no free cell")
        if not (self.occupancy == 0).any():
            raise InputDataError("layout has no free cell")

    def opening_mask(self, kind: str) -> np.ndarray:
        """Boolean ``(H, W)`` mask of free boundary cells that touch an inlet or outlet."""
        mask = np.zeros(self.occupancy.shape, dtype=bool)
        for o in self.inlets if kind == "inlet" else self.outlets:
            rows, cols = o.cells(self.grid)
            mask[rows, cols] = True
        return mask & self.free

    def meta(self) -> dict:
        """The layout's part of a case file's ``meta``."""
        g = self.grid
        d: dict = {"width_m": g.width_m, "height_m": g.height_m, "resolution": g.resolution}
        if len(self.inlets) == 1 and len(self.outlets) == 1:
            d["inlet"] = self.inlets[0].to_dict()
            d["outlet"] = self.outlets[0].to_dict()
        else:
            d["inlets"] = [o.to_dict() for o in self.inlets]
            d["outlets"] = [o.to_dict() for o in self.outlets]
        d["walls"] = [list(w) for w in self.walls]
        return d

    @classmethod
    def from_meta(cls, occupancy: np.ndarray, meta: dict, name: str = "layout") -> Layout:
        """The layout described by a case's occupancy and ``meta``."""
        res = float(meta.get("resolution", DEFAULT_RESOLUTION))
        try:
            lists = {k: meta[k + "s"] if k + "s" in meta else [meta[k]] for k in ("inlet", "outlet")}
            inlets = [Opening.from_dict(d) for d in lists["inlet"]]
            outlets = [Opening.from_dict(d) for d in lists["outlet"]]
        except KeyError as e:
            raise InputDataError(f"meta has no {e.args[0]!r} (nor a list of them)") from None
        walls = [tuple(w) for w in meta.get("walls", [])]
        return cls(occupancy, tuple(inlets), tuple(outlets), res, tuple(walls), name)


def rasterize_walls(grid: Grid, walls) -> np.ndarray:
    """Occupancy ``(H, W)`` with every cell whose centre lies in a wall rectangle solid."""
    occ = np.zeros(grid.shape, dtype=np.uint8)
    X, Y = grid.meshgrid()
    for x0, y0, x1, y1 in walls:
        occ[(X > min(x0, x1)) & (X < max(x0, x1)) & (Y > min(y0, y1)) & (Y < max(y0, y1))] = 1
    return occ
