"""Active search at building scale (issue 14, part 4): dgse-phys on generated office floors.

Each scenario is a random office floor (:func:`dgse.world.building.random_office_floor`:
corridors, rooms with doors, 2-4 inlets and outlets), a random inlet speed of the
training range and one random source, solved with the built-in RANS and transport.
The utility planner with dgse-phys's search preset (``dgse.presets``) and dgse-phys with
dgse-phys's search preset (``dgse.presets``) (the settings chosen on the paper-size validation
scenarios; nothing was tuned on these floors) search each one with the openings known.
Reported: success, error, search time (ST), distance (TD), and the computation per step
against the map's size (the first estimate, which solves the flows, and the median step).

The floors are drawn at ``--resolution`` (default 0.2 m: a 30 m floor is 150 x 150
cells; at the spec's 0.1 m it would be 300 x 300, whose flow alone takes minutes per
inlet speed on 2 cores).  The time limit scales with the floor (default 4000 s,
twice the paper-size default).  Scenarios are made once into ``_cases/`` beside the
results; every finished episode is journaled, so an interrupted run resumes, and
``--summary-only`` summarizes the episodes kept so far; ``--tag`` names a run (a new
journal and result beside the others)::

    python benchmarks/building_search.py --cases 10
    python benchmarks/building_search.py --cases 10 --tag 2026-11-29
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from phys_search import write_result

from dgse.presets import PRESETS
from dgse.search.campaign import run_trials

FIRST_SEED = 3000


def make_cases(out: Path, n: int, resolution: float, size: tuple[float, float]) -> Path:
    """The first ``n`` building scenarios as case files (made once; each solve is printed)."""
    from dgse.physics.scenario import solve_cases
    from dgse.world.building import random_office_floor
    from dgse.world.generate import as_generator, random_inlet_velocity, random_sources

    d = out / f"_cases_{resolution:g}m"
    d.mkdir(parents=True, exist_ok=True)
    for seed in range(FIRST_SEED, FIRST_SEED + n):
        path = d / f"building{seed}_src0.npz"
        if path.exists():
            continue
        rng = as_generator(seed)
        t0 = time.perf_counter()
        layout = random_office_floor(rng, resolution=resolution, width_range=size, height_range=size)
        v = random_inlet_velocity(rng)
        src = random_sources(layout, rng, n=1)
        case = solve_cases(layout, v, src, name=path.stem)[0]
        case.save(path)
        print(
            f"{path.stem}: {layout.occupancy.shape[0]} x {layout.occupancy.shape[1]} cells, "
            f"v_in {v:.2f} m/s, solved in {time.perf_counter() - t0:.0f} s",
            flush=True,
        )
    return d


def summarize(out: Path, stem: str, settings: dict) -> dict:
    """Success, error, ST, TD and step times from the journal (a partial run included)."""
    from dgse.search.metrics import aggregate
    from dgse.world.case import Case

    lines = (out / f"{stem}.journal.jsonl").read_text().splitlines()[1:]
    rows, per_map = [], []
    for line in lines:
        entry = json.loads(line)
        row = entry["row"]
        steps = row.pop("steps", None) or []
        s = np.array([st["compute_s"] for st in steps])
        case = Case.load(settings["cases_dir"] + f"/{entry['case']}.npz")
        per_map.append(
            {
                "case": entry["case"],
                "cells": list(case.occupancy.shape),
                "free_cells": int(case.free.sum()),
                "first_estimate_s": float(s[0]) if s.size else None,
                "median_step_s": float(np.median(s[1:])) if s.size > 1 else None,
                "steps": int(s.size),
                "error_m": row["error_m"],
                "reason": row["reason"],
                "search_time_s": row["search_time_s"],
                "distance_m": row["distance_m"],
            }
        )
        rows.append(row["metrics"])
    return {"settings": settings, "aggregate": aggregate(rows), "episodes": per_map}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=10)
    ap.add_argument("--trials", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--resolution", type=float, default=0.2)
    ap.add_argument("--size", type=float, nargs=2, default=(20.0, 30.0), metavar=("MIN_M", "MAX_M"))
    ap.add_argument("--time-limit", type=float, default=4000.0)
    ap.add_argument(
        "--summary-only", action="store_true", help="summarize the episodes journaled so far, run nothing"
    )
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/building_search"))
    ap.add_argument("--tag", default="", help="appended to the result's and journal's names")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    cases = make_cases(args.out, args.cases, args.resolution, tuple(args.size))
    stem = f"building{args.cases}_{args.resolution:g}m_dgse-phys_openings"
    stem += f"_{args.tag}" if args.tag else ""
    planner = {"stop.min_observations": 5, **PRESETS["dgse-phys"].planner_options_at("openings")}
    estimator = PRESETS["dgse-phys"].estimator_options_at("openings", search=True)
    settings = {
        "cases_dir": str(cases),
        "resolution_m": args.resolution,
        "floor_size_m": list(args.size),
        "time_limit_s": args.time_limit,
        "planner": planner,
        "estimator": estimator,
        "knowledge": "openings",
        "trials": args.trials,
        "seed": args.seed,
    }
    if not args.summary_only:
        run_trials(
            cases,
            "dgse-phys",
            "utility",
            trials=args.trials,
            seed=args.seed,
            planner_options=planner,
            estimator_options=estimator,
            knowledge="openings",
            time_limit=args.time_limit,
            steps=True,
            journal=args.out / f"{stem}.journal.jsonl",
        )
    result = summarize(args.out, stem, settings)
    # how busy the machine was: step times are only comparable on an otherwise idle machine
    result["machine"] = {"cores": os.cpu_count(), "load_average_at_end": list(os.getloadavg())}
    write_result(args.out / f"{stem}.json", result, stem)


if __name__ == "__main__":
    main()
