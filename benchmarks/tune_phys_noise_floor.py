"""Check dgse-phys's prior floor on the noise scale on generated validation scenarios.

Source-localization error and cross-entropy of ``dgse-phys --knowledge openings``
from 5, 20, 50 and 150 random readings (Table I noise), 2 trials on each of 12 generated
scenarios (seeds 900-911, a range kept for validation).  The floor (the prior noise scale
kept at least a share of the flows' mean concentrations, ``"always"``, or while fewer than
two readings are positive, ``"unscaled"``) was measured against none (``"never"``) and
removed (``docs/dgse-phys.md``); the script runs the estimator as it is, the ``"never"`` row.

    python benchmarks/tune_phys_noise_floor.py -o benchmarks/results/phys_noise_floor.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from phys_tuning import sweep, write_rows  # this folder's

SEEDS = range(900, 912)
COUNTS = (5, 20, 50, 150)
SETTINGS: dict[str, dict] = {"never": {}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_noise_floor.json"))
    ap.add_argument("--seeds", type=int, default=len(SEEDS), help="only the first N scenarios")
    args = ap.parse_args()
    names = list(SETTINGS)
    seeds = list(SEEDS)[: args.seeds]
    err, ce = sweep("openings", names, SETTINGS.__getitem__, seeds, COUNTS, trials=2)
    write_rows(args.out, err, ce, names, COUNTS, {"seeds": seeds, "trials": 2})


if __name__ == "__main__":
    main()
