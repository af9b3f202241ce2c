"""Choose dgse-phys's tempering on generated validation scenarios.

Source-localization error and cross-entropy of ``dgse-phys --knowledge openings``
for power posteriors with temperature ``T = max(1, m / effective_readings)`` (the gas
evidence divided by ``T``; ``inf``: never tempered), from 20, 50, 150 and 300 random
readings (Table I noise), 2 trials on each of 12 generated scenarios (seeds 900-911, a
range kept for validation).  (Constant temperatures ``T = 2, 4, 8`` were measured here too
and their option removed.)

    python benchmarks/tune_phys_temperature.py -o benchmarks/results/phys_temperature.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from phys_tuning import sweep, write_rows  # this folder's

SEEDS = range(900, 912)
COUNTS = (20, 50, 150, 300)
SETTINGS = {
    f"m_eff={m:g}": {"evidence.effective_readings": m, "evidence.effective_growth": 0.0}
    for m in (float("inf"), 50.0, 100.0)
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_temperature.json"))
    args = ap.parse_args()
    names = list(SETTINGS)
    err, ce = sweep("openings", names, SETTINGS.__getitem__, SEEDS, COUNTS, trials=2)
    write_rows(args.out, err, ce, names, COUNTS, {"seeds": list(SEEDS), "trials": 2})


if __name__ == "__main__":
    main()
