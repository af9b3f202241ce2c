"""Import GADEN filament-simulator results (ASCII snapshots) as a case.

A GADEN result file (``FilamentSimulation_gasType_<g>_sourcePosition_<x>_<y>_<z>_iteration_<n>``,
written by GADEN's ``filament_simulator`` with ASCII output) is one time frame
of a 3-D scenario::

    env_min(m) 0.0000 0.0000 0.0000
    env_max(m) 5.0000 4.0000 2.5000            (optional)
    NumCells_XYZ 50 40 25
    CellSizes_XYZ[m] 0.1000 0.1000 0.1000
    GasSourceLocation_XYZ[m] 1.5000 2.0000 0.5000
    GasType ethanol                             (optional)
    Cell_x  Cell_y  Cell_z  Gas_conc[ppm]  Wind_u[m/s]  Wind_v[m/s]  Wind_w[m/s]
    0 0 0 0.000000 0.000000 0.000000 0.000000
    ...                                         (one row per cell, any order)

Header keys are matched without their unit suffix (``env_min`` or
``env_min(m)``; a single ``CellSize`` of newer GADEN versions is accepted
too); other header lines are ignored, but the file must start with a known
key.  Missing required keys, malformed values, a row count other than the
number of cells, indices out of range and non-finite values are errors; only ``ppm``
concentrations are accepted (GADEN can also write moles).

Several files of one scenario are time frames (sorted by their trailing
``iteration_<n>`` number, else naturally by name): they must share the header,
and become ``Case.frames`` ``(T, H, W)`` with ``meta["frame_dt"]``; the
steady concentration and the wind are the means over the frames.

The 2-D case is the z slice ``z_index`` (default: the slice holding the
source).  The obstacle image (GADEN's occupancy PGM, dark = solid, row 0 at
the top) covers ``[env_min, env_min + NumCells * CellSizes]`` in x and y; it is
resampled to the case grid with :func:`dgse.world.floorplan.resample_occupancy`.
When GADEN's cell size differs from ``resolution`` (0.1 m by default) the
fields are resampled per axis: cell-area averages when GADEN's cells are
smaller, linear interpolation between cell centres when they are larger.
Wind and concentration are set to 0 in solid cells.  Positions are shifted so
that ``env_min`` becomes the case's origin.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dgse.errors import InputDataError
from dgse.files import expand_paths
from dgse.world.case import Case
from dgse.world.grid import DEFAULT_RESOLUTION, cell_index
from dgse.world.layout import Opening

__all__ = ["GadenFrame", "load_gaden", "read_gaden_frame"]

_REQUIRED = ("env_min", "NumCells_XYZ", "CellSizes_XYZ", "GasSourceLocation_XYZ")
_VECTOR_KEYS = {
    "env_min": float,
    "env_max": float,
    "NumCells_XYZ": int,
    "CellSizes_XYZ": float,
    "GasSourceLocation_XYZ": float,
}
_IMAGE_SUFFIXES = {".pgm", ".png", ".yaml", ".yml", ".json", ".npz", ".h5"}


@dataclass(frozen=True, eq=False)
class GadenFrame:
    """One GADEN snapshot, restricted to one z slice.

    Attributes:
        path: the file.
        env_min: ``(x, y, z)`` of the environment's lower corner in m.
        num_cells: ``(nx, ny, nz)``.
        cell_sizes: ``(dx, dy, dz)`` in m.
        source: ``(x, y, z)`` of the gas source in m.
        gas_type: the ``GasType`` line, if any.
        z_index: the slice kept.
        conc: ``(ny, nx)`` ppm of the slice (row = y index).
        wind: ``(2, ny, nx)`` ``[u, v]`` m/s of the slice.
    """

    path: Path
    env_min: tuple[float, float, float]
    num_cells: tuple[int, int, int]
    cell_sizes: tuple[float, float, float]
    source: tuple[float, float, float]
    gas_type: str | None
    z_index: int
    conc: np.ndarray
    wind: np.ndarray

    def header_key(self) -> tuple:
        return (
            tuple(round(v, 6) for v in self.env_min),
            self.num_cells,
            tuple(round(v, 6) for v in self.cell_sizes),
            tuple(round(v, 6) for v in self.source),
            self.z_index,
        )


def _parse_header(path: Path, lines: list[str]) -> tuple[dict[str, Any], int, str]:
    """Header values, the index of the first data line, and the concentration unit."""
    header: dict[str, Any] = {}
    for n, raw in enumerate(lines):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("Cell_x"):
            cols = line.replace(",", " ").split()
            unit_m = re.match(r"Gas_conc\[(\w+)\]", cols[3]) if len(cols) >= 7 else None
            if len(cols) != 7 or unit_m is None:
                raise InputDataError(
                    f"{path}: line {n + 1}: column header must be 'Cell_x Cell_y Cell_z "
                    f"Gas_conc[ppm] Wind_u Wind_v Wind_w', got {line!r}"
                )
            missing = [k for k in _REQUIRED if k not in header]
            if missing:
                raise InputDataError(f"{path}: header lacks {', '.join(missing)}")
            return header, n + 1, unit_m.group(1)
        key, _, rest = line.partition(" ")
        key = re.sub(r"(\(.*\)|\[.*\])$", "", key)  # drop a unit suffix
        if key in _VECTOR_KEYS:
            conv = _VECTOR_KEYS[key]
            parts = rest.split()
            try:
                vals = tuple(conv(p) for p in parts)
            except ValueError:
                vals = ()
            if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
                raise InputDataError(
                    f"{path}: line {n + 1}: {key} needs three {conv.__name__} values, got {rest!r}"
                )
            header[key] = vals
        elif key == "CellSize":  # newer GADEN versions: one cubic cell size
            try:
                c = float(rest.split()[0])
            except (ValueError, IndexError):
                c = math.nan
            if not math.isfinite(c):
                raise InputDataError(f"{path}: line {n + 1}: CellSize needs a number, got {rest!r}")
            header["CellSizes_XYZ"] = (c, c, c)
        elif key == "GasType":
            header["GasType"] = rest.strip()
        elif not header:
            raise InputDataError(
                f"{path}: not a GADEN result file (starts with {line[:40]!r}, expected env_min)"
            )
        else:
            header.setdefault("other", []).append(line)
    raise InputDataError(
        f"{path}: no column header line 'Cell_x Cell_y Cell_z Gas_conc[ppm] ...' found"
        + (
            f" (header lacks {', '.join(k for k in _REQUIRED if k not in header)})"
            if any(k not in header for k in _REQUIRED)
            else ""
        )
    )


def read_gaden_frame(path: str | Path, z_index: int | None = None) -> GadenFrame:
    """Read one GADEN ASCII snapshot, keeping z slice ``z_index`` (default: the source's).

    Raises:
        InputDataError: unreadable file, malformed header or rows, non-ppm
            concentration, a z index out of range.
    """
    p = Path(path)
    try:
        text = p.read_text(errors="strict")
    except (OSError, UnicodeDecodeError) as e:
        raise InputDataError(f"{p}: cannot read GADEN result ({e})") from None
    lines = text.splitlines()
    header, first, unit = _parse_header(p, lines)
    if unit.lower() != "ppm":
        raise InputDataError(f"{p}: gas concentration is in {unit}; only ppm is supported")
    nx, ny, nz = header["NumCells_XYZ"]
    if min(nx, ny, nz) < 1:
        raise InputDataError(f"{p}: NumCells_XYZ must be positive, got {(nx, ny, nz)}")
    dx, dy, dz = header["CellSizes_XYZ"]
    if min(dx, dy, dz) <= 0:
        raise InputDataError(f"{p}: CellSizes_XYZ must be positive, got {(dx, dy, dz)}")
    ex, ey, ez = header["env_min"]
    sx, sy, sz = header["GasSourceLocation_XYZ"]
    if z_index is None:
        z_index = min(max(math.floor((sz - ez) / dz), 0), nz - 1)
    if not 0 <= z_index < nz:
        raise InputDataError(f"{p}: z index {z_index} out of range 0..{nz - 1}")
    body = "\n".join(lines[first:])
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        try:
            flat = np.fromstring(body, dtype=np.float64, sep=" ")  # fast; stops at bad tokens
        except (ValueError, DeprecationWarning):
            flat = None
    n_cells = nx * ny * nz
    if flat is None or flat.size % 7 != 0 or flat.size // 7 != n_cells:
        got = "unparsable values" if flat is None else f"{flat.size} values"
        raise InputDataError(
            f"{p}: expected {n_cells} rows of 7 numbers (NumCells_XYZ {nx} x {ny} x {nz}), got {got}"
        )
    rows = flat.reshape(-1, 7)
    idx = rows[:, :3]
    if not np.array_equal(idx, np.round(idx)):
        raise InputDataError(f"{p}: cell indices must be integers")
    ii = idx.astype(np.int64)
    bad = (ii < 0).any(axis=1) | (ii[:, 0] >= nx) | (ii[:, 1] >= ny) | (ii[:, 2] >= nz)
    if bad.any():
        r = int(np.argmax(bad))
        raise InputDataError(f"{p}: data row {r + 1} has cell {tuple(ii[r])} outside the grid")
    if not np.isfinite(rows[:, 3:]).all():
        raise InputDataError(f"{p}: non-finite concentration or wind values")
    sel = ii[:, 2] == z_index
    conc = np.full((ny, nx), np.nan)
    wind = np.full((2, ny, nx), np.nan)
    xs, ys = ii[sel, 0], ii[sel, 1]
    conc[ys, xs] = rows[sel, 3]
    wind[0, ys, xs] = rows[sel, 4]
    wind[1, ys, xs] = rows[sel, 5]
    if np.isnan(conc).any():
        raise InputDataError(f"{p}: some cells of slice z={z_index} are missing (duplicated rows?)")
    if (conc < 0).any():
        raise InputDataError(f"{p}: negative gas concentrations")
    return GadenFrame(
        p,
        (ex, ey, ez),
        (nx, ny, nz),
        (dx, dy, dz),
        (sx, sy, sz),
        header.get("GasType"),
        int(z_index),
        conc,
        wind,
    )


def _frame_sort_key(p: Path) -> tuple:
    m = re.search(r"iteration_(\d+)$", p.name)
    if m:
        return (0, int(m.group(1)), p.name)
    parts = re.split(r"(\d+)", p.name)
    return (1, 0, tuple(int(t) if t.isdigit() else t for t in parts))


def _result_files(files: str | Path | Sequence[str | Path]) -> list[Path]:
    def is_result(q: Path) -> bool:
        return not q.name.startswith(".") and q.suffix.lower() not in _IMAGE_SUFFIXES

    return sorted(expand_paths(files, is_result, "GADEN result"), key=_frame_sort_key)


def _axis_operator(n_out: int, out_size: float, n_in: int, in_size: float) -> np.ndarray:
    """``(n_out, n_in)`` resampling matrix along one axis (both grids start at 0)."""
    M = np.zeros((n_out, n_in))
    if math.isclose(out_size, in_size, rel_tol=1e-6) and n_out == n_in:
        return np.eye(n_in)
    if in_size < out_size:  # average over the input cells each output cell covers
        for k in range(n_out):
            a, b = k * out_size, (k + 1) * out_size
            p0 = max(0, math.floor(a / in_size))
            p1 = min(n_in, math.ceil(b / in_size))
            for q in range(p0, p1):
                ov = min(b, (q + 1) * in_size) - max(a, q * in_size)
                if ov > 0:
                    M[k, q] = ov
        s = M.sum(axis=1, keepdims=True)
        s[s == 0] = 1.0
        return M / s
    u = ((np.arange(n_out) + 0.5) * out_size) / in_size - 0.5  # input index coordinate
    u = np.clip(u, 0.0, n_in - 1.0)
    i0 = np.minimum(np.floor(u).astype(int), max(n_in - 2, 0))
    w = u - i0
    for k in range(n_out):
        M[k, i0[k]] += 1.0 - w[k]
        if n_in > 1:
            M[k, i0[k] + 1] += w[k]
    return M


def _obstacles(
    path: Path, width_m: float, height_m: float, shape: tuple[int, int], resolution: float, rule: str
) -> np.ndarray:
    from PIL import Image

    from dgse.world.floorplan import resample_occupancy

    try:
        with Image.open(path) as im:
            grey = np.asarray(im.convert("L"), dtype=np.float64)
    except FileNotFoundError:
        raise InputDataError(f"{path}: no such obstacle image") from None
    except Exception as e:  # PIL raises many kinds
        raise InputDataError(f"{path}: cannot read obstacle image ({e})") from None
    h, w = grey.shape
    px, py = width_m / w, height_m / h
    if not math.isclose(px, py, rel_tol=0.02):
        raise InputDataError(
            f"{path}: image of {w} x {h} pixels does not match the {width_m:g} x {height_m:g} m "
            f"environment with square pixels ({px:.4g} vs {py:.4g} m)"
        )
    solid = np.flipud(grey < 127.5)  # dark is solid; row 0 of the image is the top
    occ = resample_occupancy(solid, px, resolution, rule)
    H, W = shape
    out = np.ones((H, W), dtype=np.uint8)
    hh, ww = min(H, occ.shape[0]), min(W, occ.shape[1])
    out[:hh, :ww] = occ[:hh, :ww]
    return out


def load_gaden(
    files: str | Path | Sequence[str | Path],
    obstacles: str | Path,
    *,
    z_index: int | None = None,
    resolution: float = DEFAULT_RESOLUTION,
    frame_dt: float | None = None,
    name: str | None = None,
    release_rate: float | None = None,
    inlet_velocity: float | None = None,
    inlets: Sequence[Opening] = (),
    outlets: Sequence[Opening] = (),
    rule: str = "majority",
) -> Case:
    """A case from GADEN result files (time frames of one scenario) and an obstacle image.

    Args:
        files: one result file, several (frames), or a directory of them (the
            files other than images/YAML in it).
        obstacles: the occupancy image (PGM/PNG; dark = solid) covering the
            environment's x-y extent.
        z_index: the z slice to keep (default: the one holding the source).
        resolution: cell size of the case in m.
        frame_dt: seconds between frames (required with more than one file).
        name: case name (default: the directory or file stem).
        release_rate: the source's release rate in g/s, when known (``meta``).
        inlet_velocity: the inlet speed in m/s, when known (``meta``).
        inlets, outlets: openings of the layout, when known (``meta``).
        rule: obstacle resampling rule (``"any"``, ``"majority"``, ``"all"``).

    Returns:
        A :class:`Case`: the mean concentration and wind of the frames, the
        frames ``(T, H, W)`` when ``T > 1``, the source position relative to
        ``env_min``; ``meta`` has ``solver="gaden"`` and a ``gaden`` record of the
        header (files, env_min, cell sizes, z slice, gas type).

    Raises:
        InputDataError: malformed files, frames that disagree, a missing
            ``frame_dt``, an obstacle image of the wrong aspect, a source in a
            solid cell.
    """
    paths = _result_files(files)
    if not (resolution > 0 and math.isfinite(resolution)):
        raise InputDataError(f"resolution must be positive, got {resolution}")
    if len(paths) > 1 and frame_dt is None:
        raise InputDataError(
            f"{len(paths)} frames given: pass {{frame_dt}} (seconds between them)",
            names={"frame_dt": "frame_dt"},
        )
    if frame_dt is not None and not (frame_dt > 0 and math.isfinite(frame_dt)):
        raise InputDataError(f"{{frame_dt}} must be positive, got {frame_dt}", names={"frame_dt": "frame_dt"})
    frames = [read_gaden_frame(paths[0], z_index)]
    z = frames[0].z_index
    for p in paths[1:]:
        f = read_gaden_frame(p, z)
        if f.header_key() != frames[0].header_key():
            raise InputDataError(
                f"{p}: header (env_min, cells, cell sizes, source) differs from {paths[0]}; "
                "frames of one scenario must share it"
            )
        frames.append(f)
    f0 = frames[0]
    nx, ny, _ = f0.num_cells
    dx, dy, dz = f0.cell_sizes
    width_m, height_m = nx * dx, ny * dy
    W = max(2, round(width_m / resolution))
    H = max(2, round(height_m / resolution))
    Ay = _axis_operator(H, resolution, ny, dy)
    Ax = _axis_operator(W, resolution, nx, dx)

    def resample(a: np.ndarray) -> np.ndarray:
        return Ay @ a @ Ax.T

    occ = _obstacles(Path(obstacles), width_m, height_m, (H, W), resolution, rule)
    free = occ == 0
    conc_frames = np.stack([np.where(free, resample(f.conc), 0.0) for f in frames])
    conc_frames = np.maximum(conc_frames, 0.0).astype(np.float32)
    wind = np.mean([np.stack([resample(f.wind[0]), resample(f.wind[1])]) for f in frames], axis=0)
    wind = np.where(free, wind, 0.0).astype(np.float32)
    conc = conc_frames.astype(np.float64).mean(axis=0).astype(np.float32)
    sx, sy = f0.source[0] - f0.env_min[0], f0.source[1] - f0.env_min[1]
    src = np.array([sx, sy], dtype=np.float32)
    sx, sy = float(src[0]), float(src[1])  # the position the case will hold
    i, j = cell_index(sy, resolution), cell_index(sx, resolution)
    if not (0 <= i < H and 0 <= j < W):
        raise InputDataError(
            f"GADEN source ({f0.source[0]:g}, {f0.source[1]:g}) m lies outside the environment"
        )
    if occ[i, j]:
        raise InputDataError(
            f"GADEN source ({f0.source[0]:g}, {f0.source[1]:g}) m lies in a solid cell "
            f"of the obstacle image {obstacles}"
        )
    stem = paths[0].parent.name if len(paths) > 1 else paths[0].name
    meta: dict[str, Any] = {
        "name": name or re.sub(r"[^A-Za-z0-9_.+-]", "_", stem) or "gaden",
        "width_m": W * resolution,
        "height_m": H * resolution,
        "resolution": resolution,
        "source_xy_m": [float(sx), float(sy)],
        "solver": "gaden",
        "walls": [],
        "gaden": {
            "files": [str(p) for p in paths],
            "obstacles": str(obstacles),
            "env_min": list(f0.env_min),
            "num_cells": list(f0.num_cells),
            "cell_sizes": list(f0.cell_sizes),
            "source_xyz": list(f0.source),
            "z_index": z,
            "z_m": f0.env_min[2] + (z + 0.5) * dz,
            "gas_type": f0.gas_type,
        },
    }
    if release_rate is not None:
        meta["release_rate_gps"] = float(release_rate)
    if inlet_velocity is not None:
        meta["inlet_velocity"] = float(inlet_velocity)
    if inlets:
        meta["inlets"] = [o.to_dict() for o in inlets]
    if outlets:
        meta["outlets"] = [o.to_dict() for o in outlets]
    if len(frames) > 1:
        meta["frame_dt"] = float(frame_dt)  # type: ignore[arg-type]
    return Case(occ, wind, conc, src, resolution, meta, conc_frames if len(frames) > 1 else None)
