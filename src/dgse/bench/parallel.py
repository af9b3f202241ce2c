"""Random-readings evaluations on many processes, each with its own part of the journal.

:func:`evaluate_parallel` runs :func:`dgse.evaluation.evaluate` for rows of
``(method, knowledge level)`` on sets of case files with one process per case and reading
count of a row, ``rounds`` trials at a time for every case before the next (so a run cut
short covers the cases evenly).  Each process writes its own part of the row's journal; the
parts are joined into the journal (:func:`join_journal`) as each round ends, so the serial
:func:`~dgse.evaluation.evaluate` with the same journal finds every estimate and computes
none again.  A time limit stops the workers, keeping every finished estimate.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dgse.errors import InputDataError
from dgse.files import write_text
from dgse.journal import journal_path

__all__ = ["evaluate_parallel", "join_journal", "journal_entries", "row_journal"]


def row_journal(out: str | os.PathLike[str], set_name: str, method: str, level: str) -> Path:
    """The journal of one row's result ``OUT/<set>_<method>_<level>.json``."""
    return journal_path(Path(out) / f"{set_name}_{method}_{level}.json")


def journal_entries(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """A journal's lines, decoded (header first); a line torn by a kill is dropped."""
    path = Path(path)
    out = []
    for line in path.read_text().splitlines() if path.exists() else []:
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return out


def join_journal(journal: str | os.PathLike[str], parts: Sequence[str | os.PathLike[str]]) -> int:
    """Append the parts' estimates that ``journal`` lacks to it (the parts are then removed);
    returns how many estimates it holds.

    Raises:
        InputDataError: a part was written with other settings (another journal identity).
    """
    journal = Path(journal)
    header, entries = None, {}
    for path in [journal, *map(Path, parts)]:
        lines = journal_entries(path)
        if not lines:
            continue
        if header is None:
            header = lines[0]
        elif lines[0].get("identity") != header.get("identity"):
            raise InputDataError(f"{path}: written with other settings than {journal}")
        for e in lines[1:]:
            r = e.get("record", {})
            entries.setdefault((r.get("case"), r.get("n_obs"), r.get("trial")), e)
    if header is None:
        return 0
    write_text(journal, "".join(json.dumps(x) + "\n" for x in [header, *entries.values()]))
    for path in parts:
        Path(path).unlink(missing_ok=True)
    return len(entries)


def _kept(lines: list[dict[str, Any]]) -> dict[str, set[tuple[Any, Any]]]:
    """``{case: {(n_obs, trial)}}`` of the estimates a journal's lines keep."""
    out: dict[str, set[tuple[Any, Any]]] = {}
    for e in lines[1:]:
        r = e["record"]
        out.setdefault(r["case"], set()).add((r["n_obs"], r["trial"]))
    return out


def _run_part(task: tuple[str, int, str, str, int, str]) -> int:
    """One case and reading count of one row with ``trials`` trials, into its own journal part
    (a worker process)."""
    from dgse.evaluation.evaluate import evaluate

    case, n, method, level, trials, part = task
    res = evaluate(case, method, [n], trials=trials, seed=0, knowledge=level, journal=part)
    return len(res["per_case"])


def evaluate_parallel(
    rows: Sequence[tuple[str, str]],
    sources: dict[str, Path],
    out: str | os.PathLike[str],
    counts: Sequence[int],
    trials: int,
    workers: int,
    rounds: int,
    time_limit: float | None = None,
) -> bool:
    """Every ``(set, row)`` with ``trials`` trials per case and count on ``workers`` processes,
    one case and count per task, ``rounds`` trials at a time, into the rows' journals
    (:func:`row_journal`).  ``sources``: a folder of case files (or one file) per set name.
    Returns True when all of it is done, False when ``time_limit`` seconds stopped it (what
    the workers finished is kept; the same call resumes)."""
    out = Path(out)
    t0 = time.monotonic()
    ctx = multiprocessing.get_context("spawn")
    cases = {name: sorted(src.glob("*.npz")) if src.is_dir() else [src] for name, src in sources.items()}
    parts_dir = out / "_parts"
    parts_dir.mkdir(parents=True, exist_ok=True)
    for name in cases:  # an interrupted run's parts
        for method, level in rows:
            journal = row_journal(out, name, method, level)
            join_journal(journal, sorted(parts_dir.glob(f"{journal.stem}.*.jsonl")))
    for upto in range(min(rounds, trials), trials + rounds, rounds):
        upto = min(upto, trials)
        tasks: list[tuple[str, int, str, str, int, str]] = []
        parts: dict[Path, list[Path]] = {}
        for name, files in cases.items():
            for method, level in rows:
                journal = row_journal(out, name, method, level)
                lines = journal_entries(journal)
                kept = _kept(lines)
                for f in files:
                    for n in counts:
                        if all((n, t) in kept.get(f.stem, set()) for t in range(upto)):
                            continue
                        part = parts_dir / f"{journal.stem}.{f.stem}.{n}.jsonl"
                        if lines:  # the part starts with what the journal has of this case and count
                            mine = [
                                x
                                for x in lines[1:]
                                if (x["record"]["case"], x["record"]["n_obs"]) == (f.stem, n)
                            ]
                            write_text(part, "".join(json.dumps(x) + "\n" for x in [lines[0], *mine]))
                        tasks.append((str(f), n, method, level, upto, str(part)))
                        parts.setdefault(journal, []).append(part)
        if not tasks:
            continue
        pool = ctx.Pool(workers)
        finished = False
        try:
            pending = pool.map_async(_run_part, tasks, chunksize=1)
            left = None if time_limit is None else time_limit - (time.monotonic() - t0)
            pending.wait(left)
            finished = pending.ready()
        finally:  # Ctrl-C, an error or the time limit: what the workers finished is kept
            if finished:
                pool.close()
            else:
                pool.terminate()
            pool.join()
            for journal, ps in parts.items():
                join_journal(journal, ps)
        if finished:
            pending.get()  # a worker's error ends the run here, with its traceback
        else:
            return False
    return True
