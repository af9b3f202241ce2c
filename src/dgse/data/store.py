"""The dataset store: many cases in one compact, chunked HDF5 file.

Why HDF5 (h5py) and not Zarr
----------------------------
* **One file.**  A dataset of 3,750 layouts x 4 sources is one ``.h5`` file that
  is copied, checksummed, archived and mounted as one object; a Zarr directory
  store is tens of thousands of small chunk files (slow on network file
  systems, awkward to move, easy to copy half of).
* **Snapshot commits by rename.**  Because the store is one file, a whole batch
  of new layouts is committed by writing them into a copy of the file and
  ``os.replace``-ing it over the original (see :func:`commit_pending`): a
  reader, or a generator killed at any moment, only ever sees the previous or
  the next complete file.  HDF5 is *not* crash safe when it is modified in
  place (a process killed in the middle of a metadata flush can leave an
  unreadable file), so the long-running generator never modifies the store in
  place; Zarr would need a transaction layer of its own for the same guarantee.
* **Layout-level groups with appends.**  Layouts differ in shape; HDF5 groups
  hold per-layout datasets of any shape plus attributes, appended one group at
  a time.  (SWMR, HDF5's single-writer/multiple-reader mode, only appends to
  existing datasets and cannot create groups, so it does not fit per-layout
  groups; snapshot commits give readers the same consistency.)
* **Portable compression.**  gzip + shuffle is built into every HDF5 reader (no
  plugins), stores the float32 fields losslessly at about 2/3 of their raw size,
  and decompresses a layout in about a millisecond.

File layout (``format = "dgse-dataset"``, ``format_version = 1``)::

    /                      attrs: format, format_version, created, generation (JSON)
    /layouts/<layout_id>/  attrs: split, layout_index (-1 if none), n_sources,
                                  resolution (float64), summary (JSON)
        occupancy          uint8   (H, W)        gzip
        wind               float32 (2, H, W)     gzip + shuffle, one chunk
        concentration      float32 (S, H, W)     gzip + shuffle, chunk (1, H, W)
        source             float32 (S, 2)        (x, y) in m
        meta               str     (S,)          the case's meta as JSON
        frames/<k>         float32 (T, H, W)     optional, source k's frames
    /failures/<layout_id>  attrs: the failure record (layout_index, seed, reason, ...)
    /fixed/<split>/        fixed sensor configurations (see FixedConfigurations)
    /_staging/             groups being written (never read)

Every case of a layout shares its occupancy, wind and resolution; the
concentration, source, meta and frames are per source.  :meth:`DatasetStore.case`
returns a :class:`~dgse.world.case.Case` equal (arrays bit for bit, meta after
a JSON round trip, as :meth:`Case.save`/:meth:`Case.load` give it) to the one
that was added.

Writes
------
:meth:`DatasetStore.add_layout` writes a layout group under ``/_staging/``,
moves it to ``/layouts/<id>`` (a single link operation) and flushes: a reader
never sees a half-written layout.  For kill-safety the generator instead
stages finished layouts as small files in the journal directory
``<store>.pending/`` (:class:`Journal`, each written to a temporary name,
fsynced and renamed) and :func:`commit_pending` moves them into a copy of the
store that then replaces the original.

Errors: a missing, corrupt or foreign file, or a missing layout, raises
:class:`~dgse.errors.InputDataError` naming the file and the problem.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import math
import os
import re
import shutil
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dgse.errors import DGSEError, InputDataError
from dgse.files import atomic_path, expand_paths, is_temporary, write_json
from dgse.world.case import Case

__all__ = [
    "DEFAULT_SPLIT_FRACTIONS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "SENSOR_COUNTS",
    "SPLITS",
    "STORE_SUFFIXES",
    "DatasetStore",
    "FixedConfigurations",
    "Journal",
    "SensorConfiguration",
    "assign_splits",
    "check_store_path",
    "commit_pending",
    "split_counts",
]

FORMAT_NAME = "dgse-dataset"
FORMAT_VERSION = 1
#: Splits, in the order their shares are laid out over the permuted layouts.
SPLITS = ("train", "val", "test")
#: The paper's layout-level split: 3000 / 500 / 250 of 3750 layouts.
DEFAULT_SPLIT_FRACTIONS: dict[str, float] = {"train": 12 / 15, "val": 2 / 15, "test": 1 / 15}
#: Sensor counts of a configuration (paper Sec. IV): 5, 10, ..., 300.
SENSOR_COUNTS = np.arange(5, 301, 5)
#: Fixed sensor configurations per environment for validation and test (paper Sec. IV).
DEFAULT_CONFIGS_PER_ENV = 30

#: The names a new store file may have (an HDF5 file).
STORE_SUFFIXES = (".h5", ".hdf5")

_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,127}$")
_TAG_SPLIT = 0x5B11
_TAG_FIXED = 0xF1ED
_COMPRESSIONS = ("gzip", "lzf")


# -- splits ------------------------------------------------------------------------------------
def _check_fractions(fractions: Mapping[str, float] | None) -> dict[str, float]:
    fr = dict(DEFAULT_SPLIT_FRACTIONS if fractions is None else fractions)
    unknown = sorted(set(fr) - set(SPLITS))
    if unknown:
        raise InputDataError(f"unknown split(s) {', '.join(unknown)}: use {', '.join(SPLITS)}")
    vals = [float(fr.get(s, 0.0)) for s in SPLITS]
    if any(not (v >= 0 and math.isfinite(v)) for v in vals) or not math.isclose(sum(vals), 1.0, abs_tol=1e-6):
        raise InputDataError(f"split fractions must be >= 0 and sum to 1, got {fr}")
    return dict(zip(SPLITS, vals, strict=True))


def split_counts(n: int, fractions: Mapping[str, float] | None = None) -> dict[str, int]:
    """Layouts per split for ``n`` layouts: largest-remainder rounding of ``n * fraction``.

    With ``n`` at least the number of splits with a positive fraction, every such
    split gets at least one layout (taken from the largest).  The paper's
    fractions give 3000 / 500 / 250 for ``n = 3750``.
    """
    fr = _check_fractions(fractions)
    if n < 0:
        raise InputDataError(f"number of layouts must be >= 0, got {n}")
    exact = {s: n * fr[s] for s in SPLITS}
    counts = {s: math.floor(exact[s] + 1e-9) for s in SPLITS}
    rest = n - sum(counts.values())
    for s in sorted(SPLITS, key=lambda s: (-(exact[s] - counts[s]), SPLITS.index(s)))[:rest]:
        counts[s] += 1
    positive = [s for s in SPLITS if fr[s] > 0]
    if n >= len(positive):
        for s in positive:
            if counts[s] == 0:
                donor = max(positive, key=lambda d: counts[d])
                counts[donor] -= 1
                counts[s] += 1
    return counts


def assign_splits(n: int, seed: int = 0, fractions: Mapping[str, float] | None = None) -> list[str]:
    """The split of each of ``n`` layouts (index order), deterministic given ``seed``.

    A seeded random permutation of the indices is cut into consecutive blocks of
    :func:`split_counts` sizes (train, val, test).  The assignment depends on
    ``(n, seed, fractions)`` only, never on which layouts exist or their order
    of completion.
    """
    counts = split_counts(n, fractions)
    perm = np.random.default_rng(np.random.SeedSequence([_check_seed(seed), _TAG_SPLIT])).permutation(n)
    out = [""] * n
    start = 0
    for s in SPLITS:
        for i in perm[start : start + counts[s]]:
            out[int(i)] = s
        start += counts[s]
    return out


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputDataError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_split(split: str) -> str:
    if split not in SPLITS:
        raise InputDataError(f"unknown split {split!r}: use one of {', '.join(SPLITS)}")
    return split


def _check_id(layout_id: str) -> str:
    if not isinstance(layout_id, str) or not _ID_RE.match(layout_id):
        raise InputDataError(
            f"bad layout id {layout_id!r}: use 1-128 characters of letters, digits and _.+- "
            "starting with a letter or digit"
        )
    return layout_id


def _id_entropy(layout_id: str) -> int:
    """A stable 64-bit integer of a layout id (for seeding per-layout draws)."""
    return int.from_bytes(hashlib.sha256(layout_id.encode()).digest()[:8], "little")


# -- fixed sensor configurations ---------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SensorConfiguration:
    """One fixed sensor configuration of an environment.

    Attributes:
        cells: ``int64 (n, 2)`` distinct free cells ``(i, j)`` (row, column), in the
            order they were drawn (as :func:`dgse.sensing.sensors.measure` takes them).
        noise_seed: seed of the measurement noise of this configuration (the
            noise model draws its ``alpha``/``sigma`` and per-sensor noise from
            ``numpy.random.default_rng(noise_seed)``).
    """

    cells: np.ndarray
    noise_seed: int

    @property
    def n_sensors(self) -> int:
        return int(self.cells.shape[0])

    def __repr__(self) -> str:
        return f"SensorConfiguration(n_sensors={self.n_sensors}, noise_seed={self.noise_seed})"

    def positions(self, resolution: float) -> np.ndarray:
        """``float (n, 2)`` sensor positions ``(x, y)`` in m (cell centres)."""
        return (self.cells[:, ::-1].astype(np.float64) + 0.5) * float(resolution)

    def rng(self) -> np.random.Generator:
        """A fresh generator of this configuration's noise."""
        return np.random.default_rng(self.noise_seed)


