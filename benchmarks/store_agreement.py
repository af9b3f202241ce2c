"""How a rebuilt dataset store compares with the statistics recorded of the original.

``dgse generate --split test`` rebuilds a dataset's test layouts without the rest (the
same layouts, inlet speeds and sources: each layout's draws depend on the seed and its
index alone), but solves them with today's solver.  This compares the rebuilt store's
:func:`dgse.data.stats.dataset_stats` with the ones recorded of the original store, layout
by layout and case by case::

    dgse generate --layouts 1000 --out dgse1000.h5 --split test
    python benchmarks/store_agreement.py dgse1000.h5 benchmarks/results/dataset_stats.json \\
        -o benchmarks/results/store_agreement.json

The original store must have held every layout index (its ``values`` lists are in index
order, four sources a layout).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dgse.data.stats import dataset_stats
from dgse.data.store import DatasetStore
from dgse.files import write_text

#: Per-layout quantities that the draws alone decide, and those the solver decides too.
DRAWN = ("width_m", "height_m", "inlet_velocity")
SOLVED_LAYOUT = ("max_speed",)
SOLVED_CASE = ("max_ppm", "mean_ppm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store", type=Path, help="the rebuilt store")
    ap.add_argument("recorded", type=Path, help="dataset_stats JSON of the original store")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/store_agreement.json"))
    args = ap.parse_args()
    old = json.loads(args.recorded.read_text())["values"]
    new = dataset_stats(args.store)["values"]
    with DatasetStore(args.store, "r") as s:
        index = [int(lid.rsplit("-", 1)[1]) for lid in s.layouts()]
        n_src = [s.n_sources(lid) for lid in s.layouts()]
    per_source = len(old["release_rate_gps"]) // len(old["width_m"])
    cases = [per_source * i + k for i, n in zip(index, n_src, strict=True) for k in range(n)]
    report: dict[str, object] = {"store": str(args.store), "recorded": str(args.recorded)}
    report["layouts"] = len(index)
    pairs = [(q, index) for q in DRAWN] + [("release_rate_gps", cases)]
    same = [np.allclose([old[q][i] for i in where], new[q], rtol=1e-12, atol=0) for q, where in pairs]
    report["drawn_equal"] = bool(all(same))
    for q, where in [*((q, index) for q in SOLVED_LAYOUT), *((q, cases) for q in SOLVED_CASE)]:
        ratio = np.asarray(new[q], float) / np.asarray([old[q][i] for i in where], float)
        report[q] = {
            "n": int(ratio.size),
            "within_1pct": float(np.mean(np.abs(ratio - 1) < 0.01)),
            "within_5pct": float(np.mean(np.abs(ratio - 1) < 0.05)),
            "ratio_min": float(ratio.min()),
            "ratio_max": float(ratio.max()),
        }
    write_text(args.out, json.dumps(report, indent=1) + "\n")
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
