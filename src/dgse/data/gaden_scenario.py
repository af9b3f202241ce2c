"""Import a GADEN scenario folder (map, outlet models, simulation, scene, CFD wind) as a layout or a case.

A GADEN scenario folder (GADEN's ``test_env/scenarios/<name>``, the PMFS test
configurations of MAPIRlab's GasSourceLocalization) describes one building and
one experiment in files that GADEN's tools write or read:

* a ROS map_server map (a YAML with ``image``, ``resolution``, ``origin``,
  ``negate``, ``occupied_thresh``, ``free_thresh``, and its PGM/PNG image), as
  ``gaden_preprocessing`` writes it (``occupancy.yaml`` + ``occupancy.pgm``).
  GADEN writes its floor height as the third ``origin`` value, where ROS keeps
  the yaw; it is not taken as a rotation here;
* STL models (ASCII or binary) of the walls and of the *outlets*: the openings
  of the building, listed under ``outlets_models`` in the preprocessing
  settings (a ``config.yaml`` or a ROS parameter file; GADEN's older numbered
  ``outlets_model_N`` parameters of a launch XML are read too; files listing
  different models need ``settings_path``), or, when no settings list them,
  the STL files whose name contains ``outlet``;
* a simulation file with the gas source: ``source: {position: [x, y, z]}``
  (GADEN 2's ``sim.yaml``), or ``source_position_{x,y,z}``, ``source_{x,y,z}``,
  ``source_location_{x,y,z}``, ``source_0_position_{x,y,z}`` (older YAML files
  and launch XML ``<arg>``/``<param>`` entries);
* a robot scene (BasicSim's YAML: ``robots: [{position: [x, y, z]}, ...]``)
  giving the robot's start;
* the CFD wind as ParaView exports it, ``<prefix>_<t>.csv`` with the prefix
  the settings give (``unprocessed_wind_files`` or ``wind_files``), else
  ``wind_at_cell_centers_<t>.csv``: a header, then one row per CFD cell centre
  with its point ``Points:0..2`` and wind ``U:0..2`` in m/s (either order;
  columns found by name, else by GADEN's rule: points first when the first
  header field names ``Points``).

:func:`load_gaden_scenario` reads them into a :class:`GadenScenario`:

* the occupancy: :func:`~dgse.world.floorplan.load_ros_map` on the DGSE grid
  (``resolution``, default 0.1 m), its origin the map-frame corner of the grid;
* each outlet model's x-y footprint (bounding box of its triangles) projected
  onto the nearest side of the map: the boundary cells it covers become an
  :class:`~dgse.world.layout.Opening`.  A footprint farther than
  ``edge_tolerance`` from every side, or outside the map, is an error;
* inlets and outlets: the models named by ``inlets``/``outlets``; the others
  by the wind's net flow through their boundary cells (into the map: inlet,
  else outlet); without a wind every model must be named;
* the wind: every file of one wind simulation (time steps averaged), its
  points within ``height_tolerance`` of ``height`` (map-frame z; default the
  source's height, where the sensors are) binned into the grid's cells and
  averaged, free cells with no point given their nearest binned cell's wind,
  solid cells 0;
* source and start converted from the map frame to the grid frame (m from the
  grid's lower-left corner), each checked to lie in a free cell.

The layout is :func:`~dgse.world.floorplan.layout_from_floorplan`'s (openings
cut through up to ``carve_depth_m`` of outer wall; free space no opening
reaches made solid).  :func:`import_gaden_scenario` writes it as a layout file,
or solves it with a physics engine into a case file (the inlet speed from the
wind, the release rate given); both keep ``source_m``, ``start_m``,
``map_origin_m`` and a ``gaden`` record of the files read in their ``meta``.

Writing: :func:`export_gaden_scenario` writes a case as such a folder (map, one outlet model
per opening, configuration, simulation, wind CSV, optionally a scene), from the writers
:func:`write_stl` and :func:`write_wind_csv` (:func:`read_stl`'s and :func:`read_wind_csv`'s
formats) and :func:`~dgse.world.floorplan.export_ros_map`; importing it gives back the
occupancy, the openings, the source and the wind.
"""

from __future__ import annotations

import math
import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dgse.errors import InputDataError
from dgse.world.grid import DEFAULT_RESOLUTION, Grid
from dgse.world.layout import INWARD_NORMAL, Layout, Opening

__all__ = [
    "GadenScenario",
    "box_triangles",
    "export_gaden_scenario",
    "import_gaden_scenario",
    "load_gaden_scenario",
    "read_stl",
    "read_wind_csv",
    "write_stl",
    "write_wind_csv",
]

_YAML_SUFFIXES = (".yaml", ".yml")
_XML_SUFFIXES = (".launch", ".xml")
_WIND_GLOB = "*wind_at_cell_center*.csv"
#: Key prefixes of a source position (``<prefix>x``, ``<prefix>y``, ``<prefix>z``), in the order tried.
_SOURCE_PREFIXES = ("source_position_", "source_location_", "source_0_position_", "source_")
_SUBST = re.compile(r"\$\((?:var|arg)\s+([\w-]+)\)")
_ANY_SUBST = re.compile(r"\$\([^)]*\)")


