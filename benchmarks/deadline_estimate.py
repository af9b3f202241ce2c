"""What a search should declare when it ends at its deadline (issue 12, knowledge ``map``).

For every episode of searches journaled with ``--steps`` (``benchmarks/phys_search.py``) that
ended at its deadline, the final belief is rebuilt from the recorded readings (dgse-phys at
``map`` with its search preset, its opening proposals made from the readings' last power of
two, as in the search) and scored with several point estimates: the posterior mean (the
paper's ``s_hat``, what searches declared), the mode, and the centre of the free cell whose
disk of 0.5, 1 or 2 m holds the most posterior mass
(:func:`dgse.planning.planners.declared_source`).  A later journal's episode replaces an earlier
one's of the same case.  The rebuilt mean must equal the journal's error (checked).

    python benchmarks/deadline_estimate.py \\
        benchmarks/results/phys_search/validation3*_map_*-gas1m_base-s0.journal.jsonl \\
        benchmarks/results/phys_search/validation3-files3_*-gas1m_fit0.7-s0.journal.jsonl \\
        -o benchmarks/results/phys_search/deadline_estimate_validation3.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from phys_search import journal_episodes, map_estimator_at_end, step_observations  # this folder's

from dgse.files import write_text
from dgse.planning.planners import Deadline, UtilityPlanner, declared_source
from dgse.presets import PRESETS
from dgse.world.case import Case

RADII = (0.5, 1.0, 2.0)
SUCCESS_M = 2.0


def episode_row(case: Case, row: dict) -> dict:
    obs = step_observations(row["steps"])
    est = map_estimator_at_end(case, obs, **PRESETS["dgse-phys"].estimator_options_at("map", search=True))
    belief = est.estimate(case.occupancy, case.resolution, obs)
    sx, sy = (float(v) for v in case.source)

    def error(xy: tuple[float, float]) -> float:
        return math.hypot(xy[0] - sx, xy[1] - sy)

    i, j = belief.most_likely_cell()
    out = {
        "journal_error_m": row["error_m"],
        "mean": error(belief.source_estimate()),
        "mode": error(((j + 0.5) * case.resolution, (i + 0.5) * case.resolution)),
        "wind_misfit": belief.info["wind_misfit"],
    }
    for r in RADII:
        planner = UtilityPlanner(deadline=Deadline(estimate_radius_m=r))
        out[f"disk{r:g}m"] = error(declared_source(planner, belief, True))
    if abs(out["mean"] - row["error_m"]) > 1e-6:
        raise SystemExit(f"rebuilt mean {out['mean']:.3f} m off, the search's {row['error_m']:.3f} m")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()
    rows = {}
    for name, (case, row) in sorted(journal_episodes(args.journals).items()):
        if row["reason"] != "deadline":
            continue
        rows[name] = episode_row(case, row)
        print(name, {k: round(v, 2) for k, v in rows[name].items()}, flush=True)
    keys = ["mean", "mode", *(f"disk{r:g}m" for r in RADII)]
    summary = {
        k: {
            "within_2m": sum(r[k] <= SUCCESS_M for r in rows.values()),
            "error_m_mean": float(np.mean([r[k] for r in rows.values()])) if rows else None,
        }
        for k in keys
    }
    summary["deadline_episodes"] = len(rows)
    write_text(args.out, json.dumps({"summary": summary, "episodes": rows}, indent=1))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
