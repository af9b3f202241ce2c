"""A resumable run's journal: finished pieces of work kept on disk as they finish.

Long loops (:func:`dgse.search.campaign.run_trials`, :func:`dgse.evaluation.evaluate.evaluate`)
append one JSON line per finished piece (an episode, an estimate) to a
journal, so that an interrupted run (Ctrl-C, a kill) keeps what it did and a
rerun with the same settings skips it.

File format (JSON lines, UTF-8)::

    {"format": "dgse-journal", "format_version": 1, "kind": "search", "identity": {...}, ...}
    {... one finished piece ...}
    {... one finished piece ...}

The first line is the header: ``kind`` says which loop wrote it and
``identity`` the settings a piece depends on.  A journal is reused only by
the same kind of loop with an equal identity; otherwise :class:`Journal`
raises :class:`~dgse.errors.InputDataError` naming the settings that differ
(so results of different settings are never mixed).

Robustness: every line is written with one ``write`` and flushed, so a kill
loses at most the line being written; a torn or unreadable line is dropped
when the journal is read (its piece is simply done again), and the file is
then rewritten without it (atomically, :func:`dgse.files.write_text`).  The file is
not synced to disk after every line: a power loss may lose the last lines.
Nothing is written before the first piece finishes (a run that fails
early leaves no file behind); ``restart=True`` empties the journal at once.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from dgse.errors import InputDataError
from dgse.files import write_text
from dgse.world.case import Case

__all__ = [
    "JOURNAL_FORMAT",
    "JOURNAL_VERSION",
    "Journal",
    "case_fingerprint",
    "check_kept_case",
    "count_records",
    "journal_path",
]

JOURNAL_FORMAT = "dgse-journal"
JOURNAL_VERSION = 1


def journal_path(json_path: str | os.PathLike[str]) -> Path:
    """The journal kept beside a run's JSON file: ``out.json`` -> ``out.journal.jsonl``."""
    p = Path(json_path)
    stem = p.stem if p.suffix.lower() == ".json" else p.name
    return p.with_name(f"{stem}.journal.jsonl")


def case_fingerprint(case: Case) -> str:
    """A short hash (16 hex digits) of a case's arrays, resolution, frame spacing and start (if any).

    Pieces of work are kept with the fingerprint of their case, so a case file
    that changed since the journal was written is noticed.
    """
    h = hashlib.sha256()
    arrays = (case.occupancy, case.wind, case.concentration, case.source, case.frames)
    for a in arrays:
        if a is None:
            h.update(b"none;")
            continue
        c = np.ascontiguousarray(a)
        h.update(f"{c.dtype.str}{c.shape};".encode())
        h.update(c.data)
    h.update(repr((float(case.resolution), case.meta.get("frame_dt"))).encode())
    if "start_m" in case.meta:  # a case's own start fixes its episodes' starts
        h.update(repr(case.meta["start_m"]).encode())
    return h.hexdigest()[:16]


def check_kept_case(entry: Mapping[str, Any], fingerprint: str | None, differs: str) -> None:
    """Refuse a kept piece of work whose case changed since (its ``case_fingerprint`` is not
    ``fingerprint``): :class:`InputDataError` with ``differs``, which says which case and
    journal and how to start afresh (``{restart}`` is named as the caller's option)."""
    if entry.get("case_fingerprint") != fingerprint:
        raise InputDataError(differs, names={"restart": "restart=True"})


def _canonical(obj: Any) -> Any:
    """``obj`` as it reads back from JSON (tuples as lists, keys as strings)."""
    return json.loads(json.dumps(obj, allow_nan=False))


def _short(value: Any, width: int = 60) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= width else text[: width - 3] + "..."


def _differences(old: Mapping[str, Any], new: Mapping[str, Any], prefix: str = "") -> list[str]:
    """What differs between two identities, nested settings named by their dotted path."""
    out = []
    for key in sorted(set(old) | set(new)):
        name = f"{prefix}{key}"
        if key not in old:
            out.append(f"{name} (not recorded) is now {_short(new[key])}")
        elif key not in new:
            out.append(f"{name} was {_short(old[key])}, now not given")
        elif isinstance(old[key], Mapping) and isinstance(new[key], Mapping):
            out += _differences(old[key], new[key], f"{name}.")
        elif old[key] != new[key]:
            out.append(f"{name} was {_short(old[key])}, now {_short(new[key])}")
    return out