@dataclass(frozen=True, eq=False)
class GadenScenario:
    """A GADEN scenario folder on the DGSE grid (positions in m, grid frame).

    Attributes:
        layout: occupancy and openings.
        source: ``(x, y)`` of the gas source.
        source_z: its map-frame height, m.
        start: ``(x, y)`` of the robot's start, or None.
        origin: map-frame ``(x, y)`` of the grid's lower-left corner.
        wind: ``(2, H, W)`` ``[u, v]`` m/s at ``height``, or None without a wind file.
        height: map-frame z of the wind slice, m.
        inlet_speed: mean inward wind speed over the inlets' free cells, m/s (None without wind).
        files: what was read (``map``, ``simulation``, ``scene``, ``inlets``, ``outlets``, ``wind``).
    """

    layout: Layout
    source: tuple[float, float]
    source_z: float
    start: tuple[float, float] | None
    origin: tuple[float, float]
    wind: np.ndarray | None
    height: float
    inlet_speed: float | None
    files: dict[str, Any] = field(default_factory=dict)

    def meta(self) -> dict[str, Any]:
        """What a layout or case file keeps of the import besides the layout."""
        d: dict[str, Any] = {
            "source_m": [float(self.source[0]), float(self.source[1])],
            "source_z_m": float(self.source_z),
            "map_origin_m": [float(self.origin[0]), float(self.origin[1])],
        }
        if self.start is not None:
            d["start_m"] = [float(self.start[0]), float(self.start[1])]
        d["gaden"] = {**self.files, "height_m": float(self.height)}
        if self.inlet_speed is not None:
            d["gaden"]["inlet_speed_m_s"] = float(self.inlet_speed)
        return d


# -- STL ------------------------------------------------------------------------------------------
_BINARY_STL = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def read_stl(path: str | Path) -> np.ndarray:
    """The triangles ``(n, 3, 3)`` (triangle, vertex, xyz) of an ASCII or binary STL file, in m.

    A file whose size is ``84 + 50 n`` with ``n`` the count at byte 80 is
    binary (even when its header starts with ``solid``); otherwise it must be
    ASCII (``solid ... facet ... vertex x y z ... endsolid``).

    Raises:
        InputDataError: a missing or unreadable file, no triangles, non-finite vertices.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputDataError(f"{p}: cannot read STL model ({e.strerror or e})") from None
    tris: np.ndarray | None = None
    if len(data) >= 84:
        n = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * n:
            tris = np.frombuffer(data, dtype=_BINARY_STL, count=n, offset=84)["v"].astype(np.float64)
    if tris is None:
        try:
            text = data.decode("ascii")
        except UnicodeDecodeError:
            text = ""
        if not text.lstrip().startswith("solid"):
            raise InputDataError(f"{p}: not an STL model (neither ASCII 'solid ...' nor binary)")
        nums = re.findall(r"vertex\s+(\S+)\s+(\S+)\s+(\S+)", text)
        try:
            flat = np.array(nums, dtype=np.float64)
        except ValueError:
            raise InputDataError(f"{p}: ASCII STL with a vertex that is not three numbers") from None
        if flat.size == 0 or flat.shape[0] % 3:
            raise InputDataError(f"{p}: ASCII STL with {flat.shape[0]} vertices (not whole triangles)")
        tris = flat.reshape(-1, 3, 3)
    if tris.shape[0] == 0:
        raise InputDataError(f"{p}: STL model has no triangles")
    if not np.isfinite(tris).all():
        raise InputDataError(f"{p}: STL model has non-finite vertices")
    return tris


# -- settings files -------------------------------------------------------------------------------
def _load_yaml(path: Path) -> Any:
    import yaml

    try:
        return yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None


def _load_launch(path: Path) -> dict[str, str] | None:
    """``name -> value`` of the ``<arg>`` defaults and ``<param>`` values, ``$(var x)`` resolved."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return None
    args = {e.get("name"): e.get("default", e.get("value")) for e in root.iter("arg")}
    out: dict[str, str] = {k: v for k, v in args.items() if k and v is not None}
    for e in root.iter("param"):
        name, value = e.get("name"), e.get("value")
        if name and value is not None:
            out[name] = value
    for k, v in out.items():
        out[k] = _SUBST.sub(lambda m: str(args.get(m.group(1)) or m.group(0)), v)
    return out


