"""Time of one estimate of every registered estimator against the map size (issue 14, part 4).

Each estimator gets the same 50 random readings (Table I noise) on paper-size test
scenarios (``benchmarks/phys_search.py``'s, 0.1 m cells) and on generated office
floors (``benchmarks/building_search.py``'s, 20-30 m at 0.2 m cells), at the lowest
knowledge level it works at (``dgse-phys`` at ``openings``, as the building
searches ran it), and is timed on a fresh instance: the first estimate on a map,
with whatever the estimator solves or loads for that map, and then a second
estimate with 5 more readings on the same instance (what a search step costs where
the estimator keeps state).  Each estimate has ``--limit`` seconds (``SIGALRM``):
one that runs over is reported as such.

    python benchmarks/estimator_time_vs_size.py --paper 2 --floors 2

Writes ``benchmarks/results/estimator_time_vs_size.{json,md}``.  Run it on an idle
machine; the load average at the end is recorded.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import time
from pathlib import Path

from building_search import make_cases  # this folder's
from phys_search import cases_dir  # this folder's

from dgse.belief.knowledge import Knowledge
from dgse.errors import DGSEError
from dgse.estimators.registry import estimator_names, get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.files import write_text
from dgse.world.case import Case

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
#: the knowledge each estimator is timed at: its lowest level, dgse-phys as searched
LEVEL = {"dgse-phys": "openings"}


class _Overrun(Exception):
    pass


def _alarm(_signum, _frame):
    raise _Overrun


def _timed(fn, limit: float) -> float | None:
    signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, limit)
    t = time.perf_counter()
    try:
        fn()
    except _Overrun:
        return None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    return time.perf_counter() - t


def time_estimator(name: str, case: Case, limit: float) -> dict:
    est = get_estimator(name)
    levels = tuple(getattr(est, "knowledge_levels", ("map",)))
    level = LEVEL.get(name, levels[0])
    est.set_knowledge(Knowledge.from_case(case, level))
    obs = draw_observations(case, 55, seed=0)
    first, more = obs.take(slice(0, 50)), obs
    row: dict = {"estimator": name, "knowledge": level}
    row["first_s"] = _timed(lambda: est.estimate(case.occupancy, case.resolution, first), limit)
    if row["first_s"] is not None:
        row["next_s"] = _timed(lambda: est.estimate(case.occupancy, case.resolution, more), limit)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--paper", type=int, default=2, help="paper-size test scenarios")
    ap.add_argument("--floors", type=int, default=2, help="office floors")
    ap.add_argument("--estimators", nargs="*", default=None, help="default: every registered one")
    ap.add_argument("--limit", type=float, default=300.0, help="seconds per estimate")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    names = args.estimators or estimator_names()
    paths = sorted(cases_dir(RESULTS / "phys_search", "test", args.paper).glob("*.npz"))
    # the floors' folder is the building search's: it may hold more floors than asked for
    floors = make_cases(RESULTS / "building_search", args.floors, 0.2, (20.0, 30.0))
    paths += sorted(floors.glob("building*.npz"))[: args.floors]
    rows = []
    for path in paths:
        case = Case.load(path)
        for name in names:
            row = {"case": path.stem, "free_cells": int(case.free.sum()), "cell_m": float(case.resolution)}
            try:
                row |= time_estimator(name, case, args.limit)
            except DGSEError as e:  # e.g. a network trained on 0.1 m cells, on a 0.2 m floor
                row |= {"estimator": name, "error": str(e)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    result = {
        "cores": os.cpu_count(),
        "load_average_at_end": os.getloadavg(),
        "limit_s": args.limit,
        "rows": rows,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "estimator_time_vs_size.json", json.dumps(result, indent=1))
    cases = list(dict.fromkeys((r["case"], r["free_cells"], r["cell_m"]) for r in rows))

    def cell(r: dict | None, key: str) -> str:
        if r is not None and "error" in r:
            return "error"
        if r is None or key not in r:
            return "-"
        return f"over {args.limit:g}" if r[key] is None else f"{r[key]:.2f}"

    md = [
        "One estimate from 50 random readings (first on the map: `first`), then one from 55 on the "
        "same instance (`next`), seconds; each estimator at its lowest knowledge level (dgse-phys at "
        f"`openings`). `python benchmarks/estimator_time_vs_size.py --paper {args.paper} --floors "
        f"{args.floors}`; {os.cpu_count()} cores, load average at the end "
        f"{', '.join(f'{x:.2f}' for x in result['load_average_at_end'])}.",
        "",
        "| estimator | knowledge | "
        + " | ".join(f"{c} ({n} cells, {m:g} m) first / next" for c, n, m in cases)
        + " |",
        "|---|---|" + "---|" * len(cases),
    ]
    for name in names:
        by_case = {r["case"]: r for r in rows if r["estimator"] == name}
        level = next((r["knowledge"] for r in by_case.values() if "knowledge" in r), "-")
        cells = [f"{cell(by_case.get(c), 'first_s')} / {cell(by_case.get(c), 'next_s')}" for c, _, _ in cases]
        md.append(f"| {name} | {level} | " + " | ".join(cells) + " |")
    errors = sorted({f"{r['estimator']}: {r['error']}" for r in rows if "error" in r})
    if errors:
        md += ["", "Errors (the estimator refused the map):", ""] + [f"* {e}" for e in errors]
    write_text(args.out / "estimator_time_vs_size.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