@dataclass(frozen=True, eq=False)
class FixedConfigurations:
    """The fixed sensor configurations of one split: ``n_per_env`` per environment.

    An environment is a ``(layout_id, source_index)`` pair.  Configuration ``k``
    of environment ``e`` has ``n_sensors[e, k]`` sensors at
    ``cells[offsets[e * n_per_env + k] : offsets[e * n_per_env + k + 1]]`` and
    noise seed ``noise_seeds[e, k]``.  The draws of an environment depend only on
    ``(seed, layout_id, source_index)``: the sensor count uniform over
    :data:`SENSOR_COUNTS` (capped at the number of free cells), the cells uniform
    over the free cells without replacement, the noise seed uniform in
    ``[0, 2**63)``.
    """

    split: str
    seed: int
    n_per_env: int
    envs: tuple[tuple[str, int], ...]
    n_sensors: np.ndarray  # int32 (E, n_per_env)
    noise_seeds: np.ndarray  # uint64 (E, n_per_env)
    offsets: np.ndarray  # int64 (E * n_per_env + 1,)
    cells: np.ndarray  # int32 (total, 2)

    def __len__(self) -> int:
        return len(self.envs) * self.n_per_env

    def env_index(self, layout_id: str, source_index: int) -> int:
        try:
            return self._index[(layout_id, int(source_index))]
        except KeyError:
            raise InputDataError(
                f"no fixed configurations for environment ({layout_id!r}, source {source_index}) "
                f"in split {self.split!r}"
            ) from None

    @property
    def _index(self) -> dict[tuple[str, int], int]:
        cached = self.__dict__.get("_index_cache")
        if cached is None:
            cached = {env: e for e, env in enumerate(self.envs)}
            object.__setattr__(self, "_index_cache", cached)
        return cached

    def get(self, layout_id: str, source_index: int, k: int) -> SensorConfiguration:
        """Configuration ``k`` of environment ``(layout_id, source_index)``."""
        e = self.env_index(layout_id, source_index)
        if not 0 <= k < self.n_per_env:
            raise InputDataError(f"configuration index {k} out of range 0..{self.n_per_env - 1}")
        n = e * self.n_per_env + k
        return SensorConfiguration(
            self.cells[self.offsets[n] : self.offsets[n + 1]].astype(np.int64),
            int(self.noise_seeds[e, k]),
        )

    def for_env(self, layout_id: str, source_index: int) -> list[SensorConfiguration]:
        """The ``n_per_env`` configurations of an environment."""
        return [self.get(layout_id, source_index, k) for k in range(self.n_per_env)]

    def __iter__(self) -> Iterator[tuple[str, int, int, SensorConfiguration]]:
        """``(layout_id, source_index, k, configuration)`` for every configuration."""
        for layout_id, src in self.envs:
            for k in range(self.n_per_env):
                yield layout_id, src, k, self.get(layout_id, src, k)


