"""A case: one steady scenario (layout, inlet/outlet, one source) and its file.

The interchange file ``<name>.npz`` of spec section 2 is read and written
losslessly by :meth:`Case.load` and :meth:`Case.save`; loading validates
shapes, dtypes, units and the source position and raises
:class:`~dgse.errors.CaseFileError` naming the problem.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from dgse.errors import CaseFileError, InputDataError
from dgse.files import atomic_open
from dgse.world.grid import OnGrid, cell_index
from dgse.world.layout import Layout

REQUIRED_KEYS = ("occupancy", "wind", "concentration", "source", "resolution", "meta")


@dataclass(frozen=True, eq=False)
class Case(OnGrid):
    """One steady scenario.

    Attributes:
        occupancy: ``uint8 (H, W)``, 1 solid, 0 free.
        wind: ``float32 (2, H, W)``, ``[u_x, u_y]`` in m/s, 0 in solid.
        concentration: ``float32 (H, W)`` steady concentration in ppm, 0 in solid.
        source: ``float32 (2,)`` source position ``(x, y)`` in m.
        resolution: cell size in m.
        meta: JSON-able dict (width_m, height_m, inlet/outlet, inlet_velocity,
            release_rate_gps, walls, solver, timings, ...).
        frames: optional ``float32 (T, H, W)`` time-varying concentration (ppm),
            ``meta["frame_dt"]`` seconds apart.
    """

    occupancy: np.ndarray
    wind: np.ndarray
    concentration: np.ndarray
    source: np.ndarray
    resolution: float
    meta: dict = field(default_factory=dict)
    frames: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "occupancy", np.asarray(self.occupancy).astype(np.uint8))
        object.__setattr__(self, "wind", np.asarray(self.wind, dtype=np.float32))
        object.__setattr__(self, "concentration", np.asarray(self.concentration, dtype=np.float32))
        object.__setattr__(self, "source", np.asarray(self.source, dtype=np.float32).reshape(-1))
        # stored as float32: keep the decimal value it stands for (0.1, not 0.100000001)
        object.__setattr__(self, "resolution", float(f"{float(self.resolution):.7g}"))
        if self.frames is not None:
            object.__setattr__(self, "frames", np.asarray(self.frames, dtype=np.float32))
        problems = validate_arrays(
            self.occupancy,
            self.wind,
            self.concentration,
            self.source,
            self.resolution,
            self.meta,
            self.frames,
        )
        if problems:
            raise InputDataError("invalid case: " + "; ".join(problems))

    # -- derived views ------------------------------------------------------------------
    @property
    def name(self) -> str:
        return str(self.meta.get("name", "case"))

    @property
    def source_cell(self) -> tuple[int, int]:
        """``(i, j)`` of the source cell."""
        return self.grid.cell_of(float(self.source[0]), float(self.source[1]))

    @property
    def inlet_velocity(self) -> float:
        return float(self.meta["inlet_velocity"])

    @property
    def release_rate(self) -> float:
        """Release rate in g/s."""
        return float(self.meta["release_rate_gps"])

    @property
    def layout(self) -> Layout:
        return Layout.from_meta(self.occupancy, self.meta, name=self.name)

    def with_meta(self, **updates) -> Case:
        return replace(self, meta={**self.meta, **updates})

    # -- file I/O -----------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the case file (compressed ``.npz``); returns the path written."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz") if path.suffix else path.with_suffix(".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {
            "occupancy": self.occupancy,
            "wind": self.wind,
            "concentration": self.concentration,
            "source": self.source,
            "resolution": np.float32(self.resolution),
            "meta": np.array(json.dumps(self.meta)),
        }
        if self.frames is not None:
            arrays["frames"] = self.frames
        # each write has a temporary file of its own: runs that make the same case set at
        # once each write a whole file and the last rename wins (the contents are the same)
        with atomic_open(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Case:
        """Read and validate a case file; raises :class:`CaseFileError` naming the problem."""
        path = Path(path)
        if not path.exists():
            raise CaseFileError(f"{path}: no such file")
        if not zipfile.is_zipfile(path):
            raise CaseFileError(f"{path}: not a readable .npz case file (not a zip archive)")
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
            raise CaseFileError(f"{path}: not a readable .npz case file ({e})") from None
        return cls.from_arrays(arrays, origin=str(path))

    @classmethod
    def from_arrays(cls, arrays: dict, origin: str = "case") -> Case:
        """A case from the arrays of a case file (as ``np.load`` gives them)."""
        missing = [k for k in REQUIRED_KEYS if k not in arrays]
        if missing:
            raise CaseFileError(f"{origin}: missing key(s) {', '.join(missing)}")
        occ = arrays["occupancy"]
        problems = []
        if occ.dtype != np.uint8:
            problems.append(f"occupancy has dtype {occ.dtype}, expected uint8")
        for key in ("wind", "concentration", "source") + (("frames",) if "frames" in arrays else ()):
            if arrays[key].dtype != np.float32:
                problems.append(f"{key} has dtype {arrays[key].dtype}, expected float32")
        meta = read_meta(arrays, origin, CaseFileError)
        res = np.asarray(arrays["resolution"])
        if res.shape != () or not np.issubdtype(res.dtype, np.floating):
            problems.append(f"resolution must be a float scalar, got {res.dtype} {res.shape}")
        if problems:
            raise CaseFileError(f"{origin}: " + "; ".join(problems))
        try:
            return cls(
                occ,
                arrays["wind"],
                arrays["concentration"],
                arrays["source"],
                float(res),
                meta,
                arrays.get("frames"),
            )
        except InputDataError as e:
            raise CaseFileError(f"{origin}: {e}") from None


def read_meta(arrays: Mapping[str, np.ndarray], origin: str, error: type[InputDataError]) -> dict:
    """The ``meta`` entry of a case or layout file's arrays, a JSON object, as a dict.

    Raises ``error`` naming ``origin`` (the file) when it is not a JSON object.
    """
    try:
        meta = json.loads(str(arrays["meta"]))
        if not isinstance(meta, dict):
            raise ValueError("not a JSON object")
    except ValueError as e:
        raise error(f"{origin}: meta is not a JSON object ({e})") from None
    return meta


#: Largest wind speed (m/s) tolerated in a solid cell of a wind field given by a user (not a case file).
WALL_WIND_TOLERANCE = 1e-6


def wind_problem(
    occ: np.ndarray, wind: np.ndarray, what: str = "wind", wall_tolerance: float = 0.0
) -> str | None:
    """The first problem of a ``(2, H, W)`` wind on map ``occ`` (shape, finite, no flow in walls), or None.

    ``wall_tolerance``: the largest speed (m/s) a solid cell may carry.
    """
    H, W = np.asarray(occ).shape
    if wind.shape != (2, H, W):
        return f"{what} has shape {wind.shape}, expected (2, {H}, {W}) (u_x, u_y per cell)"
    if not np.isfinite(wind).all():
        return f"{what} has NaN or infinite values"
    speed = np.hypot(wind[0], wind[1])
    through = (np.asarray(occ) != 0) & (speed > wall_tolerance)
    if through.any():
        return (
            f"{what} has flow through walls: {int(through.sum())} solid cells carry wind "
            f"(up to {float(speed[through].max()):.3g} m/s); solid cells must be 0"
        )
    return None


def validate_arrays(occ, wind, conc, source, resolution, meta, frames=None) -> list[str]:
    """Problems (human-readable) with a case's arrays; empty when valid."""
    p: list[str] = []
    if occ.ndim != 2 or min(occ.shape, default=0) < 2:
        return [f"occupancy must be a 2-D map, got shape {occ.shape}"]
    H, W = occ.shape
    if not np.isin(occ, (0, 1)).all():
        p.append("occupancy must contain only 0 (free) and 1 (solid)")
    if not (resolution > 0 and np.isfinite(resolution)):
        p.append(f"resolution must be positive, got {resolution}")
    problem = wind_problem(occ, wind)
    if problem:
        p.append(problem)
    if conc.shape != (H, W):
        p.append(f"concentration has shape {conc.shape}, expected ({H}, {W})")
    elif not np.isfinite(conc).all():
        p.append("concentration has non-finite values")
    elif conc.min(initial=0) < 0:
        p.append(f"concentration has negative values (min {conc.min():.3g} ppm)")
    elif np.abs(conc[occ == 1]).max(initial=0) > 0:
        p.append("concentration is not 0 in solid cells")
    if frames is not None:
        if frames.ndim != 3 or frames.shape[1:] != (H, W):
            p.append(f"frames has shape {frames.shape}, expected (T, {H}, {W})")
        elif "frame_dt" not in meta:
            p.append("frames given but meta has no frame_dt")
    if source.shape != (2,):
        p.append(f"source has shape {source.shape}, expected (2,)")
    elif resolution > 0:
        x, y = float(source[0]), float(source[1])
        j, i = cell_index(x, resolution), cell_index(y, resolution)
        if not (0 <= i < H and 0 <= j < W):
            p.append(f"source ({x:.3f}, {y:.3f}) m lies outside the map")
        elif occ[i, j] != 0:
            p.append(f"source ({x:.3f}, {y:.3f}) m lies in a solid cell")
    if isinstance(meta, dict) and resolution > 0:
        for key, n in (("width_m", W), ("height_m", H)):
            if key in meta and abs(float(meta[key]) - n * resolution) > 0.5 * resolution:
                p.append(f"meta {key}={meta[key]} does not match {n} cells of {resolution} m")
    return p
