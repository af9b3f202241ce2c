"""Choose how dgse-phys mixes in DGSE-S's source belief at knowledge ``map`` (validation scenarios).

At ``map`` with few readings the physics flows rest on openings proposed from
a handful of wind readings, and DGSE-S localizes better.  ``dgse-phys`` mixes
the two posteriors with DGSE-S's weight ``fusion.weight * max(0, 1 - m /
fusion.readings)`` (no floor at weight 0, as this was measured).  Source-localization
error and cross-entropy from 5, 10, 20 and 40 random readings, one trial on each of 8
generated scenarios (seeds 900-907, kept for validation); the opening proposals and flows
are shared by every setting of a reading set.

    python benchmarks/tune_phys_learned.py -o benchmarks/results/phys_learned_tuning.json
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from phys_tuning import sweep, write_rows  # this folder's

from dgse.estimators.registry import get_estimator

SEEDS = range(900, 908)
COUNTS = (5, 10, 20, 40)
#: (fusion.weight at map, fusion.readings)
SETTINGS = ((0.0, 20.0), (0.5, 20.0), (0.9, 20.0), (0.5, 50.0), (0.9, 50.0), (1.0, 1e9))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_learned_tuning.json"))
    args = ap.parse_args()
    net = get_estimator("dgse-s", seed=0, dtype="bf16", channels_last=True)  # one network for all

    def share_network(est: Any) -> None:
        est._networks["default"] = net

    err, ce = sweep(
        "map",
        SETTINGS,
        lambda s: {
            "fusion.weight.map": s[0],
            "fusion.readings": s[1],
            **({"fusion.floor": 0.0} if s[0] == 0 else {}),
        },
        SEEDS,
        COUNTS,
        prepare=share_network,
    )
    write_rows(args.out, err, ce, list(SETTINGS), COUNTS, {"seeds": list(SEEDS), "trials": 1})


if __name__ == "__main__":
    main()
