"""Source localization from random readings per knowledge level: DGSE-S, adjoint, dgse-phys, oracle.

Issue 12's table: mean (and median) source-localization error and source
cross-entropy from 5, 20, 50, 150 and 300 random readings (Table I noise),
each method at the knowledge level it is run with (``--knowledge``):

* ``dgse-s`` and ``dgse-phys`` at ``map`` (openings proposed from the wind readings);
* ``adjoint`` and ``dgse-phys`` at ``openings``;
* ``dgse-phys`` at ``wind`` (the case's wind as the user's CFD, openings from the wind);
* ``adjoint-oracle`` at ``wind`` (the true flow re-solved).

Case sets: ``reference`` = ``../shared/reference-cases`` (OpenFOAM solutions:
the physics estimators' model differs from the generating solver), ``test``
= generated scenarios with seeds 2000-2007 (a seed range kept for testing,
never used for tuning).  Every finished estimate is kept in a journal beside
each JSON file, so an interrupted run resumes.

    python benchmarks/phys_gsl.py --trials 2 -o benchmarks/results/phys_gsl

On a machine with many cores, ``--workers N`` runs one process per case and
reading count of a row, ``--rounds R`` trials at a time for every case before the next R (so
a run cut short covers the cases evenly), each process with its own part of
the journal; the parts are joined into the row's journal as each round
ends.  ``--time-limit S`` stops the workers after ``S`` seconds, keeping
every finished estimate: the same command resumes, and with ``--trials`` no
more than every case has, the table is written from the journal alone.

    python benchmarks/phys_gsl.py --trials 20 --workers 14 --rounds 2 --time-limit 480 \\
        --methods dgse-phys@map -o benchmarks/results/phys_gsl_20
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from dgse.evaluation.evaluate import evaluate, write_json
from dgse.files import write_text
from dgse.journal import journal_path

COUNTS = [5, 20, 50, 150, 300]
METHODS = [
    ("dgse-s", "map"),
    ("dgse-phys", "map"),
    ("adjoint", "openings"),
    ("dgse-phys", "openings"),
    ("dgse-phys", "wind"),
    ("adjoint-oracle", "wind"),
]
TEST_SEEDS = range(2000, 2008)


def _test_cases(out: Path) -> Path:
    """The generated test scenarios as case files (made once)."""
    from dgse.physics.scenario import random_cases

    d = out / "_test_cases"
    d.mkdir(parents=True, exist_ok=True)
    for seed in TEST_SEEDS:
        path = d / f"test{seed}_src0.npz"
        if not path.exists():
            random_cases(seed, n_sources=1)[0].save(path)
    return d


def _run_part(task: tuple[str, int, str, str, int, str]) -> int:
    """One case and reading count of one row with ``trials`` trials, into its own journal part
    (a worker process)."""
    case, n, method, level, trials, part = task
    res = evaluate(case, method, [n], trials=trials, seed=0, knowledge=level, journal=part)
    return len(res["per_case"])


def _entries(path: Path) -> list[dict[str, Any]]:
    """A journal's lines, decoded (header first); a line torn by a kill is dropped."""
    out = []
    for line in path.read_text().splitlines() if path.exists() else []:
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return out


def _join(journal: Path, parts: list[Path]) -> int:
    """Append the parts' estimates that ``journal`` lacks to it (the parts are then removed);
    returns how many it holds."""
    header, entries = None, {}
    for path in [journal, *parts]:
        lines = _entries(path)
        if not lines:
            continue
        if header is None:
            header = lines[0]
        elif lines[0].get("identity") != header.get("identity"):
            raise SystemExit(f"{path}: written with other settings than {journal}")
        for e in lines[1:]:
            r = e.get("record", {})
            entries.setdefault((r.get("case"), r.get("n_obs"), r.get("trial")), e)
    if header is None:
        return 0
    write_text(journal, "".join(json.dumps(x) + "\n" for x in [header, *entries.values()]))
    for path in parts:
        path.unlink(missing_ok=True)
    return len(entries)


