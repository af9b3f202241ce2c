"""Atomic file writes: a result file is either the old one or the new one, never a torn one.

Every file the toolkit writes as a result goes through :func:`atomic_path` or the
helpers built on it.  The data are written to a hidden temporary file in the
target's directory (``.NAME.tmp-<random><suffix>``; the suffix is kept for
libraries that choose the format from it, such as ``np.savez``, ``savefig`` or
Pillow), fsynced, and moved onto the target with :func:`os.replace`, which is
atomic within one file system.  A Ctrl-C, a kill or an error while writing
leaves the previous file as it was.

:func:`update_json` is the read-modify-write of a JSON file that several
processes update (e.g. a suite's ``_timings.json``): it holds an exclusive
``flock`` on the sidecar ``.NAME.lock`` while it reads, changes and replaces
the file, so no update is lost.

A temporary file outlives its write only when the process dies without running
its cleanup (``SIGKILL``, power loss); :func:`is_temporary` lets directory
scans skip such leftovers, which keep the target's suffix.

:func:`expand_paths` is the other direction: the input files that a list of files and
directories names, as every command that takes "files or a directory of them" reads it.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from dgse.errors import InputDataError

__all__ = [
    "atomic_open",
    "atomic_path",
    "expand_paths",
    "is_temporary",
    "json_safe",
    "lock_path",
    "temporary_name",
    "update_json",
    "write_bytes",
    "write_json",
    "write_text",
]

#: A temporary name: ``.NAME.tmp-`` + 8 random hex digits + the target's suffix.
_TEMP_RE = re.compile(r"^\..+\.tmp-[0-9a-f]{8}(\.[^.]+)?$")
#: Longest target name (bytes) kept whole in a temporary name: file systems allow 255.
_MAX_NAME_BYTES = 200


def expand_paths(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    keep: Callable[[Path], bool],
    what: str,
) -> list[Path]:
    """The files that ``paths`` name, in the given order: a file as itself, a directory as
    its files that ``keep`` accepts, sorted by name (a leftover temporary file never).

    Raises:
        InputDataError: a path that is neither a file nor a directory
            (``"P: no such WHAT file or directory"``), or no file at all (``"no WHAT files given"``).
    """
    items = [paths] if isinstance(paths, str | os.PathLike) else list(paths)
    out: list[Path] = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            out.extend(sorted(q for q in p.iterdir() if q.is_file() and not is_temporary(q) and keep(q)))
        elif p.is_file():
            out.append(p)
        else:
            raise InputDataError(f"{p}: no such {what} file or directory")
    if not out:
        raise InputDataError(f"no {what} files given")
    return out


def temporary_name(path: str | os.PathLike[str]) -> Path:
    """A fresh temporary path for ``path``: same directory, hidden, same suffix."""
    target = Path(path)
    base = target.name
    if len(base.encode()) > _MAX_NAME_BYTES:  # keep the whole name under the 255-byte limit
        base = base.encode()[:_MAX_NAME_BYTES].decode(errors="ignore")
    return target.with_name(f".{base}.tmp-{os.urandom(4).hex()}{target.suffix}")


def is_temporary(path: str | os.PathLike[str]) -> bool:
    """True for a name :func:`atomic_path` gives its temporary files (e.g. a leftover of a killed run)."""
    return _TEMP_RE.match(Path(path).name) is not None


def _reserve(target: Path) -> Path:
    """Create an empty temporary file for ``target`` (mode 0o666 less the umask, as ``open``)."""
    for _ in range(100):
        tmp = temporary_name(target)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(f"cannot write {target}: no free temporary name beside it")


def _fsync(path: Path) -> None:
    """Flush a file's data to the disk, so that the rename never exposes unwritten blocks."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path``, on an exception it is removed.

    The temporary file exists (empty) when the block starts and lies in the
    target's directory, so the final :func:`os.replace` is atomic.  A symlink at
    ``path`` is followed: its target is replaced, as an in-place write would.
    The parent directory must exist.
    """
    target = Path(path)
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    tmp = _reserve(target)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w", **open_kwargs: Any) -> Iterator[IO[Any]]:
    """:func:`open` a temporary file for writing (``"w"`` or ``"wb"``), as :func:`atomic_path`.

    The file replaces ``path`` only when the block finishes without an exception.
    """
    if mode not in ("w", "wt", "wb"):
        raise ValueError(f"atomic_open writes a whole file: mode 'w' or 'wb', not {mode!r}")
    with atomic_path(path) as tmp, open(tmp, mode, **open_kwargs) as fh:
        yield fh


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; returns ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)
    return Path(path)


def json_safe(obj: Any) -> Any:
    """``obj`` as plain JSON data: NaN and infinities as None; numpy scalars as Python numbers;
    arrays and tuples as lists; mapping keys as strings (so ``json.dumps(..., allow_nan=False)``
    takes it)."""
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: str | os.PathLike[str], obj: Any, *, end: str = "", **json_kwargs: Any) -> Path:
    """Write ``json.dumps(obj, **json_kwargs) + end`` to ``path`` atomically; returns ``path``.

    The text is made before the file is touched, so an object that cannot be
    serialized leaves the old file as it was.
    """
    return write_text(path, json.dumps(obj, **json_kwargs) + end)


def lock_path(path: str | os.PathLike[str]) -> Path:
    """The sidecar lock file of :func:`update_json` for ``path`` (``.NAME.lock``, kept)."""
    target = Path(path)
    return target.with_name(f".{target.name}.lock")


def update_json(
    path: str | os.PathLike[str],
    fn: Callable[[Any], Any],
    *,
    default: Any = None,
    end: str = "",
    **json_kwargs: Any,
) -> Any:
    """Replace the JSON file ``path`` by ``fn(its content)`` under an exclusive lock; returns the new content.

    ``fn`` gets ``default`` when the file does not exist.  The lock
    (``flock`` on :func:`lock_path`, which stays in place so that every writer
    locks the same file) serializes writers in other processes and threads;
    readers need no lock, since the file is replaced atomically.
    """
    import fcntl  # POSIX only; imported here so that the rest of the module works anywhere

    target = Path(path)
    with open(lock_path(target), "a") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX)
        try:
            current = json.loads(target.read_text(encoding="utf-8")) if target.is_file() else default
            new = fn(current)
            write_json(target, new, end=end, **json_kwargs)
        finally:
            fcntl.flock(lock.fileno(), fcntl.LOCK_UN)
    return new
