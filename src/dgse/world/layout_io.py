"""Layout files: a :class:`~dgse.world.layout.Layout` on its own, without fields.

A layout file ``<name>.npz`` holds two of a case file's keys (spec section 2):

* ``occupancy``: uint8 ``(H, W)``, 1 solid, 0 free air;
* ``meta``: 0-d str, JSON of :meth:`Layout.meta` (width_m, height_m,
  resolution, inlet/outlet or inlets/outlets, walls) plus ``name`` and
  ``kind = "layout"``.

:func:`load_layout` also reads the layout of a case file (its ``meta`` holds
the same keys).  :func:`npz_kind` tells the two apart.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dgse.errors import InputDataError
from dgse.files import atomic_open
from dgse.world.case import read_meta
from dgse.world.grid import DEFAULT_RESOLUTION
from dgse.world.layout import Layout, Opening

__all__ = ["LAYOUT_KEYS", "load_layout", "npz_kind", "save_layout"]

#: The keys of a layout file.
LAYOUT_KEYS = ("occupancy", "meta")
#: Keys only a case file has; one of them marks a file as a case file.
_CASE_ONLY_KEYS = ("wind", "concentration", "source")


def _npz_path(path: str | Path) -> Path:
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def save_layout(layout: Layout, path: str | Path, meta: Mapping[str, Any] | None = None) -> Path:
    """Write ``layout`` as a layout file (``.npz`` appended if missing); returns the path.

    ``meta``: further JSON-able entries of the file's ``meta`` (e.g. a source or a
    start position); the layout's own keys take precedence.
    """
    path = _npz_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {**(meta or {}), "kind": "layout", "name": layout.name, **layout.meta()}
    with atomic_open(path, "wb") as fh:
        np.savez_compressed(fh, occupancy=layout.occupancy.astype(np.uint8), meta=np.array(json.dumps(meta)))
    return path


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    if not path.exists():
        raise InputDataError(f"{path}: no such file")
    if path.is_dir():
        raise InputDataError(f"{path}: is a directory, not an .npz file")
    if not zipfile.is_zipfile(path):
        raise InputDataError(f"{path}: not an .npz file (not a zip archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):
                raise ValueError("a bare .npy array, not an .npz archive")
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise InputDataError(f"{path}: not a readable .npz file ({e})") from None


def npz_kind(path: str | Path) -> Literal["case", "layout"]:
    """``"case"`` or ``"layout"``: what the ``.npz`` file at ``path`` holds.

    A file with any of ``wind``, ``concentration``, ``source`` is a case file
    (whether complete or not); one with ``occupancy`` or ``meta`` only is a
    layout file.  Raises :class:`InputDataError` for anything else.
    """
    path = Path(path)
    keys = set(_read_npz(path))
    if keys & set(_CASE_ONLY_KEYS):
        return "case"
    if keys & set(LAYOUT_KEYS):
        return "layout"
    found = ", ".join(sorted(keys)) or "none"
    raise InputDataError(
        f"{path}: neither a case file nor a layout file (keys: {found}; a layout file "
        f"needs {', '.join(LAYOUT_KEYS)})"
    )


def load_layout(path: str | Path) -> Layout:
    """Read and validate a layout file (or the layout of a case file).

    Raises:
        InputDataError: naming the file and the problem (missing file or key,
            wrong dtype or shape, bad ``meta``, openings off the map, ...).
    """
    path = Path(path)
    arrays = _read_npz(path)
    missing = [k for k in LAYOUT_KEYS if k not in arrays]
    if missing:
        raise InputDataError(f"{path}: missing key(s) {', '.join(missing)}")
    occ = arrays["occupancy"]
    if occ.dtype != np.uint8:
        raise InputDataError(f"{path}: occupancy has dtype {occ.dtype}, expected uint8")
    if occ.ndim != 2 or min(occ.shape) < 2:
        raise InputDataError(f"{path}: occupancy must be a 2-D map, got shape {occ.shape}")
    meta = read_meta(arrays, str(path), InputDataError)
    try:
        res = float(meta.get("resolution", DEFAULT_RESOLUTION))
    except (TypeError, ValueError):
        raise InputDataError(
            f"{path}: meta resolution must be a number, got {meta['resolution']!r}"
        ) from None
    H, W = occ.shape
    for key, n in (("width_m", W), ("height_m", H)):
        if key in meta:
            try:
                ok = abs(float(meta[key]) - n * res) <= 0.5 * res
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise InputDataError(f"{path}: meta {key}={meta[key]!r} does not match {n} cells of {res} m")
    name = str(meta.get("layout") or meta.get("name") or path.stem)
    try:
        inlets = _openings(meta, "inlet")
        outlets = _openings(meta, "outlet")
        walls = tuple(tuple(w) for w in meta.get("walls", []))
        return Layout(occ, inlets, outlets, res, walls, name)
    except InputDataError as e:
        raise InputDataError(f"{path}: {e}") from None
    except (TypeError, ValueError) as e:  # e.g. malformed walls
        raise InputDataError(f"{path}: bad layout meta ({e})") from None


def _openings(meta: dict, kind: str) -> tuple[Opening, ...]:
    """The openings ``meta[kind + "s"]`` (a list) or ``meta[kind]`` (one) name."""
    if kind + "s" in meta:
        items = meta[kind + "s"]
        if not isinstance(items, list):
            raise InputDataError(f"meta {kind}s must be a list, got {items!r}")
    elif kind in meta:
        items = [meta[kind]]
    else:
        raise InputDataError(f"meta has no {kind!r} (nor a list {kind + 's'!r})")
    return tuple(Opening.from_dict(d) for d in items)