def run_parallel(
    rows: list[tuple[str, str]],
    sources: dict[str, Path],
    out: Path,
    trials: int,
    workers: int,
    rounds: int,
    time_limit: float | None,
) -> bool:
    """Every (set, row) with ``trials`` trials on ``workers`` processes, one case and count per task,
    ``rounds`` trials at a time; True when all of it is done (else stopped at ``time_limit``)."""
    t0 = time.monotonic()
    ctx = multiprocessing.get_context("spawn")
    cases = {name: sorted(src.glob("*.npz")) if src.is_dir() else [src] for name, src in sources.items()}
    parts_dir = out / "_parts"
    parts_dir.mkdir(exist_ok=True)
    for name in cases:  # an interrupted run's parts
        for method, level in rows:
            journal = journal_path(out / f"{name}_{method}_{level}.json")
            _join(journal, sorted(parts_dir.glob(f"{journal.stem}.*.jsonl")))
    for upto in range(min(rounds, trials), trials + rounds, rounds):
        upto = min(upto, trials)
        tasks: list[tuple[str, int, str, str, int, str]] = []
        parts: dict[Path, list[Path]] = {}
        for name, files in cases.items():
            for method, level in rows:
                journal = journal_path(out / f"{name}_{method}_{level}.json")
                lines = _entries(journal)
                kept = _kept(lines)
                for f in files:
                    for n in COUNTS:
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
        print(f"trials up to {upto}: {len(tasks)} tasks on {workers} workers", flush=True)
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
                print(f"{journal.name}: {_join(journal, ps)} estimates kept", flush=True)
        if finished:
            pending.get()  # a worker's error ends the run here, with its traceback
        else:
            print(f"stopped after {time.monotonic() - t0:.0f} s (--time-limit); the same command resumes")
            return False
    return True


def _kept(lines: list[dict[str, Any]]) -> dict[str, set[tuple[Any, Any]]]:
    """``{case: {(n_obs, trial)}}`` of the estimates a journal's lines (:func:`_entries`) keep."""
    out: dict[str, set[tuple[Any, Any]]] = {}
    for e in lines[1:]:
        r = e["record"]
        out.setdefault(r["case"], set()).add((r["n_obs"], r["trial"]))
    return out


#: (row, against it, what the issue asks): paired on the same case, count and trial
PAIRS = [
    ("dgse-phys@openings", "adjoint-oracle@wind", "within 10 % of the oracle from 50 readings on"),
    ("dgse-phys@openings", "dgse-s@map", "better than DGSE-S at every count"),
    ("dgse-phys@map", "dgse-s@map", "better than DGSE-S at every count"),
    ("dgse-phys@map", "adjoint-oracle@wind", "goal: within 1.5x of the oracle at 150 and 300"),
]


