"""dgse-phys's first estimate and median search step against the map size (issue 14).

Joins what two search benchmarks recorded, without running anything: the
paper-size test scenarios of ``benchmarks/phys_step_time.py``
(``phys_search/step_time.json``, 0.1 m cells) and the 20-30 m office floors of
``benchmarks/building_search.py`` (``building_search/*.json``, 0.2 m cells),
both with the openings known.  Per episode: free cells, the first estimate
(which solves the flows of the inlet-speed candidates) and the median of the
other steps, then both against the free cells by bins.  The machine load of
each run is what those files say (the building runs shared the 2 cores with
other work).

    python benchmarks/phys_time_vs_size.py

Writes ``benchmarks/results/phys_time_vs_size.{json,md}``.
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"


def paper_size_episodes(step_time: Path) -> list[dict]:
    from phys_search import cases_dir  # this folder's

    from dgse.world.case import Case

    d = json.loads(step_time.read_text())
    folder = cases_dir(RESULTS / "phys_search", "test", len(d["episodes"]))
    out = []
    for e in d["episodes"]:
        case = Case.load(folder / f"{e['case']}.npz")
        out.append(
            {
                "set": "paper-size test scenarios",
                "case": e["case"],
                "free_cells": int(case.free.sum()),
                "resolution_m": float(case.resolution),
                "first_estimate_s": e["first_s"],
                "median_step_s": e["median_s"],
                "steps": e["steps"],
            }
        )
    return out


def building_episodes(d: dict) -> list[dict]:
    res = d["settings"]["resolution_m"]
    return [
        {
            "set": "office floors 20-30 m",
            "case": e["case"],
            "free_cells": e["free_cells"],
            "resolution_m": res,
            "first_estimate_s": e["first_estimate_s"],
            "median_step_s": e["median_step_s"],
            "steps": e["steps"],
        }
        for e in d["episodes"]
        if e["first_estimate_s"] is not None
    ]


def main() -> None:
    from dgse.files import write_text

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--step-time", type=Path, default=RESULTS / "phys_search" / "step_time.json")
    building = RESULTS / "building_search" / "building10_0.2m_dgse-phys_openings_2026-11-29.json"
    ap.add_argument("--building", type=Path, default=building)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    args.step_time, args.building = args.step_time.resolve(), args.building.resolve()
    building_result = json.loads(args.building.read_text())
    rows = paper_size_episodes(args.step_time) + building_episodes(building_result)
    machine = building_result.get("machine")
    load = (
        "the building searches shared the 2 cores with one or two other runs"
        if machine is None  # runs before 2026-11-29 recorded no load
        else f"load average {machine['load_average_at_end'][1]:.1f} on {machine['cores']} cores over the "
        "building run's last 5 minutes"
    )
    rows.sort(key=lambda r: r["free_cells"])
    edges = [0, 5000, 10000, 15000, 20000, 10**9]
    bins = []
    for lo, hi in itertools.pairwise(edges):
        sel = [r for r in rows if lo <= r["free_cells"] < hi]
        if sel:
            bins.append(
                {
                    "free_cells": f"{lo}-{hi if hi < 10**9 else ''}",
                    "episodes": len(sel),
                    "first_estimate_s_median": float(np.median([r["first_estimate_s"] for r in sel])),
                    "median_step_s_median": float(np.median([r["median_step_s"] for r in sel])),
                }
            )
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "phys_time_vs_size.json", json.dumps({"bins": bins, "episodes": rows}, indent=1))
    md = [
        "dgse-phys with the openings known, one search per scenario: the first estimate (flows of the "
        "inlet-speed candidates solved) and the median of the other steps' computation, against the "
        "map's free cells (`python benchmarks/phys_time_vs_size.py`, from "
        f"`{args.step_time.relative_to(REPO)}` and `{args.building.relative_to(REPO)}`; {load}).",
        "",
        "| free cells | episodes | first estimate s (median) | median step s (median) |",
        "|---|---|---|---|",
    ]
    md += [
        f"| {b['free_cells']} | {b['episodes']} | {b['first_estimate_s_median']:.1f} | "
        f"{b['median_step_s_median']:.2f} |"
        for b in bins
    ]
    md += ["", "| set | case | free cells | cell m | first estimate s | median step s | steps |"]
    md += ["|---|---|---|---|---|---|---|"]
    md += [
        f"| {r['set']} | {r['case']} | {r['free_cells']} | {r['resolution_m']:g} | "
        f"{r['first_estimate_s']:.1f} | {r['median_step_s']:.2f} | {r['steps']} |"
        for r in rows
    ]
    write_text(args.out / "phys_time_vs_size.md", "\n".join(md) + "\n")
    print("\n".join(md[:12]))


if __name__ == "__main__":
    main()
