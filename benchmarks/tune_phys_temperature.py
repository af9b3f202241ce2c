"""Choose dgse-phys's tempering on generated validation scenarios.

Source-localization error and cross-entropy of ``dgse-phys --knowledge openings``
for power posteriors with temperature ``T`` (the gas evidence divided by
``T``), from 20, 50, 150 and 300 random readings (Table I noise), 2 trials on
each of 12 generated scenarios (seeds 900-911, a range kept for validation).
The chosen rule, ``T = max(1, m / effective_readings)``, is evaluated too.

    python benchmarks/tune_phys_temperature.py -o benchmarks/results/phys_temperature.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from phys_tuning import sweep, write_rows  # this folder's

SEEDS = range(900, 912)
COUNTS = (20, 50, 150, 300)
SETTINGS = {
    **{f"T={t:g}": {"temperature": t, "effective_readings": float("inf")} for t in (1.0, 2.0, 4.0, 8.0)},
    **{f"m_eff={m:g}": {"temperature": 1.0, "effective_readings": m} for m in (50.0, 100.0)},
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
