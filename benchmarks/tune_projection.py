"""Choose the settings of dgse.physics.projection on generated validation scenarios.

A given wind (here: the built-in RANS wind of a generated scenario, as a user's
CFD would give it) is made mass-conserving and given an eddy viscosity; the
forward concentration on that flow is compared with the scenario's own in
log(1 + ppm) over the free cells.  Scenarios: ``dgse.physics.scenario.random_cases``
with seeds 900-907 (two sources each), a seed range kept for validation
(the test and reference scenarios are never used here).

    python benchmarks/tune_projection.py -o benchmarks/results/projection_tuning.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from dgse.files import write_text
from dgse.physics.projection import TURBULENCE_TOLERANCE, project_wind, transport_from_wind
from dgse.physics.scenario import random_cases

VALIDATION_SEEDS = range(900, 908)
#: (openings known?, closure, open_fraction, frozen k-epsilon tolerance)
SETTINGS = [
    (True, "k-epsilon", None, TURBULENCE_TOLERANCE),
    (True, "k-epsilon", None, 1e-4),
    (True, "mixing-length", None, None),
    *[(False, "k-epsilon", f, TURBULENCE_TOLERANCE) for f in (0.1, 0.3, 0.5, 0.75, 1.0, 1.5)],
    (False, "k-epsilon", 0.75, 1e-4),
    (False, "mixing-length", 0.75, None),
]


def log_rmse(c: np.ndarray, truth: np.ndarray, free: np.ndarray) -> float:
    d = np.log1p(np.maximum(c, 0.0)) - np.log1p(truth)
    return float(np.sqrt(np.mean(d[free] ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/projection_tuning.json"))
    args = ap.parse_args()
    scenarios = [random_cases(seed, n_sources=2) for seed in VALIDATION_SEEDS]
    rows = []
    for known, closure, fraction, tol in SETTINGS:
        errs, secs = [], []
        for cases in scenarios:
            c0 = cases[0]
            kw: dict = {"layout": c0.layout} if known else {"open_fraction": fraction}
            if tol is not None:
                kw["turbulence_tolerance"] = tol
            t0 = time.perf_counter()
            flow = project_wind(c0.occupancy, c0.resolution, c0.wind, closure=closure, **kw)
            ts = transport_from_wind(flow)
            cells = [c0.layout.grid.cell_of(*c.source) for c in cases]
            fields = ts.solve_cells(cells, [c.release_rate for c in cases])
            secs.append(time.perf_counter() - t0)
            for c, f in zip(cases, fields, strict=True):
                errs.append(log_rmse(f * ts.physics.ppm_per_gm3, c.concentration, c.free))
        row = {
            "openings": "known" if known else "unknown (map edges)",
            "closure": closure,
            "open_fraction": fraction,
            "turbulence_tolerance": tol,
            "log_rmse_mean": float(np.mean(errs)),
            "log_rmse_median": float(np.median(errs)),
            "log_rmse_max": float(np.max(errs)),
            "seconds_median": float(np.median(secs)),
        }
        rows.append(row)
        print(
            f"{row['openings']:20s} {closure:13s} open_fraction {fraction!s:5s} tol {tol!s:6s} "
            f"log RMSE mean {row['log_rmse_mean']:.3f} median {row['log_rmse_median']:.3f} "
            f"max {row['log_rmse_max']:.3f}; {row['seconds_median']:.2f} s per flow",
            flush=True,
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps({"seeds": list(VALIDATION_SEEDS), "rows": rows}, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