def _draw_env_configs(
    occupancy: np.ndarray, seed: int, layout_id: str, source_index: int, n_per_env: int
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    rng = np.random.default_rng(
        np.random.SeedSequence([seed, _TAG_FIXED, _id_entropy(layout_id), int(source_index)])
    )
    W = occupancy.shape[1]
    free = np.flatnonzero(occupancy.reshape(-1) == 0)
    counts = np.empty(n_per_env, dtype=np.int32)
    seeds = np.empty(n_per_env, dtype=np.uint64)
    cells = []
    for k in range(n_per_env):
        n = min(int(rng.choice(SENSOR_COUNTS)), free.size)
        pick = rng.choice(free, size=n, replace=False)
        cells.append(np.stack([pick // W, pick % W], axis=1).astype(np.int32))
        counts[k] = n
        seeds[k] = rng.integers(0, 2**63, dtype=np.uint64)
    return counts, seeds, cells


# -- helpers -----------------------------------------------------------------------------------
def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):  # not every file system supports it
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _json_attr(value: Any) -> str:
    try:
        return json.dumps(value, allow_nan=True)
    except (TypeError, ValueError) as e:
        raise InputDataError(f"not JSON-serializable: {e}") from None


def _same_layout(a: Case, b: Case) -> bool:
    return (
        a.occupancy.shape == b.occupancy.shape
        and a.resolution == b.resolution
        and np.array_equal(a.occupancy, b.occupancy)
        and np.array_equal(a.wind, b.wind)
    )


def _case_summary(case: Case) -> dict[str, Any]:
    free = case.occupancy == 0
    conc = case.concentration[free]
    return {
        "max_ppm": float(conc.max(initial=0.0)),
        "mean_ppm": float(conc.mean()) if conc.size else 0.0,
        "release_rate_gps": _num(case.meta.get("release_rate_gps")),
        "source_xy_m": [float(case.source[0]), float(case.source[1])],
        "frames": 0 if case.frames is None else int(case.frames.shape[0]),
    }


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _layout_summary(cases: Sequence[Case]) -> dict[str, Any]:
    c0 = cases[0]
    H, W = c0.occupancy.shape
    speed = np.hypot(c0.wind[0], c0.wind[1])[c0.occupancy == 0]
    return {
        "shape": [int(H), int(W)],
        "width_m": W * c0.resolution,
        "height_m": H * c0.resolution,
        "free_fraction": float((c0.occupancy == 0).mean()),
        "inlet_velocity": _num(c0.meta.get("inlet_velocity")),
        "max_speed": float(speed.max(initial=0.0)),
        "mean_speed": float(speed.mean()) if speed.size else 0.0,
        "sources": [_case_summary(c) for c in cases],
    }


def _write_layout(
    parent: h5py.Group,
    name: str,
    cases: Sequence[Case],
    split: str,
    layout_index: int,
    compression: str,
) -> h5py.Group:
    """Write a layout group ``parent/name`` (which must not exist) of ``cases``."""
    c0 = cases[0]
    H, W = c0.occupancy.shape
    S = len(cases)
    fl = {"compression": compression, "shuffle": True}
    if compression == "gzip":
        fl["compression_opts"] = 4
    g = parent.create_group(name)
    g.create_dataset("occupancy", data=c0.occupancy, chunks=(H, W), compression=compression)
    g.create_dataset("wind", data=c0.wind, chunks=(2, H, W), **fl)
    g.create_dataset(
        "concentration",
        data=np.stack([c.concentration for c in cases]),
        chunks=(1, H, W),
        **fl,
    )
    g.create_dataset("source", data=np.stack([c.source for c in cases]).astype(np.float32))
    metas = [_json_attr(c.meta) for c in cases]
    g.create_dataset("meta", data=metas, dtype=h5py.string_dtype("utf-8"))
    for k, c in enumerate(cases):
        if c.frames is not None:
            g.require_group("frames").create_dataset(str(k), data=c.frames, chunks=(1, H, W), **fl)
    g.attrs["split"] = split
    g.attrs["layout_index"] = int(layout_index)
    g.attrs["n_sources"] = S
    g.attrs["resolution"] = float(c0.resolution)
    g.attrs["summary"] = _json_attr(_layout_summary(cases))
    return g


def _read_all(name: str, obj: Any) -> None:
    """Read a dataset whole (``visititems``), attributes included: HDF5 raises on damaged data."""
    dict(obj.attrs)
    if isinstance(obj, h5py.Dataset):
        obj[()]


def _layout_problem(g: h5py.Group) -> str | None:
    """What is wrong with a layout group's arrays (None: nothing); HDF5 errors propagate."""
    a = g.attrs
    summary = json.loads(a["summary"])
    S, res = int(a["n_sources"]), float(a["resolution"])
    H, W = (int(v) for v in summary["shape"])
    occ, wind, conc = g["occupancy"][()], g["wind"][()], g["concentration"][()]
    source, meta = g["source"][()], [json.loads(m) for m in g["meta"].asstr()[()]]
    expected = {
        "occupancy": (occ.shape, (H, W)),
        "wind": (wind.shape, (2, H, W)),
        "concentration": (conc.shape, (S, H, W)),
        "source": (source.shape, (S, 2)),
        "meta": ((len(meta),), (S,)),
    }
    for key, (got, want) in expected.items():
        if tuple(got) != want:
            return f"{key} has shape {tuple(got)}, the layout's summary says {want}"
    if not np.isin(occ, (0, 1)).all():
        return "occupancy holds values other than 0 and 1"
    for key, arr in (("wind", wind), ("concentration", conc)):
        if not np.isfinite(arr).all():
            return f"{key} holds non-finite values"
    if not (np.isfinite(source).all() and (source >= 0).all() and (source <= (W * res, H * res)).all()):
        return "a source lies outside the map"
    if not all(isinstance(m, dict) for m in meta):
        return "a case's meta is not a JSON object"
    if "frames" in g:
        for k, frames in g["frames"].items():
            if frames.shape[1:] != (H, W) or not np.isfinite(frames[()]).all():
                return f"frames of source {k} have shape {frames.shape} or non-finite values"
    return None


def _prepare_cases(cases: Sequence[Case] | Iterable[Case]) -> list[Case]:
    out = list(cases)
    if not out:
        raise InputDataError("a layout needs at least one case")
    for c in out:
        if not isinstance(c, Case):
            raise InputDataError(f"expected Case objects, got {type(c).__name__}")
    for k, c in enumerate(out[1:], start=1):
        if not _same_layout(out[0], c):
            raise InputDataError(
                f"case {k} ({c.name}) does not share the occupancy, wind and resolution of "
                f"case 0 ({out[0].name}); the cases of one layout must"
            )
    return out


# -- the store ---------------------------------------------------------------------------------
def check_store_path(path: str | Path) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it names a store file to create: ``*.h5`` or ``*.hdf5``.

    Raises:
        InputDataError: another suffix (``x.txt``), or a folder.
    """
    path = Path(path)
    if path.is_dir():
        raise InputDataError(f"{path} is a folder; give the dataset store's file name (*.h5)")
    if path.suffix.lower() not in STORE_SUFFIXES:
        raise InputDataError(
            f"{path}: a dataset store is an HDF5 file; give it a name ending in "
            + " or ".join(STORE_SUFFIXES)
        )
    return path


class DatasetStore:
    """Many cases in one HDF5 file, grouped by layout (see the module docstring).

    Args:
        path: the ``.h5`` file.
        mode: ``"r"`` read only (default), ``"r+"`` read/write an existing store,
            ``"a"`` read/write, creating the store if missing, ``"w"`` create
            (truncating an existing file), ``"x"`` create, failing if it exists.
        compression: ``"gzip"`` (level 4, with shuffle; default) or ``"lzf"`` for
            layouts written through this object.

    Raises:
        InputDataError: the file is missing (``r``/``r+``), not HDF5, corrupt, not
            a DGSE dataset store, of a newer format, or locked by a writer.

    Use as a context manager or call :meth:`close`.
    """

    def __init__(self, path: str | Path, mode: str = "r", *, compression: str = "gzip") -> None:
        self.path = Path(path)
        if mode not in ("r", "r+", "a", "w", "x"):
            raise InputDataError(f"unknown store mode {mode!r}: use r, r+, a, w or x")
        if compression not in _COMPRESSIONS:
            raise InputDataError(f"unknown compression {compression!r}: use gzip or lzf")
        self.mode = mode
        self.compression = compression
        if self.path.is_dir():
            raise InputDataError(f"{self.path} is a directory, not a dataset store file")
        exists = self.path.exists()
        if mode in ("r", "r+") and not exists:
            raise InputDataError(f"{self.path}: no such dataset store")
        if mode == "x" and exists:
            raise InputDataError(f"{self.path} already exists")
        if mode in ("w", "x") or (mode == "a" and not exists):
            check_store_path(self.path)
        if mode != "r":
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._f = h5py.File(self.path, mode)
        except (OSError, ValueError) as e:
            raise InputDataError(f"{self.path}: cannot open as an HDF5 dataset store ({_short(e)})") from None
        try:
            self._init_or_check(new=not exists or mode == "w")
        except BaseException:
            self._f.close()
            raise

    def _init_or_check(self, new: bool) -> None:
        a = self._f.attrs
        if new:
            a["format"] = FORMAT_NAME
            a["format_version"] = FORMAT_VERSION
            a["created"] = _now()
            self._f.require_group("layouts")
            self._f.require_group("failures")
            self._f.flush()
            return
        with self._guard():
            fmt = a.get("format")
            if isinstance(fmt, bytes):
                fmt = fmt.decode()
            if fmt != FORMAT_NAME or "layouts" not in self._f:
                raise InputDataError(
                    f"{self.path} is an HDF5 file but not a DGSE dataset store (format attribute {fmt!r})"
                )
            version = int(a.get("format_version", 0))
            if version > FORMAT_VERSION:
                raise InputDataError(
                    f"{self.path} has store format version {version}; this DGSE reads up to "
                    f"{FORMAT_VERSION} (upgrade DGSE)"
                )
            if self.writable:
                self._f.require_group("failures")
                if "_staging" in self._f:  # left by an interrupted in-place write
                    del self._f["_staging"]
                    self._f.flush()

    # -- basics -------------------------------------------------------------------------------
    @property
    def writable(self) -> bool:
        return self.mode != "r"

    def close(self) -> None:
        """Flush and close the file (idempotent)."""
        if getattr(self, "_f", None) is not None and self._f.id.valid:
            with contextlib.suppress(Exception):
                if self.writable:
                    self._f.flush()
            self._f.close()

    def __enter__(self) -> DatasetStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "open" if self._f.id.valid else "closed"
        return f"DatasetStore({str(self.path)!r}, mode={self.mode!r}, {state})"

    def flush(self) -> None:
        self._f.flush()

    @contextlib.contextmanager
    def _guard(self, what: str = "") -> Iterator[None]:
        """Turn HDF5 failures (corrupt data, missing objects) into InputDataError."""
        try:
            yield
        except DGSEError:
            raise
        except (OSError, KeyError, ValueError, RuntimeError) as e:
            where = f" ({what})" if what else ""
            raise InputDataError(
                f"{self.path}: corrupt or unreadable dataset store{where}: {_short(e)}"
            ) from None

    def _require_writable(self) -> None:
        if not self.writable:
            raise InputDataError(f"{self.path} is open read-only (open it with mode 'a' or 'r+')")

    @property
    def generation_info(self) -> dict[str, Any]:
        """The generation parameters recorded by :func:`dgse.data.generation.generate` ({} if none)."""
        raw = self._f.attrs.get("generation")
        if raw is None:
            return {}
        with self._guard("generation attribute"):
            return dict(json.loads(raw))

    def set_generation_info(self, info: Mapping[str, Any]) -> None:
        self._require_writable()
        self._f.attrs["generation"] = _json_attr(dict(info))

    # -- layouts ------------------------------------------------------------------------------
    def _group(self, layout_id: str) -> h5py.Group:
        with self._guard():
            g = self._f["layouts"].get(layout_id)
        if g is None:
            raise InputDataError(f"{self.path}: no layout {layout_id!r} in the store")
        return g

    def layouts(self, split: str | None = None) -> list[str]:
        """Layout ids (sorted), all or of one split."""
        if split is not None:
            _check_split(split)
        with self._guard("layout list"):
            names = sorted(self._f["layouts"].keys())
            if split is None:
                return names
            return [n for n in names if self._f["layouts"][n].attrs["split"] == split]

    def __len__(self) -> int:
        with self._guard():
            return len(self._f["layouts"])

    def __contains__(self, layout_id: object) -> bool:
        with self._guard():
            return isinstance(layout_id, str) and layout_id in self._f["layouts"]

    def layout_info(self, layout_id: str) -> dict[str, Any]:
        """``split``, ``layout_index``, ``n_sources``, ``resolution`` and ``summary`` of a layout."""
        g = self._group(layout_id)
        with self._guard(f"layout {layout_id}"):
            a = g.attrs
            return {
                "layout_id": layout_id,
                "split": str(a["split"]),
                "layout_index": int(a["layout_index"]),
                "n_sources": int(a["n_sources"]),
                "resolution": float(a["resolution"]),
                "summary": json.loads(a["summary"]),
            }

    def n_sources(self, layout_id: str) -> int:
        with self._guard():
            return int(self._group(layout_id).attrs["n_sources"])

    def n_cases(self, split: str | None = None) -> int:
        return sum(self.n_sources(i) for i in self.layouts(split))

    @property
    def splits(self) -> dict[str, list[str]]:
        """``{split: [layout ids]}`` for train, val and test."""
        out: dict[str, list[str]] = {s: [] for s in SPLITS}
        with self._guard("splits"):
            for name, g in self._f["layouts"].items():
                out[str(g.attrs["split"])].append(name)
        return {s: sorted(v) for s, v in out.items()}

    def split_of(self, layout_id: str) -> str:
        with self._guard():
            return str(self._group(layout_id).attrs["split"])

    def reassign_splits(
        self, seed: int = 0, fractions: Mapping[str, float] | None = None
    ) -> dict[str, list[str]]:
        """Split all layouts anew: :func:`assign_splits` over the sorted layout ids."""
        self._require_writable()
        ids = self.layouts()
        for lid, s in zip(ids, assign_splits(len(ids), seed, fractions), strict=True):
            self._group(lid).attrs["split"] = s
        self._f.flush()
        return self.splits

    def layout_indices(self) -> set[int]:
        """Generation indices (``layout_index >= 0``) of the stored layouts."""
        with self._guard("layout indices"):
            idx = (int(g.attrs["layout_index"]) for g in self._f["layouts"].values())
            return {i for i in idx if i >= 0}

    def add_layout(
        self,
        cases: Sequence[Case] | Iterable[Case],
        split: str,
        layout_id: str | None = None,
        *,
        layout_index: int = -1,
    ) -> str:
        """Add one layout's cases (sharing occupancy, wind, resolution); returns its id.

        The id defaults to the cases' ``meta["layout"]`` when that is a valid, unused
        id, else ``layout-<n>``.  The group is written under ``/_staging`` and then
        moved into place and flushed, so it appears whole or not at all.

        Raises:
            InputDataError: cases that do not share a layout, an unknown split, an id
                already in the store, a read-only store.
        """
        self._require_writable()
        cases = _prepare_cases(cases)
        _check_split(split)
        if layout_id is None:
            layout_id = self._free_id(cases[0].meta.get("layout"))
        _check_id(layout_id)
        if layout_id in self:
            raise InputDataError(f"{self.path}: layout {layout_id!r} is already in the store")
        staging = self._f.require_group("_staging")
        if layout_id in staging:
            del staging[layout_id]
        _write_layout(staging, layout_id, cases, split, layout_index, self.compression)
        self._f.move(f"_staging/{layout_id}", f"layouts/{layout_id}")
        self._f.flush()
        return layout_id

    def _free_id(self, wanted: object) -> str:
        if isinstance(wanted, str) and _ID_RE.match(wanted) and wanted not in self:
            return wanted
        base = wanted if isinstance(wanted, str) and _ID_RE.match(wanted) else "layout"
        n = len(self)
        while f"{base}-{n}" in self:
            n += 1
        return f"{base}-{n}"

    def _copy_layout(self, source: h5py.Group, layout_id: str) -> None:
        """Copy a layout group (e.g. from a journal file) into the store under ``layout_id``."""
        staging = self._f.require_group("_staging")
        if layout_id in staging:
            del staging[layout_id]
        self._f.copy(source, staging, name=layout_id)
        self._f.move(f"_staging/{layout_id}", f"layouts/{layout_id}")

    # -- cases --------------------------------------------------------------------------------
    def case(self, layout_id: str, source_idx: int) -> Case:
        """The case of source ``source_idx`` of a layout (equal to the case that was added)."""
        g = self._group(layout_id)
        with self._guard(f"layout {layout_id}"):
            n = int(g.attrs["n_sources"])
            if not 0 <= int(source_idx) < n:
                raise InputDataError(
                    f"layout {layout_id!r} has {n} sources; source index {source_idx} out of range"
                )
            return self._read_case(g, int(source_idx), g["occupancy"][()], g["wind"][()])

    def layout_cases(self, layout_id: str) -> list[Case]:
        """All cases of a layout, in source order."""
        g = self._group(layout_id)
        with self._guard(f"layout {layout_id}"):
            occ, wind = g["occupancy"][()], g["wind"][()]
            return [self._read_case(g, k, occ, wind) for k in range(int(g.attrs["n_sources"]))]

    def _read_case(self, g: h5py.Group, k: int, occ: np.ndarray, wind: np.ndarray) -> Case:
        meta = json.loads(g["meta"].asstr()[k])
        frames = None
        if "frames" in g and str(k) in g["frames"]:
            frames = g["frames"][str(k)][()]
        try:
            return Case(
                occ,
                wind,
                g["concentration"][k],
                g["source"][k],
                float(g.attrs["resolution"]),
                meta,
                frames,
            )
        except InputDataError as e:
            raise InputDataError(f"{self.path}: layout {g.name}: invalid stored case: {e}") from None

    def iter_cases(self, split: str | None = None) -> Iterator[tuple[str, int, Case]]:
        """``(layout_id, source_idx, case)`` for every case (of one split), layout by layout."""
        for lid in self.layouts(split):
            for k, c in enumerate(self.layout_cases(lid)):
                yield lid, k, c

    # -- failures -----------------------------------------------------------------------------
    def add_failure(self, record: Mapping[str, Any], *, flush: bool = True) -> None:
        """Record a layout that could not be made (``layout_index``, ``seed``, ``reason``, ...).

        Stored as the attributes of ``/failures/<layout_id>`` (one record per layout;
        a new record replaces an old one).
        """
        self._require_writable()
        rec = dict(record)
        lid = _check_id(str(rec.get("layout_id") or f"layout-{int(rec['layout_index']):06d}"))
        rec["layout_id"] = lid
        fails = self._f.require_group("failures")
        if lid in fails:
            del fails[lid]
        g = fails.create_group(lid)
        g.attrs["record"] = _json_attr(rec)
        g.attrs["layout_index"] = int(rec.get("layout_index", -1))
        if flush:
            self._f.flush()

    def remove_failure(self, layout_id: str) -> None:
        self._require_writable()
        fails = self._f.require_group("failures")
        if layout_id in fails:
            del fails[layout_id]

    def verify(self) -> int:
        """Read every array of the store and check it against what the layout says; the layouts read.

        Decompressing every chunk finds damaged data (gzip checks its stream); the shapes are
        checked against each layout's summary and source count, the occupancy against 0/1, the
        fields for finite values and the sources for positions inside the map.  It reads the
        whole file (seconds per thousand layouts).

        Raises:
            InputDataError: naming the first damaged layout (or group) and what is wrong.
        """
        for lid in self.layouts():
            with self._guard(f"layout {lid}"):
                problem = _layout_problem(self._f["layouts"][lid])
            if problem:
                raise InputDataError(f"{self.path}: corrupt dataset store (layout {lid}): {problem}")
        for name in ("failures", "fixed"):
            if name in self._f:
                with self._guard(name):
                    self._f[name].visititems(_read_all)
        return len(self.layouts())

    def failures(self) -> list[dict[str, Any]]:
        """The failure records, sorted by layout id."""
        if "failures" not in self._f:
            return []
        with self._guard("failures"):
            return [json.loads(g.attrs["record"]) for _, g in sorted(self._f["failures"].items())]

    def failed_indices(self) -> set[int]:
        return {int(r["layout_index"]) for r in self.failures() if int(r.get("layout_index", -1)) >= 0}

    # -- fixed sensor configurations ----------------------------------------------------------
    def fixed_configurations(
        self,
        split: str,
        n_per_env: int | None = None,
        seed: int | None = None,
        *,
        overwrite: bool = False,
    ) -> FixedConfigurations:
        """The fixed sensor configurations of a split, stored in the store.

        Every environment (layout, source) of the split gets ``n_per_env``
        configurations (see :class:`FixedConfigurations` for the draws).  Stored
        configurations are returned as they are; environments added to the split
        since are drawn and stored too (the draws of an environment do not depend
        on the others, so existing ones never change).

        Args:
            split: ``"val"`` or ``"test"`` (``"train"`` works too).
            n_per_env: configurations per environment; default: the stored value,
                or 30 (paper Sec. IV).
            seed: default: the stored seed, or the generation seed, or 0.
            overwrite: replace stored configurations drawn with another
                ``seed``/``n_per_env`` instead of raising.

        In a read-only store, configurations that are not stored yet are drawn and
        returned without being stored.

        Raises:
            InputDataError: stored configurations with another seed or ``n_per_env``
                (without ``overwrite``).
        """
        _check_split(split)
        stored = self._read_fixed(split)
        if stored is not None:
            mismatch = (seed is not None and seed != stored.seed) or (
                n_per_env is not None and n_per_env != stored.n_per_env
            )
            if mismatch and not overwrite:
                raise InputDataError(
                    f"{self.path} holds fixed configurations for split {split!r} drawn with "
                    f"seed {stored.seed}, {stored.n_per_env} per environment; ask for those "
                    "(or pass overwrite=True to replace them)"
                )
            if mismatch:
                stored = None
            else:
                seed, n_per_env = stored.seed, stored.n_per_env
        if seed is None:
            seed = int(self.generation_info.get("seed", 0))
        seed = _check_seed(seed)
        n_per_env = DEFAULT_CONFIGS_PER_ENV if n_per_env is None else int(n_per_env)
        if n_per_env < 1:
            raise InputDataError(f"n_per_env must be at least 1, got {n_per_env}")

        wanted = [(lid, k) for lid in self.layouts(split) for k in range(self.n_sources(lid))]
        have: dict[tuple[str, int], int] = {} if stored is None else stored._index
        if stored is not None and list(have) == wanted:
            return stored
        # assemble: stored environments as they are, new ones drawn
        per_env: dict[tuple[str, int], tuple[np.ndarray, np.ndarray, list[np.ndarray]]] = {}
        occ_id, occ = "", np.zeros((0, 0), np.uint8)
        for env in wanted:
            if stored is not None and env in have:
                e = have[env]
                cells = [stored.get(*env, k).cells for k in range(n_per_env)]
                per_env[env] = (stored.n_sensors[e], stored.noise_seeds[e], cells)
                continue
            if env[0] != occ_id:
                with self._guard(f"layout {env[0]}"):
                    occ_id, occ = env[0], self._group(env[0])["occupancy"][()]
            per_env[env] = _draw_env_configs(occ, seed, env[0], env[1], n_per_env)
        envs = tuple(wanted)
        E = len(envs)
        n_sensors = np.zeros((E, n_per_env), dtype=np.int32)
        noise = np.zeros((E, n_per_env), dtype=np.uint64)
        all_cells: list[np.ndarray] = []
        for e, env in enumerate(envs):
            counts, seeds, cells = per_env[env]
            n_sensors[e] = counts
            noise[e] = seeds
            all_cells.extend(cells)
        sizes = np.array([c.shape[0] for c in all_cells], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        cells_arr = np.concatenate(all_cells).astype(np.int32) if all_cells else np.zeros((0, 2), np.int32)
        fixed = FixedConfigurations(split, seed, n_per_env, envs, n_sensors, noise, offsets, cells_arr)
        if self.writable:
            self._write_fixed(fixed)
        return fixed

    def has_fixed_configurations(self, split: str) -> bool:
        """True when stored fixed configurations cover every environment of ``split``."""
        stored = self._read_fixed(_check_split(split))
        if stored is None:
            return False
        wanted = [(lid, k) for lid in self.layouts(split) for k in range(self.n_sources(lid))]
        return list(stored.envs) == wanted

    def _write_fixed(self, fx: FixedConfigurations) -> None:
        staging = self._f.require_group("_staging")
        name = f"fixed-{fx.split}"
        if name in staging:
            del staging[name]
        g = staging.create_group(name)
        g.attrs["seed"] = fx.seed
        g.attrs["n_per_env"] = fx.n_per_env
        g.attrs["created"] = _now()
        g.create_dataset("env_layout", data=[e[0] for e in fx.envs], dtype=h5py.string_dtype("utf-8"))
        g.create_dataset("env_source", data=np.array([e[1] for e in fx.envs], dtype=np.int32))
        g.create_dataset("n_sensors", data=fx.n_sensors, compression="gzip")
        g.create_dataset("noise_seed", data=fx.noise_seeds, compression="gzip")
        g.create_dataset("offsets", data=fx.offsets, compression="gzip")
        g.create_dataset(
            "cells",
            data=fx.cells,
            compression="gzip",
            shuffle=True,
            # an empty split (no layouts) gets h5py's own chunking: newer h5py rejects
            # a chunk larger than the data in any dimension
            chunks=(min(fx.cells.shape[0], 65536), 2) if fx.cells.shape[0] else None,
        )
        fixed = self._f.require_group("fixed")
        if fx.split in fixed:
            del fixed[fx.split]
        self._f.move(f"_staging/{name}", f"fixed/{fx.split}")
        self._f.flush()

    def _read_fixed(self, split: str) -> FixedConfigurations | None:
        if "fixed" not in self._f or split not in self._f["fixed"]:
            return None
        with self._guard(f"fixed configurations of {split}"):
            g = self._f["fixed"][split]
            layouts = list(g["env_layout"].asstr()[()])
            sources = g["env_source"][()]
            return FixedConfigurations(
                split,
                int(g.attrs["seed"]),
                int(g.attrs["n_per_env"]),
                tuple((str(a), int(b)) for a, b in zip(layouts, sources, strict=True)),
                g["n_sensors"][()],
                g["noise_seed"][()],
                g["offsets"][()],
                g["cells"][()],
            )

    # -- export / import ----------------------------------------------------------------------
    def export(self, directory: str | Path, split: str | None = None) -> list[Path]:
        """Write every case (of one split) as a case file ``<layout_id>_src<k>.npz``.

        Also writes ``manifest.json``: ``{"layouts": {layout_id: {"split", "files"}}}``.
        Returns the case files written.
        """
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        written: list[Path] = []
        manifest: dict[str, Any] = {"format": "dgse-cases", "source_store": str(self.path), "layouts": {}}
        for lid in self.layouts(split):
            files = []
            for k, c in enumerate(self.layout_cases(lid)):
                p = c.save(d / f"{lid}_src{k}.npz")
                written.append(p)
                files.append(p.name)
            manifest["layouts"][lid] = {"split": self.split_of(lid), "files": files}
        write_json(d / "manifest.json", manifest, indent=1)
        return written

    def import_cases(self, paths: Iterable[str | Path], split: str = "train") -> list[str]:
        """Add case files (or directories of them) to the store; returns the new layout ids.

        Cases are grouped into layouts: cases with identical occupancy, wind and
        resolution and the same ``meta["layout"]`` form one layout, ordered by
        ``meta["source_index"]`` where every case has one (else in the given
        order).  The layout id is ``meta["layout"]`` when free.  A layout whose
        cases are already stored under that id, identical, is skipped (so
        importing twice adds nothing).  Directories contribute their ``*.npz``
        files in sorted order.
        """
        self._require_writable()
        _check_split(split)
        files = expand_paths(paths, lambda q: q.suffix == ".npz", "case")
        groups: dict[tuple, list[Case]] = {}
        for f in files:
            case = Case.load(f)
            key = (
                str(case.meta.get("layout", "")),
                case.occupancy.shape,
                case.resolution,
                hashlib.sha256(case.occupancy.tobytes() + case.wind.tobytes()).hexdigest(),
            )
            groups.setdefault(key, []).append(case)
        added: list[str] = []
        for key, cases in groups.items():
            if all(isinstance(c.meta.get("source_index"), int) for c in cases):
                cases = sorted(cases, key=lambda c: int(c.meta["source_index"]))
            name = key[0]
            if name and name in self and self._same_as_stored(name, cases):
                continue
            added.append(self.add_layout(cases, split, self._free_id(name or None)))
        return added

    def _same_as_stored(self, layout_id: str, cases: Sequence[Case]) -> bool:
        stored = self.layout_cases(layout_id)
        return len(stored) == len(cases) and all(
            cases_equal(a, b) for a, b in zip(stored, cases, strict=True)
        )


def cases_equal(a: Case, b: Case) -> bool:
    """True when two cases have bit-identical arrays, equal resolution and equal meta."""

    def same(x: np.ndarray | None, y: np.ndarray | None) -> bool:
        if x is None or y is None:
            return x is None and y is None
        return x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()

    return (
        same(a.occupancy, b.occupancy)
        and same(a.wind, b.wind)
        and same(a.concentration, b.concentration)
        and same(a.source, b.source)
        and same(a.frames, b.frames)
        and a.resolution == b.resolution
        and json.dumps(a.meta, sort_keys=True) == json.dumps(b.meta, sort_keys=True)
    )


def _short(e: BaseException) -> str:
    s = str(e).strip() or type(e).__name__
    return s if len(s) < 300 else s[:297] + "..."


# -- journal: kill-safe staging of results -----------------------------------------------------
class Journal:
    """Finished layouts and failures not yet committed to the store file.

    The journal is the directory ``<store>.pending/`` beside the store.  Every
    entry is one file written to a temporary name, fsynced and renamed, so an
    entry is either complete or absent whatever moment the writer is killed:

    * ``<layout_id>.h5``: an HDF5 file holding ``/layouts/<layout_id>`` in the
      store's format;
    * ``<layout_id>.failure.json``: a failure record.

    :func:`commit_pending` moves the entries into the store.
    """

    def __init__(self, store_path: str | Path, compression: str = "gzip") -> None:
        self.store_path = Path(store_path)
        self.dir = self.store_path.with_name(self.store_path.name + ".pending")
        self.compression = compression

    def _atomic(self, final: Path, write: Callable[[Path], None]) -> Path:
        self.dir.mkdir(parents=True, exist_ok=True)
        with atomic_path(final) as tmp:
            write(tmp)
        _fsync_dir(self.dir)
        return final

    def add_layout(self, cases: Sequence[Case], split: str, layout_id: str, layout_index: int) -> Path:
        """Stage one finished layout."""
        cases = _prepare_cases(cases)
        _check_split(split)
        _check_id(layout_id)

        def write(tmp: Path) -> None:
            with h5py.File(tmp, "w") as f:
                _write_layout(
                    f.create_group("layouts"),
                    layout_id,
                    cases,
                    split,
                    layout_index,
                    self.compression,
                )

        return self._atomic(self.dir / f"{layout_id}.h5", write)

    def add_failure(self, record: Mapping[str, Any]) -> Path:
        """Stage one failure record (needs ``layout_id``)."""
        rec = dict(record)
        lid = _check_id(str(rec["layout_id"]))
        text = _json_attr(rec)
        return self._atomic(self.dir / f"{lid}.failure.json", lambda tmp: tmp.write_text(text))

    def entries(self) -> tuple[list[tuple[str, Path, int]], list[tuple[dict[str, Any], Path]]]:
        """``([(layout_id, file, layout_index)], [(failure record, file)])``.

        Temporary files of interrupted writes and unreadable entries are deleted
        (their layouts are simply made again).
        """
        layouts: list[tuple[str, Path, int]] = []
        failures: list[tuple[dict[str, Any], Path]] = []
        if not self.dir.is_dir():
            return layouts, failures
        for p in sorted(self.dir.iterdir()):
            if is_temporary(p) or (p.name.startswith(".") and p.name.endswith(".tmp")):
                p.unlink(missing_ok=True)
            elif p.name.endswith(".failure.json"):
                try:
                    rec = json.loads(p.read_text())
                    if not isinstance(rec, dict) or "layout_id" not in rec:
                        raise ValueError("not a failure record")
                    failures.append((rec, p))
                except (OSError, ValueError, KeyError, TypeError):
                    p.unlink(missing_ok=True)
            elif p.suffix == ".h5":
                lid = p.stem
                try:
                    with h5py.File(p, "r") as f:
                        idx = int(f["layouts"][lid].attrs["layout_index"])
                    layouts.append((lid, p, idx))
                except (OSError, KeyError, ValueError):
                    p.unlink(missing_ok=True)
        return layouts, failures

    def __len__(self) -> int:
        a, b = self.entries()
        return len(a) + len(b)


def create_store(path: str | Path, generation: Mapping[str, Any] | None = None) -> None:
    """Create an empty store file atomically (temporary file, fsync, rename)."""
    path = Path(path)
    if path.exists():
        raise InputDataError(f"{path} already exists")
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, DatasetStore(tmp, "w") as s:
        if generation is not None:
            s.set_generation_info(generation)
    _fsync_dir(path.parent)


def commit_pending(
    store_path: str | Path,
    finalize: Callable[[DatasetStore], None] | None = None,
    *,
    compression: str = "gzip",
) -> int:
    """Commit the journal's entries into the store file by copy-and-rename.

    The store is copied to a temporary file, the staged layouts and failures are
    added to the copy (layouts already in it are skipped, a successful layout
    removes the failure record of its id), ``finalize(store)`` runs on the copy,
    and the copy is fsynced and renamed over the store; then the committed
    journal entries are deleted.  Killed at any moment, the store is the old or
    the new complete file and nothing staged is lost or duplicated.

    Returns the number of journal entries committed.  With no entries and no
    ``finalize`` nothing is written.
    """
    store_path = Path(store_path)
    journal = Journal(store_path, compression)
    layouts, failures = journal.entries()
    if not layouts and not failures and finalize is None:
        return 0
    if not store_path.exists():
        raise InputDataError(f"{store_path}: no such dataset store to commit into")
    with atomic_path(store_path) as tmp:
        shutil.copyfile(store_path, tmp)
        with DatasetStore(tmp, "r+", compression=compression) as s:
            for rec, _ in failures:
                lid = str(rec["layout_id"])
                if lid not in s:
                    s.add_failure(rec, flush=False)
            for lid, path, _ in layouts:
                if lid not in s:
                    try:
                        with h5py.File(path, "r") as src:
                            s._copy_layout(src["layouts"][lid], lid)
                    except (OSError, KeyError) as e:
                        raise InputDataError(f"journal entry {path} is unreadable: {e}") from None
                s.remove_failure(lid)
            if finalize is not None:
                finalize(s)
    _fsync_dir(store_path.parent)
    for _, path, _ in layouts:
        path.unlink(missing_ok=True)
    for _, path in failures:
        path.unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        journal.dir.rmdir()  # only when empty
    return len(layouts) + len(failures)