def _comparisons(per_estimate: dict[str, dict[str, dict[tuple, float]]]) -> list[str]:
    """Mean SL error ratios of :data:`PAIRS` on the estimates both rows have, with the paired
    difference's mean and standard error (m).  ``per_estimate``: ``{set: {row: {(case, n_obs,
    trial): SL error}}}``."""
    import numpy as np

    lines: list[str] = []
    for name, errors in per_estimate.items():
        rows = [(a, b, goal) for a, b, goal in PAIRS if a in errors and b in errors]
        if not rows:
            continue
        lines += [
            f"## {name}: paired comparisons",
            "",
            "mean SL error ratio A / B (paired difference A - B, m, mean +- standard error; estimates)",
            "",
            "| A | B | " + " | ".join(str(n) for n in COUNTS) + " | asked |",
            "|---|---|" + "---|" * len(COUNTS) + "---|",
        ]
        for a, b, goal in rows:
            cells = []
            for n in COUNTS:
                keys = sorted(k for k in errors[a] if k[1] == n and k in errors[b])
                x = np.array([errors[a][k] for k in keys])
                y = np.array([errors[b][k] for k in keys])
                if len(keys) < 2:
                    cells.append("-")
                    continue
                d = x - y
                se = d.std(ddof=1) / np.sqrt(len(d))
                cells.append(f"{x.mean() / y.mean():.2f} ({d.mean():+.2f} +- {se:.2f}; {len(d)})")
            lines.append(f"| {a} | {b} | " + " | ".join(cells) + f" | {goal} |")
        lines.append("")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_gsl"))
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--sets", nargs="+", default=["reference", "test"], choices=["reference", "test"])
    ap.add_argument(
        "--methods",
        nargs="+",
        default=None,
        metavar="METHOD@LEVEL",
        help="only these rows, e.g. dgse-phys@openings adjoint-oracle@wind (default: all)",
    )
    ap.add_argument(
        "--reference",
        type=Path,
        default=Path(
            os.environ.get(
                "DGSE_REFERENCE_CASES", Path(__file__).resolve().parents[2] / "shared" / "reference-cases"
            )
        ),
    )
    ap.add_argument("--summary-only", action="store_true", help="summarize the folder's results, run nothing")
    ap.add_argument(
        "--workers", type=int, default=1, help="processes, one case and count of a row each (module doc)"
    )
    ap.add_argument("--rounds", type=int, default=None, help="with --workers: trials per round (default all)")
    ap.add_argument("--time-limit", type=float, default=None, help="with --workers: stop after this many s")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = METHODS
    if args.methods:
        known = {f"{m}@{lv}": (m, lv) for m, lv in METHODS}
        bad = [x for x in args.methods if x not in known]
        if bad:
            ap.error(f"unknown rows {bad}; choose from {sorted(known)}")
        rows = [known[x] for x in args.methods]
    table: dict = {}
    sets = [] if args.summary_only else args.sets
    sources = {name: args.reference if name == "reference" else _test_cases(args.out) for name in sets}
    if args.workers < 1 or (args.rounds is not None and args.rounds < 1):
        ap.error("--workers and --rounds must be at least 1")
    if sets and args.workers > 1:
        try:
            done = run_parallel(
                rows,
                sources,
                args.out,
                args.trials,
                args.workers,
                args.rounds or args.trials,
                args.time_limit,
            )
        except KeyboardInterrupt:
            raise SystemExit(
                "interrupted: the finished estimates are kept; the same command resumes"
            ) from None
        if not done:
            return
    for name in sets:
        for method, level in rows:
            out = args.out / f"{name}_{method}_{level}.json"
            res = evaluate(
                sources[name], method, COUNTS, trials=args.trials, seed=0, knowledge=level,
                journal=journal_path(out), progress=True,
            )  # fmt: skip
            write_json(res, out)
    # the summary covers every row in the folder, this run's and earlier runs' (one method per
    # process is the way to use both cores)
    per_estimate: dict[str, dict[str, dict[tuple, float]]] = {}
    for name in ("reference", "test"):
        for method, level in METHODS:
            path = args.out / f"{name}_{method}_{level}.json"
            if not path.exists():
                continue
            res = json.loads(path.read_text())
            per_estimate.setdefault(name, {})[f"{method}@{level}"] = {
                (r["case"], r["n_obs"], r["trial"]): r["sl_error_m"] for r in res["per_case"]
            }
            seconds = [r["seconds"] for r in res["per_case"] if r.get("seconds") is not None]
            table.setdefault(name, {})[f"{method}@{level}"] = {
                "trials": res["trials"],
                "median_seconds": float(np.median(seconds)) if seconds else None,
                **{
                    n: {
                        k: res["aggregate"][str(n)].get(k)
                        for k in ("sl_error_m_mean", "sl_error_m_median", "ce_mean")
                    }
                    for n in COUNTS
                },
            }
    lines = []
    for name, rows in table.items():
        lines += [
            f"## {name}",
            "",
            "SL error mean / median (m), CE mean (nats); trials per case; the median seconds an estimate "
            "took (as the run was made: with --workers N, N estimates at a time)",
            "",
        ]
        lines.append("| method@knowledge | trials | " + " | ".join(str(n) for n in COUNTS) + " | median s |")
        lines.append("|---|---|" + "---|" * (len(COUNTS) + 1))
        for key, by_n in rows.items():
            cells = [
                f"{v['sl_error_m_mean']:.2f} / {v['sl_error_m_median']:.2f} / {v['ce_mean']:.1f}"
                for n, v in by_n.items()
                if n in COUNTS
            ]
            secs = by_n["median_seconds"]
            cells.append("-" if secs is None else f"{secs:.2f}")
            lines.append(f"| {key} | {by_n['trials']} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += _comparisons(per_estimate)
    write_text(args.out / "summary.md", "\n".join(lines))
    write_text(args.out / "summary.json", json.dumps(table, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
