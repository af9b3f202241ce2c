"""Choose how dgse-phys mixes in DGSE-S's source belief at knowledge ``map`` (validation scenarios).

At ``map`` with few readings the physics flows rest on openings proposed from
a handful of wind readings, and DGSE-S localizes better.  ``dgse-phys`` mixes
the two posteriors with DGSE-S's weight ``learned_weight * max(0, 1 - m /
learned_readings)``.  Source-localization error and cross-entropy from 5, 10,
20 and 40 random readings, one trial on each of 8 generated scenarios (seeds
900-907, kept for validation); the opening proposals and flows are shared by
every setting of a reading set.

    python benchmarks/tune_phys_learned.py -o benchmarks/results/phys_learned_tuning.json
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
COUNTS = (5, 10, 20, 40)
#: (learned_weight, learned_readings)
SETTINGS = ((0.0, 20.0), (0.5, 20.0), (0.9, 20.0), (0.5, 50.0), (0.9, 50.0), (1.0, 1e9))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_learned_tuning.json"))
    args = ap.parse_args()
    err: dict = defaultdict(list)
    ce: dict = defaultdict(list)
    net = get_estimator("dgse-s", seed=0, dtype="bf16", channels_last=True)
    for seed in SEEDS:
        case = random_cases(seed, n_sources=1)[0]
        k = Knowledge.from_case(case, "map")
        cell = case.layout.grid.cell_of(*case.source)
        for n in COUNTS:
            obs = draw_observations(case, n, seed=0)
            shared = None
            for s in SETTINGS:
                est = get_estimator("dgse-phys", knowledge=k, learned_weight=s[0], learned_readings=s[1])
                est._learned = net
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