def _read_lines(path: Path) -> tuple[dict[str, Any] | None, list[dict[str, Any]], bool]:
    """``(header, records, clean)``: the header (None for an empty or torn one), the readable
    records, and whether every line was readable and the file ends with a newline."""
    text = path.read_text(encoding="utf-8", errors="replace")
    lines = text.split("\n")
    clean = text.endswith("\n") or not text
    try:
        header = json.loads(lines[0]) if lines[0].strip() else None
    except ValueError:
        header = None
        clean = False
    if header is not None and not isinstance(header, dict):
        raise InputDataError(f"{path} is not a dgse journal (first line is not a header)")
    records = []
    for line in lines[1:]:
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError:
            clean = False
            continue
        if isinstance(rec, dict):
            records.append(rec)
        else:
            clean = False
    return header, records, clean


def count_records(path: str | os.PathLike[str]) -> int:
    """The number of readable pieces in the journal at ``path`` (0 when there is none)."""
    p = Path(path)
    if not p.is_file():
        return 0
    try:
        header, records, _ = _read_lines(p)
    except (InputDataError, OSError):
        return 0
    return len(records) if header is not None else 0


#: How a Python caller asks to discard a journal (the command line says ``--restart``).
_RESTART = {"restart": "restart=True"}


class Journal:
    """An append-only JSON-lines journal (module docstring); use as a context manager.

    Args:
        path: the journal file.
        kind: the loop that writes it (e.g. ``"search"``).
        identity: JSON-able settings the pieces depend on; an existing journal
            must have been written with an equal identity.
        restart: discard an existing journal (at once) instead of resuming it.
        unit: what one piece is, for messages (e.g. ``"episode"``).

    Attributes:
        records: the pieces already in the journal (resumed), then the appended ones.

    Raises:
        InputDataError: the file is not a journal, was written by another kind of
            loop, by a newer format, or with another identity (the message lists
            the differences and how to start afresh).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        kind: str,
        identity: Mapping[str, Any],
        *,
        restart: bool = False,
        unit: str = "piece",
    ) -> None:
        self.path = Path(path)
        self.kind = kind
        self.identity = _canonical(dict(identity))
        self.records: list[dict[str, Any]] = []
        self._fh: IO[str] | None = None
        self._rewrite = True
        if restart:
            if self.path.exists():
                self._write_all()
            return
        if not self.path.exists():
            return
        header, records, clean = _read_lines(self.path)
        if header is None:  # empty, or killed while writing the header
            return
        if header.get("format") != JOURNAL_FORMAT:
            raise InputDataError(f"{self.path} is not a dgse journal; give another output path")
        if int(header.get("format_version", 0)) > JOURNAL_VERSION:
            raise InputDataError(f"{self.path} was written by a newer dgse (journal format too new)")
        if header.get("kind") != kind:
            raise InputDataError(
                f"{self.path} is the journal of a {header.get('kind')!r} run, not of a {kind!r} run; "
                "give another output path"
            )
        old = header.get("identity")
        if not isinstance(old, dict) or old != self.identity:
            diff = _differences(old if isinstance(old, dict) else {}, self.identity)
            raise InputDataError(
                f"{self.path} holds {len(records)} finished {unit}{'s' * (len(records) != 1)} of a {kind} "
                "run with other settings "
                f"({'; '.join(diff)}): rerun with the same settings to resume it, give another output "
                "path to keep both, or start afresh with {restart}",
                names=_RESTART,
            )
        self.records = records
        self._rewrite = not clean

    def _write_all(self) -> None:
        """Write the header and the records to a temporary file and move it into place."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        header = {
            "format": JOURNAL_FORMAT,
            "format_version": JOURNAL_VERSION,
            "kind": self.kind,
            "identity": self.identity,
        }
        lines = [json.dumps(header, allow_nan=False)]
        lines += [json.dumps(r, allow_nan=False) for r in self.records]
        write_text(self.path, "\n".join(lines) + "\n")
        self._rewrite = False

    def append(self, record: Mapping[str, Any]) -> None:
        """Keep one finished piece (JSON-able, no NaN) on disk, then in :attr:`records`."""
        line = json.dumps(record, allow_nan=False)
        if self._fh is None:
            if self._rewrite:
                self._write_all()
            self._fh = open(self.path, "a", encoding="utf-8")
        self._fh.write(line + "\n")
        self._fh.flush()
        self.records.append(dict(record))

    def close(self) -> None:
        """Sync and close the file (if anything was appended)."""
        if self._fh is not None:
            try:
                os.fsync(self._fh.fileno())
            finally:
                self._fh.close()
                self._fh = None

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
