"""How confident and how wrong DGSE-S is from very few random readings (why ``min_observations``).

    python benchmarks/few_readings.py benchmarks/results/report/_scenarios/test-20 \\
        --counts 1 2 3 4 5 10 20 50 --trials 5 -o benchmarks/results/few_readings.json

For each case file of the folder and each number of readings, ``--trials``
sets of random readings (Table I noise, seeded), the shipped DGSE-S's
normalized source entropy ``H / log N`` and localization error.  The
networks were trained on 5 to 300 readings; the entropy test of the utility
planner (``H <= eta log N``) is only meaningful where the network has been
trained.  Writes per-case and pooled statistics to the JSON file and prints
the pooled table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dgse.estimators.registry import get_estimator
from dgse.files import write_text
from dgse.sensing.sensors import random_observations
from dgse.world.case import Case


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases", type=Path, help="folder of case files (.npz)")
    ap.add_argument("--counts", type=int, nargs="+", default=[1, 2, 3, 4, 5, 10, 20, 50])
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--eta", type=float, default=0.78, help="threshold to count estimates below")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()

    est = get_estimator("dgse-s", model="default", dtype="bf16", channels_last=True)
    files = sorted(args.cases.glob("*.npz"))
    if not files:
        raise SystemExit(f"no case files in {args.cases}")
    per_case = []
    pooled: dict[int, dict[str, list[float]]] = {n: {"h": [], "err": []} for n in args.counts}
    for k, f in enumerate(files):
        case = Case.load(f)
        rng = np.random.default_rng([args.seed, k])
        row: dict[str, object] = {"case": f.stem}
        for n in args.counts:
            hs, errs = [], []
            for _ in range(args.trials):
                b = est.estimate(case.occupancy, case.resolution, random_observations(case, n, rng))
                hs.append(float(b.normalized_entropy()))
                errs.append(float(np.hypot(*(np.asarray(b.source_estimate()) - case.source))))
            row[str(n)] = {"entropy": hs, "error_m": errs}
            pooled[n]["h"] += hs
            pooled[n]["err"] += errs
        per_case.append(row)
    summary = {}
    print(f"{'readings':>8} {'H/logN median':>14} {'min':>6} {'below eta':>10} {'err below eta (m)':>18}")
    for n in args.counts:
        h, e = np.array(pooled[n]["h"]), np.array(pooled[n]["err"])
        below = h <= args.eta
        summary[str(n)] = {
            "estimates": int(h.size),
            "normalized_entropy_median": float(np.median(h)),
            "normalized_entropy_min": float(h.min()),
            "share_below_eta": float(below.mean()),
            "error_m_mean": float(e.mean()),
            "error_m_mean_below_eta": float(e[below].mean()) if below.any() else None,
        }
        s = summary[str(n)]
        eb = "-" if s["error_m_mean_below_eta"] is None else f"{s['error_m_mean_below_eta']:.2f}"
        print(
            f"{n:>8} {s['normalized_entropy_median']:>14.3f} {s['normalized_entropy_min']:>6.3f} "
            f"{s['share_below_eta']:>10.2f} {eb:>18}"
        )
    out = {
        "cases": str(args.cases),
        "trials": args.trials,
        "eta": args.eta,
        "seed": args.seed,
        "model": "default (dgse-s), bf16",
        "pooled": summary,
        "per_case": per_case,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps(out, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
