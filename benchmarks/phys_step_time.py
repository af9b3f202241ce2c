"""Search step cost of dgse-phys (issue 12, part 4): the first estimate and the median step.

Runs one search episode per scenario (the first test scenarios of
``benchmarks/phys_search.py``, knowledge ``openings`` or ``--knowledge map``, the planner and estimator
settings of a search, ``search_planner`` and ``search_estimator``) and writes the
computation seconds of every step: the first (which solves the flows) and the median and
90th percentile of the rest, per episode and (the median) pooled over the episodes.
Run it on an otherwise idle machine; the number of cores it had is recorded::

    python benchmarks/phys_step_time.py --cases 2
    python benchmarks/phys_step_time.py --cases 2 --knowledge map   # step_time_map.json
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np
from phys_search import cases_dir

from dgse.files import write_text
from dgse.presets import PRESETS
from dgse.search.campaign import run_trials


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=2)
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_search"))
    ap.add_argument("--knowledge", choices=("openings", "map"), default="openings")
    args = ap.parse_args()
    d = cases_dir(args.out, "test", args.cases)
    rows = []
    for path in sorted(d.glob("*.npz")):
        res = run_trials(
            path,
            "dgse-phys",
            "utility",
            trials=1,
            planner_options={
                "stop.min_observations": 5,
                **PRESETS["dgse-phys"].planner_options_at(args.knowledge),
            },
            estimator_options=PRESETS["dgse-phys"].estimator_options_at(args.knowledge, search=True),
            knowledge=args.knowledge,
            steps=True,
        )
        trial = res["per_case"][0]["trials"][0]
        s = np.array([st["compute_s"] for st in trial["steps"]])
        rows.append(
            {
                "case": path.stem,
                "steps": int(s.size),
                "first_s": float(s[0]),
                "median_s": float(np.median(s[1:])),
                "p90_s": float(np.percentile(s[1:], 90)),
                "error_m": trial["error_m"],
                "step_s": [round(float(x), 4) for x in s],
            }
        )
        print(json.dumps({k: v for k, v in rows[-1].items() if k != "step_s"}), flush=True)
    out = {
        "cores": os.cpu_count(),
        "load_average_at_end": os.getloadavg(),
        "estimator_options": PRESETS["dgse-phys"].estimator_options_at(args.knowledge, search=True),
        "knowledge": args.knowledge,
        "episodes": rows,
        # every step after each episode's first, pooled over the episodes
        "median_all_s": float(np.median(np.concatenate([r["step_s"][1:] for r in rows]))),
    }
    name = "step_time.json" if args.knowledge == "openings" else f"step_time_{args.knowledge}.json"
    path = args.out / name
    write_text(path, json.dumps(out, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