def _mappings(obj: Any) -> Iterator[Mapping]:
    """``obj`` and every mapping nested in it (ROS parameter files nest ``node: ros__parameters:``)."""
    if isinstance(obj, Mapping):
        yield obj
        for v in obj.values():
            yield from _mappings(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _mappings(v)


@dataclass
class _Settings:
    """Every YAML mapping and launch file of a folder, parsed once."""

    directory: Path
    docs: list[tuple[Path, Any]]

    @classmethod
    def scan(cls, directory: Path) -> _Settings:
        docs: list[tuple[Path, Any]] = []
        for p in sorted(directory.rglob("*")):
            if not p.is_file() or any(part.startswith(".") for part in p.relative_to(directory).parts):
                continue
            if p.suffix.lower() in _YAML_SUFFIXES:
                doc = _load_yaml(p)
            elif p.suffix.lower() in _XML_SUFFIXES:
                doc = _load_launch(p)
            else:
                continue
            if doc is not None:
                docs.append((p, doc))
        return cls(directory, docs)

    def only(self, path: Path | None) -> list[tuple[Path, Any]]:
        if path is None:
            return self.docs
        if not path.is_file():
            raise InputDataError(f"{path}: no such file")
        doc = _load_launch(path) if path.suffix.lower() in _XML_SUFFIXES else _load_yaml(path)
        if doc is None:
            raise InputDataError(f"{path}: not a readable YAML or launch file")
        return [(path, doc)]

    def resolve(self, base: Path, name: str) -> Path:
        """A file named in a settings file: relative to it, or (ROS substitutions) found by name."""
        cleaned = _ANY_SUBST.sub("", name).strip()
        for cand in (base.parent / cleaned, self.directory / cleaned):
            if cleaned and cand.is_file():
                return cand
        hits = sorted(self.directory.rglob(Path(cleaned).name)) if Path(cleaned).name else []
        if len(hits) == 1:
            return hits[0]
        raise InputDataError(f"{base}: names the model {name!r}, which is not in {self.directory}")


def _floats(values: Sequence[Any], what: str, where: Path) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise InputDataError(f"{where}: {what} must be numbers, got {list(values)!r}") from None
    if not all(math.isfinite(v) for v in out):
        raise InputDataError(f"{where}: {what} must be finite, got {list(values)!r}")
    return out


def _source_in(d: Mapping, where: Path) -> tuple[float, float, float] | None:
    src = d.get("source")
    if isinstance(src, Mapping) and isinstance(src.get("position"), list | tuple):
        pos = _floats(src["position"], "source position", where)
        if len(pos) in (2, 3):
            return (pos[0], pos[1], pos[2] if len(pos) == 3 else 0.0)
    with_xy = [p for p in _SOURCE_PREFIXES if f"{p}x" in d and f"{p}y" in d]
    if not with_xy:
        return None
    prefix = next((p for p in with_xy if f"{p}z" in d), with_xy[0])  # one with a height first
    keys = [f"{prefix}{a}" for a in "xyz" if f"{prefix}{a}" in d]
    x, y, *z = _floats([d[k] for k in keys], f"{prefix}x/y/z", where)
    return (x, y, z[0] if z else 0.0)


def _start_in(d: Mapping, where: Path) -> tuple[float, float] | None:
    robots = d.get("robots")
    if isinstance(robots, list) and robots and isinstance(robots[0], Mapping) and "position" in robots[0]:
        pos = robots[0]["position"]
        if isinstance(pos, list | tuple) and len(pos) >= 2:
            x, y = _floats(pos[:2], "robot position", where)
            return (x, y)
    return None


def _unique(found: list[tuple[Path, Any]], what: str, option: str) -> tuple[Path, Any] | None:
    """The one value found (files agreeing count once), None for none; an error for several."""
    if not found:
        return None
    values = {tuple(round(v, 6) for v in val) for _, val in found}
    if len(values) > 1:
        listing = "; ".join(f"{p.name}: {tuple(round(v, 3) for v in val)}" for p, val in found[:4])
        raise InputDataError(f"several {what}s ({listing}): give {option}")
    return found[0]


def _find(settings: _Settings, path: Path | None, pick, what: str, option: str):
    found = []
    for p, doc in settings.only(path):
        for d in _mappings(doc):
            try:
                v = pick(d, p)
            except InputDataError:
                if path is not None:
                    raise
                v = None  # a file found by looking, with unresolved values (launch substitutions)
            if v is not None:
                found.append((p, v))
                break
    if path is not None and not found:
        raise InputDataError(f"{path}: no {what} in it")
    return _unique(found, what, option)


def _find_map(settings: _Settings, map_path: Path | None) -> Path:
    if map_path is not None:
        return map_path
    maps = [
        p
        for p, doc in settings.docs
        if isinstance(doc, Mapping) and {"image", "resolution", "origin"} <= set(doc)
    ]
    if not maps:
        raise InputDataError(
            f"{settings.directory}: no ROS map YAML (image, resolution, origin) in the folder: give --map"
        )
    depth = min(len(p.parts) for p in maps)
    top = [p for p in maps if len(p.parts) == depth]
    if len(top) > 1:
        raise InputDataError(
            f"{settings.directory}: several map YAML files ({', '.join(p.name for p in top)}): give --map"
        )
    return top[0]


def _outlet_lists(settings: _Settings, path: Path | None) -> tuple[Path | None, list[Path], str | None]:
    """The settings file listing the outlet models, the models (resolved) and its wind-file prefix.

    Files listing the same models count once; different lists need ``path`` (``--settings``).
    Without a list: the STL files named ``*outlet*`` and no settings file.
    """
    lists: list[tuple[Path, list[Path], str | None]] = []
    for p, doc in settings.only(path):
        models: list[Path] = []
        prefix = None
        for d in _mappings(doc):
            listed = d.get("outlets_models")
            if isinstance(listed, list):
                models += [
                    settings.resolve(p, s) for s in listed if isinstance(s, str) and not s.startswith("!")
                ]
            numbered = sorted(
                (int(m.group(1)), k)
                for k in d
                if isinstance(k, str) and (m := re.fullmatch(r"outlets?_model_(\d+)", k))
            )
            models += [settings.resolve(p, str(d[k])) for _, k in numbered]
            for key in ("unprocessed_wind_files", "wind_files"):
                if isinstance(d.get(key), str) and prefix is None:
                    prefix = d[key]
        if models:
            lists.append((p, list(dict.fromkeys(m.resolve() for m in models)), prefix))
    if path is not None and not lists:
        raise InputDataError(f"{path}: lists no outlet models (outlets_models or outlets_model_N)")
    if not lists:
        found = sorted(
            q.resolve()
            for q in settings.directory.rglob("*")
            if q.suffix.lower() == ".stl" and "outlet" in q.name.lower()
        )
        return None, found, None
    if len({tuple(sorted(m)) for _, m, _ in lists}) > 1:
        listing = "; ".join(f"{p.relative_to(settings.directory)}: {len(m)} models" for p, m, _ in lists[:4])
        raise InputDataError(f"several lists of outlet models ({listing}): give --settings FILE")
    return lists[0]


def _named(names: Sequence[str | Path], models: list[Path], directory: Path, option: str) -> list[Path]:
    """The models ``names`` names (a path, a file name or a stem of one of ``models``)."""
    out = []
    for n in names:
        p = Path(n)
        hits = [m for m in models if m.name == p.name or m.stem == str(n) or m == p.resolve()]
        if len(hits) == 1:
            out.append(hits[0])
            continue
        for cand in (p, directory / p):
            if cand.is_file():
                out.append(cand.resolve())
                break
        else:
            known = ", ".join(m.name for m in models) or "none"
            raise InputDataError(f"{option} {n}: no such outlet model (the scenario's: {known})")
    return out


# -- geometry -------------------------------------------------------------------------------------
def _opening(tris: np.ndarray, origin: tuple[float, float], grid: Grid, tol: float, path: Path) -> Opening:
    """The boundary cells the x-y footprint of a model covers, as an opening of the nearest side."""
    x0, y0 = tris[..., 0].min() - origin[0], tris[..., 1].min() - origin[1]
    x1, y1 = tris[..., 0].max() - origin[0], tris[..., 1].max() - origin[1]
    W, H = grid.width_m, grid.height_m
    frame = f"x {x0 + origin[0]:.2f}..{x1 + origin[0]:.2f}, y {y0 + origin[1]:.2f}..{y1 + origin[1]:.2f} m"
    if x1 < -tol or y1 < -tol or x0 > W + tol or y0 > H + tol:
        raise InputDataError(f"{path}: the outlet ({frame}) lies outside the map")
    gaps = {"west": x0, "east": W - x1, "south": y0, "north": H - y1}
    side = min(gaps, key=lambda s: abs(gaps[s]))
    if abs(gaps[side]) > tol:
        raise InputDataError(
            f"{path}: the outlet ({frame}) is not at the map's edge (nearest: the {side} side, "
            f"{abs(gaps[side]):.2f} m away; tolerance {tol:g} m)"
        )
    a, b = (y0, y1) if side in ("west", "east") else (x0, x1)
    length = H if side in ("west", "east") else W
    r = grid.resolution
    snap = 1e-3  # of a cell: STL vertices are float32, a door edge on a cell face stays there
    a = max(0.0, math.floor(a / r + snap) * r)
    b = min(length, math.ceil(b / r - snap) * r)
    if not b > a:
        raise InputDataError(f"{path}: the outlet ({frame}) covers no cell of the {side} side")
    return Opening(side, round(a, 9), round(b, 9))


def _check_free(layout: Layout, xy: tuple[float, float], origin, what: str, where: str) -> None:
    X, Y = xy[0] + origin[0], xy[1] + origin[1]
    g = layout.grid
    label = f"{what} ({X:.3f}, {Y:.3f}) m (map frame{'; ' + where if where else ''})"
    try:
        i, j = g.cell_of(*xy)
    except InputDataError:
        raise InputDataError(f"{label} lies outside the map") from None
    if layout.occupancy[i, j]:
        raise InputDataError(f"{label} lies in a wall (grid cell ({i}, {j}))")


# -- wind -----------------------------------------------------------------------------------------
def read_wind_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(n, 3)`` (m) and winds ``(n, 3)`` (m/s) of a ParaView cell-centre CSV export.

    Raises:
        InputDataError: unreadable file, no rows, rows that are not numbers.
    """
    p = Path(path)
    try:
        with p.open() as fh:
            header = fh.readline()
            names = [h.strip().strip('"').strip() for h in header.split(",")]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # an empty file: an error below, not a warning
                rows = np.loadtxt(fh, delimiter=",", ndmin=2, dtype=np.float64)
    except (OSError, UnicodeDecodeError) as e:
        raise InputDataError(f"{p}: cannot read wind CSV ({e})") from None
    except ValueError as e:
        raise InputDataError(f"{p}: wind CSV rows must be comma-separated numbers ({e})") from None
    if rows.size == 0 or rows.shape[1] < 6:
        raise InputDataError(f"{p}: wind CSV needs a header and rows of points and winds (6 columns)")
    if {"Points:0", "U:0"} <= set(names) and len(names) == rows.shape[1]:
        pc = [names.index(f"Points:{k}") for k in range(3)]
        uc = [names.index(f"U:{k}") for k in range(3)]
    elif "Points" in names[0]:
        pc, uc = [0, 1, 2], [3, 4, 5]
    else:
        uc, pc = [0, 1, 2], [3, 4, 5]
    pts, wind = rows[:, pc], rows[:, uc]
    if not (np.isfinite(pts).all() and np.isfinite(wind).all()):
        raise InputDataError(f"{p}: wind CSV has non-finite values")
    return pts, wind


def _wind_files(
    settings: _Settings, given: Sequence[Path], base: Path | None, prefix: str | None
) -> list[Path]:
    """The wind CSV files: ``given``; else ``<prefix>_<t>.csv`` of the settings (found by name
    under the folder); else the one folder of ``wind_at_cell_centers*.csv`` files."""
    directory = settings.directory
    if given:
        return list(given)
    if prefix is not None and base is not None:
        stem = Path(_ANY_SUBST.sub("", prefix).strip()).name
        pattern = re.compile(re.escape(stem) + r"_\d+\.csv$")
        files = sorted(q for q in directory.rglob("*.csv") if pattern.fullmatch(q.name))
        if files and len({f.parent for f in files}) == 1:
            return files
    files = sorted(directory.rglob(_WIND_GLOB))
    folders = sorted({f.parent for f in files})
    if len(folders) > 1:
        names = ", ".join(str(f.relative_to(directory)) for f in folders)
        raise InputDataError(
            f"{directory}: several wind simulations ({names}): give --wind FILE (repeatable) or --no-wind"
        )
    return files


def _slice_wind(files: Sequence[Path], layout: Layout, origin, height: float, tol: float) -> np.ndarray:
    from scipy import ndimage

    g = layout.grid
    H, W = g.shape
    total = np.zeros((2, H, W))
    count = np.zeros((H, W))
    for f in files:
        pts, wind = read_wind_csv(f)
        keep = np.abs(pts[:, 2] - height) <= tol
        if not keep.any():
            raise InputDataError(
                f"{f}: no wind point within {tol:g} m of the height {height:g} m "
                f"(points from z {pts[:, 2].min():.3f} to {pts[:, 2].max():.3f} m): give --height"
            )
        j = np.floor((pts[keep, 0] - origin[0]) / g.resolution).astype(np.int64)
        i = np.floor((pts[keep, 1] - origin[1]) / g.resolution).astype(np.int64)
        inside = (i >= 0) & (i < H) & (j >= 0) & (j < W)
        for c in range(2):
            np.add.at(total[c], (i[inside], j[inside]), wind[keep, c][inside])
        np.add.at(count, (i[inside], j[inside]), 1.0)
    free = layout.free
    have = (count > 0) & free
    if not have.any():
        raise InputDataError(f"no wind point at height {height:g} m falls in a free cell of the map")
    mean = np.where(count > 0, total / np.maximum(count, 1.0), 0.0)
    _, (ni, nj) = ndimage.distance_transform_edt(~have, return_indices=True)
    filled = mean[:, ni, nj]
    return np.where(free, filled, 0.0)


def _inward_flux(o: Opening, layout: Layout, wind: np.ndarray) -> tuple[float, int]:
    rows, cols = o.cells(layout.grid)
    ok = layout.occupancy[rows, cols] == 0
    nx, ny = INWARD_NORMAL[o.side]
    un = wind[0, rows[ok], cols[ok]] * nx + wind[1, rows[ok], cols[ok]] * ny
    return float(un.sum()), int(ok.sum())


# -- the folder -----------------------------------------------------------------------------------
def load_gaden_scenario(
    directory: str | Path,
    *,
    resolution: float = DEFAULT_RESOLUTION,
    map_path: str | Path | None = None,
    simulation: str | Path | None = None,
    scene: str | Path | None = None,
    settings_path: str | Path | None = None,
    inlets: Sequence[str | Path] = (),
    outlets: Sequence[str | Path] = (),
    wind_files: Sequence[str | Path] = (),
    use_wind: bool = True,
    source: tuple[float, float] | None = None,
    start: tuple[float, float] | None = None,
    height: float | None = None,
    height_tolerance: float = 0.1,
    edge_tolerance: float = 0.3,
    carve_depth_m: float = 0.5,
    rule: str = "any",
    name: str | None = None,
) -> GadenScenario:
    """Read a GADEN scenario folder (module docstring).

    Args:
        directory: the scenario folder; settings, models and wind are looked for in it and below.
        resolution: cell size of the DGSE grid, m.
        map_path: the map YAML (default: the one in the folder).
        simulation: the file with the source (default: the one source the folder's files give).
        scene: the robot scene with the start (default: the one start the folder's files give).
        settings_path: the preprocessing settings listing the outlet models (default: the one
            list the folder's files give).
        inlets, outlets: outlet models (paths, file names or stems) that are inlets or outlets;
            models not named are told apart by the wind.
        wind_files: the wind CSV files (default: the folder's one wind simulation).
        use_wind: read no wind when False.
        source, start: map-frame ``(x, y)`` in m instead of the files'.
        height: map-frame z of the wind slice (default: the source's z from the files; 0
            with ``source``).
        height_tolerance: wind points within this distance of ``height`` are used, m.
        edge_tolerance: how far an outlet's footprint may lie from the map's edge, m.
        carve_depth_m: outer wall an opening is cut through, m.
        rule: the map's resampling rule (:func:`~dgse.world.floorplan.resample_occupancy`).
        name: the layout's name (default: the folder's name).

    Raises:
        InputDataError: a missing map, a model that is not an STL file or not at
            the map's edge, a source or start outside the map or in a wall, no
            or several sources or starts, openings that cannot be told apart.
    """
    from dgse.world.floorplan import layout_from_floorplan, load_ros_map

    d = Path(directory)
    if not d.is_dir():
        raise InputDataError(f"{d}: no such scenario folder")
    for what, v in (("height tolerance", height_tolerance), ("edge tolerance", edge_tolerance)):
        if not (math.isfinite(v) and v >= 0):
            raise InputDataError(f"{what} must be >= 0 m, got {v}")
    settings = _Settings.scan(d)
    map_yaml = _find_map(settings, None if map_path is None else Path(map_path))
    with warnings.catch_warnings():  # GADEN writes its floor height where ROS keeps the yaw
        warnings.simplefilter("ignore")
        fp = load_ros_map(map_yaml, resolution, rule=rule)
    grid, origin = fp.grid, fp.origin

    if source is not None:
        sx, sy = _floats(source, "--source", d)
        src_file, sz = None, 0.0 if height is None else float(height)
    else:
        found = _find(
            settings,
            None if simulation is None else Path(simulation),
            _source_in,
            "source",
            "--simulation FILE or --source X Y",
        )
        if found is None:
            raise InputDataError(
                f"{d}: no source position in the folder (source: position, source_position_x/y/z, "
                "source_x/y/z, ...): give --simulation FILE or --source X Y"
            )
        src_file, (sx, sy, sz) = found
    if start is not None:
        start_file, st = None, _floats(start, "--start", d)
    else:
        found = _find(
            settings,
            None if scene is None else Path(scene),
            _start_in,
            "robot start",
            "--scene FILE or --start X Y",
        )
        start_file, st = (None, None) if found is None else found

    settings_file, models, wind_prefix = _outlet_lists(
        settings, None if settings_path is None else Path(settings_path)
    )
    named_in = _named(inlets, models, d, "--inlet")
    named_out = _named(outlets, models, d, "--outlet")
    both = set(named_in) & set(named_out)
    if both:
        raise InputDataError(f"{', '.join(p.name for p in both)}: named both --inlet and --outlet")
    for extra in named_in + named_out:
        if extra not in models:
            models.append(extra)
    if not models:
        raise InputDataError(
            f"{d}: no outlet models (outlets_models in the settings, or STL files named *outlet*): "
            "give --inlet FILE and --outlet FILE"
        )
    openings = {m: _opening(read_stl(m), origin, grid, edge_tolerance, m) for m in models}

    z = sz if height is None else float(height)
    given_wind = [Path(w) for w in wind_files]
    wind_paths = _wind_files(settings, given_wind, settings_file, wind_prefix) if use_wind else []
    # a provisional layout (every model an outlet but one) to slice the wind on the map's free cells
    ms = list(openings)
    provisional = layout_from_floorplan(
        fp,
        None,
        [openings[ms[0]]],
        [openings[m] for m in ms[1:]] or [openings[ms[0]]],
        carve_depth_m=carve_depth_m,
        fill_unreachable=False,
    )
    wind = _slice_wind(wind_paths, provisional, origin, z, height_tolerance) if wind_paths else None
    kinds: dict[Path, str] = {m: "inlet" for m in named_in} | {m: "outlet" for m in named_out}
    fluxes: dict[str, float] = {}
    for m in ms:
        if wind is not None:
            flux, _ = _inward_flux(openings[m], provisional, wind)
            fluxes[m.name] = round(flux * grid.resolution, 6)
            kinds.setdefault(m, "inlet" if flux > 0 else "outlet")
    unnamed = [m.name for m in ms if m not in kinds]
    if unnamed:
        raise InputDataError(
            f"cannot tell inlets from outlets without a wind file: name {', '.join(unnamed)} "
            "with --inlet FILE or --outlet FILE"
        )
    ins = [m for m in ms if kinds[m] == "inlet"]
    outs = [m for m in ms if kinds[m] == "outlet"]
    if not ins or not outs:
        missing = "inlet" if not ins else "outlet"
        raise InputDataError(
            f"no {missing} among the outlet models ({', '.join(m.name for m in ms)}"
            + (f"; wind flux into the map, m^2/s: {fluxes}" if fluxes else "")
            + f"): name one with --{missing} FILE"
        )
    layout = layout_from_floorplan(
        fp,
        None,
        [openings[m] for m in ins],
        [openings[m] for m in outs],
        name=name or d.resolve().name,
        carve_depth_m=carve_depth_m,
    )
    src_xy = (sx - origin[0], sy - origin[1])
    _check_free(layout, src_xy, origin, "source", "" if src_file is None else str(src_file))
    start_xy = None
    if st is not None:
        start_xy = (st[0] - origin[0], st[1] - origin[1])
        _check_free(layout, start_xy, origin, "start", "" if start_file is None else str(start_file))
    if wind is not None:
        wind = np.where(layout.free, wind, 0.0)
    speed = None
    if wind is not None:
        speeds = []
        for m in ins:
            f, n = _inward_flux(openings[m], layout, wind)
            if n:
                speeds.append(f / n)
        speed = max(float(np.mean(speeds)), 0.0) if speeds else None

    def rel(p: Path | None) -> str | None:
        if p is None:
            return None
        try:
            return str(p.resolve().relative_to(d.resolve()))
        except ValueError:
            return str(p)

    files = {
        "directory": str(d),
        "map": rel(map_yaml),
        "settings": rel(settings_file),
        "simulation": rel(src_file),
        "scene": rel(start_file),
        "inlets": [rel(m) for m in ins],
        "outlets": [rel(m) for m in outs],
        "wind": [rel(w) for w in wind_paths],
    }
    if fluxes:
        files["inflow_m2_s"] = fluxes
    return GadenScenario(layout, src_xy, float(sz), start_xy, origin, wind, z, speed, files)


def import_gaden_scenario(
    directory: str | Path,
    out: str | Path,
    *,
    solve: bool = False,
    inlet_velocity: float | None = None,
    release_rate: float | None = None,
    engine: str = "builtin",
    **options: Any,
) -> tuple[Path, GadenScenario]:
    """Read a scenario folder (:func:`load_gaden_scenario`'s ``options``) and write it to ``out``.

    Without ``solve`` ``out`` is a layout file; with it, a case file solved by
    ``engine`` with ``inlet_velocity`` (default: the wind's inflow speed at the
    inlets) and ``release_rate`` (g/s, required).  Both keep
    :meth:`GadenScenario.meta` in their ``meta``.

    Returns:
        The path written and the scenario.
    """
    from dgse.world.layout_io import save_layout

    sc = load_gaden_scenario(directory, **options)
    if not solve:
        return save_layout(sc.layout, out, meta=sc.meta()), sc
    from dgse.physics.scenario import solve_cases

    v = sc.inlet_speed if inlet_velocity is None else float(inlet_velocity)
    if v is None or not (math.isfinite(v) and v > 0):
        raise InputDataError(
            "a case needs an inlet speed: give --inlet-velocity (the scenario's wind gives "
            + ("none" if sc.inlet_speed is None else f"{sc.inlet_speed:g} m/s")
            + ")"
        )
    if release_rate is None or not (math.isfinite(release_rate) and release_rate > 0):
        raise InputDataError(f"a case needs a positive release rate: give --rate (g/s), got {release_rate}")
    [case] = solve_cases(sc.layout, v, [(sc.source, float(release_rate))], engine, name=sc.layout.name)
    case = case.with_meta(name=sc.layout.name, **sc.meta())
    return case.save(out), sc


# -- writing --------------------------------------------------------------------------------------
def box_triangles(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float) -> np.ndarray:
    """The 12 triangles ``(12, 3, 3)`` of the axis-aligned box ``[x0, x1] x [y0, y1] x [z0, z1]``, m."""
    c = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.stack([c[[a, b, d]] for a, b, _, d in quads] + [c[[b, e, d]] for _, b, e, d in quads])


def write_stl(path: str | Path, triangles: np.ndarray, *, binary: bool = False, name: str = "model") -> Path:
    """Write ``triangles`` ``(n, 3, 3)`` (m) as an STL model, ASCII or ``binary``; :func:`read_stl`
    reads it back (a binary file's header starts with ``solid`` too, as some exporters write it)."""
    from dgse.files import write_bytes, write_text

    tris = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if binary:
        records = np.zeros(tris.shape[0], dtype=_BINARY_STL)
        records["v"] = tris
        header = f"solid {name}".encode("ascii").ljust(80, b" ")[:80]
        return write_bytes(path, header + np.uint32(tris.shape[0]).tobytes() + records.tobytes())
    lines = [f"solid {name}"]
    for t in tris:
        lines += ["  facet normal 0 0 0", "    outer loop"]
        lines += [f"      vertex {v[0]:.6f} {v[1]:.6f} {v[2]:.6f}" for v in t]
        lines += ["    endloop", "  endfacet"]
    return write_text(path, "\n".join([*lines, f"endsolid {name}", ""]))


def write_wind_csv(path: str | Path, points: np.ndarray, wind: np.ndarray) -> Path:
    """Write points ``(n, 3)`` (m) and winds ``(n, 3)`` (m/s) as ParaView's cell-centre CSV export
    (header ``"U:0","U:1","U:2","Points:0","Points:1","Points:2"``); :func:`read_wind_csv` reads it."""
    import io

    from dgse.files import write_text

    pts, u = np.asarray(points, dtype=np.float64), np.asarray(wind, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or u.shape != pts.shape:
        raise InputDataError(f"points and winds must both be (n, 3), got {pts.shape} and {u.shape}")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    header = '"U:0","U:1","U:2","Points:0","Points:1","Points:2"'
    np.savetxt(buf, np.column_stack([u, pts]), delimiter=",", header=header, comments="", fmt="%.6f")
    return write_text(path, buf.getvalue())


#: Where :func:`export_gaden_scenario` writes the parts of a folder (GADEN's ``test_env`` layout).
EXPORT_CONFIG = Path("environment_configurations") / "config1"
EXPORT_SIMULATION = EXPORT_CONFIG / "simulations" / "sim1" / "sim.yaml"
EXPORT_WIND = Path("wind_simulations") / "steady"


def export_gaden_scenario(
    case: Any,
    directory: str | Path,
    *,
    origin: tuple[float, float] = (0.0, 0.0),
    source_z: float = 0.5,
    wind: bool = True,
    start: tuple[float, float] | None = None,
) -> Path:
    """Write ``case`` (a :class:`~dgse.world.case.Case`) as a GADEN scenario folder that
    :func:`load_gaden_scenario` reads back; return the folder.

    The folder holds (positions in the map frame, where the map's lower-left corner lies at
    ``origin``; parent folders are made):

    * ``occupancy.yaml`` + ``occupancy.pgm``: the occupancy, one pixel per cell
      (:func:`~dgse.world.floorplan.export_ros_map`);
    * ``cad_models/opening_<k>.stl``: one box per inlet and outlet (ASCII STL), one cell deep at
      the map's edge and 2 m high, listed under ``outlets_models`` of
      ``environment_configurations/config1/config.yaml`` (GADEN names every opening an outlet:
      the importer tells inlets from outlets by the wind, or by name without one);
    * ``environment_configurations/config1/simulations/sim1/sim.yaml``: the source
      (``source: position: [x, y, source_z]``) and the case's release rate;
    * with ``wind``, ``wind_simulations/steady/wind_at_cell_centers_0.csv``: the case's wind at
      the free cells' centres at height ``source_z`` (ParaView's CSV, :func:`write_wind_csv`),
      named by ``unprocessed_wind_files`` of the configuration;
    * with ``start`` (grid frame, m), ``scene.yaml``: one robot there (BasicSim's scene).

    Raises:
        InputDataError: a case without openings in its ``meta``.
    """
    from dgse.files import write_text
    from dgse.world.floorplan import export_ros_map

    d = Path(directory)
    layout = case.layout
    g = layout.grid
    res = g.resolution
    ox, oy = (float(v) for v in origin)
    export_ros_map(layout, d / "occupancy.yaml", origin=(ox, oy))
    (d / EXPORT_CONFIG).mkdir(parents=True, exist_ok=True)
    (d / EXPORT_SIMULATION).parent.mkdir(parents=True, exist_ok=True)
    # an opening's box: one cell deep inside the map at its side, a quarter cell short of its ends
    # along the side, so that its footprint is nearest to its own side even at a corner
    inset = 0.25 * res
    models = []
    for k, o in enumerate((*layout.inlets, *layout.outlets)):
        a, b = o.start_m + inset, o.end_m - inset
        x0, x1, y0, y1 = {
            "west": (0.0, res, a, b),
            "east": (g.width_m - res, g.width_m, a, b),
            "south": (a, b, 0.0, res),
            "north": (a, b, g.height_m - res, g.height_m),
        }[o.side]
        name = f"opening_{k}.stl"
        write_stl(d / "cad_models" / name, box_triangles(x0 + ox, x1 + ox, y0 + oy, y1 + oy, 0.0, 2.0))
        models.append(f"../../cad_models/{name}")
    config = ["outlets_models:", *(f"  - {m}" for m in models)]
    if wind:
        config.append(f"unprocessed_wind_files: ../../{EXPORT_WIND.as_posix()}/wind_at_cell_centers")
    config.append(f"cell_size: {res!r}")
    write_text(d / EXPORT_CONFIG / "config.yaml", "\n".join(config) + "\n")
    sx, sy = (float(v) for v in case.source)
    sim = [
        "source:",
        "  sourceType: point",
        f"  position: [{sx + ox!r}, {sy + oy!r}, {float(source_z)!r}]",
        "  gasType: 0",
    ]
    if "release_rate_gps" in case.meta:
        sim.append(f"releaseRate: {float(case.meta['release_rate_gps'])!r}")
    write_text(d / EXPORT_SIMULATION, "\n".join(sim) + "\n")
    if wind:
        i, j = np.nonzero(layout.free)
        pts = np.column_stack([(j + 0.5) * res + ox, (i + 0.5) * res + oy, np.full(i.size, float(source_z))])
        u = np.column_stack([case.wind[0, i, j], case.wind[1, i, j], np.zeros(i.size)])
        write_wind_csv(d / EXPORT_WIND / "wind_at_cell_centers_0.csv", pts, u)
    if start is not None:
        x, y = (float(v) for v in start)
        scene = [
            'map: "occupancy.yaml"',
            "robots:",
            '  - name: "robot"',
            f"    position: [{x + ox!r}, {y + oy!r}, 0.0]",
        ]
        write_text(d / "scene.yaml", "\n".join(scene) + "\n")
    return d
