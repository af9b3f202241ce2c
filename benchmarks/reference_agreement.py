"""The built-in solver on every OpenFOAM reference case, run through ``dgse solve``.

For each case of ``../shared/reference-cases`` (or ``$DGSE_REFERENCE_CASES``):
``dgse solve CASE -o OUT --engine builtin`` re-solves its layout, inlet,
inlet velocity, source and release rate; the result is compared with the
OpenFOAM fields: relative L2 error of the velocity over free cells, RMSE of
``log(1 + ppm)`` over free cells, and the scalar outflow over the release rate.

    python benchmarks/reference_agreement.py

Writes ``benchmarks/results/reference_agreement.{json,md}``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dgse.files import write_text
from dgse.world.case import Case

REPO = Path(__file__).resolve().parents[1]
REFERENCE = Path(os.environ.get("DGSE_REFERENCE_CASES", REPO.parent / "shared" / "reference-cases"))
LIMITS = {"velocity_rel_l2": 0.15, "log_ppm_rmse": 0.3, "outflow_error": 0.02}


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in sorted(REFERENCE.glob("*.npz")):
            out = Path(tmp) / path.name
            cmd = [sys.executable, "-m", "dgse.cli.main", "solve", str(path), "-o", str(out)]
            t = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            wall = time.perf_counter() - t
            ref, new = Case.load(path), Case.load(out)
            f = ref.free
            vel = np.linalg.norm((new.wind - ref.wind)[:, f]) / np.linalg.norm(ref.wind[:, f])
            d = (np.log1p(new.concentration) - np.log1p(ref.concentration))[f]
            ratio = new.meta["mass_balance"]["outlet_flux_ratio"]
            rows.append(
                {
                    "case": path.stem,
                    "cells": f"{ref.grid.width}x{ref.grid.height}",
                    "velocity_rel_l2": float(vel),
                    "log_ppm_rmse": float(np.sqrt(np.mean(d**2))),
                    "outlet_flux_ratio": float(ratio),
                    "outflow_error": abs(ratio - 1.0),
                    "flow_iterations": new.meta["iterations"]["flow"],
                    "dgse_solve_wall_s": wall,
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    ok = all(r[k] <= v for r in rows for k, v in LIMITS.items())
    res = REPO / "benchmarks" / "results"
    res.mkdir(parents=True, exist_ok=True)
    write_text(
        res / "reference_agreement.json",
        json.dumps({"limits": LIMITS, "all_within": ok, "cases": rows}, indent=1),
    )
    lines = [
        "| case | cells | velocity rel. L2 | log(1+ppm) RMSE | outlet flux / q | flow iterations | "
        "`dgse solve` wall s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['cells']} | {r['velocity_rel_l2']:.3f} | {r['log_ppm_rmse']:.3f} | "
            f"{r['outlet_flux_ratio']:.4f} | {r['flow_iterations']} | {r['dgse_solve_wall_s']:.1f} |"
        )
    lines.append(f"\nLimits (issue): velocity <= 0.15, RMSE <= 0.3, outflow within 2 %. All within: {ok}.")
    write_text(res / "reference_agreement.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
