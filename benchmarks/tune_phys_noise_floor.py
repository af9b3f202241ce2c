"""Check dgse-phys's prior floor on the noise scale on generated validation scenarios.

Source-localization error and cross-entropy of ``dgse-phys --knowledge openings``
with each ``noise_floor_prior`` (when the prior noise scale is kept at least the floor
from the flows' mean concentrations, :func:`dgse.posterior.adjoint.prior_noise_floor`), from 5,
20, 50 and 150 random readings (Table I noise), 2 trials on each of 12 generated
scenarios (seeds 900-911, a range kept for validation).  The floor matters where
few readings are positive, so the low counts are the ones to read.

    python benchmarks/tune_phys_noise_floor.py -o benchmarks/results/phys_noise_floor.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from phys_tuning import sweep, write_rows  # this folder's

SEEDS = range(900, 912)
COUNTS = (5, 20, 50, 150)
SETTINGS = {
    "always": {"noise_floor_prior": "always"},
    "unscaled": {"noise_floor_prior": "unscaled"},
    "never": {"noise_floor_prior": "never"},
}


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
