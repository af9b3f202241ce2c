"""Choose how much dgse-phys trusts its physics at knowledge ``map`` (validation scenarios).

At ``map`` the flows are solved for proposed openings (approximate windows),
so the model's error is larger than with the openings known.  Two knobs:
``hypothesis_readings`` caps the readings the comparison of flow hypotheses
counts (their log weights divided by ``m / hypothesis_readings``), and
``effective_readings`` the readings the gas evidence counts (the power
posterior's temperature ``m / effective_readings``).  Source-localization error and cross-entropy from
20, 50 and 150 random readings, one trial on each of 8 generated scenarios
(seeds 900-907, kept for validation); the proposals are made once per
reading set and shared by every setting.

    python benchmarks/tune_phys_map.py -o benchmarks/results/phys_map_tuning.json
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np
from tune_phys_temperature import write_rows  # this folder's

from dgse.estimators.knowledge import Knowledge
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.physics.scenario import random_cases

SEEDS = range(900, 908)
COUNTS = (20, 50, 150)
#: (hypothesis_readings, effective_readings)
SETTINGS = ((None, 100.0), (5.0, 100.0), (None, 30.0), (None, 10.0), (None, 3.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_map_tuning.json"))
    args = ap.parse_args()
    err: dict = defaultdict(list)
    ce: dict = defaultdict(list)
    for seed in SEEDS:
        case = random_cases(seed, n_sources=1)[0]
        k = Knowledge.from_case(case, "map")
        cell = case.layout.grid.cell_of(*case.source)
        for n in COUNTS:
            obs = draw_observations(case, n, seed=0)
            shared = None
            for s in SETTINGS:
                est = get_estimator(
                    "dgse-phys", knowledge=k, hypothesis_readings=s[0], effective_readings=s[1]
                )
                if shared is not None:
                    est._hypotheses, est._proposed_at, est._proposed_from = shared
                b = est.estimate(case.occupancy, case.resolution, obs)
                shared = (est._hypotheses, est._proposed_at, est._proposed_from)
                err[s, n].append(b.localization_error(tuple(case.source)))
                ce[s, n].append(-float(np.log(max(b.source_probs[cell], 1e-12))))
        print(f"scenario {seed} done", flush=True)
    write_rows(args.out, err, ce, list(SETTINGS), COUNTS, {"seeds": list(SEEDS), "trials": 1})


if __name__ == "__main__":
    main()
