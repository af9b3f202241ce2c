"""Turbulence on a frozen flow against the coupled solve's, per residual criterion (knowledge ``wind``).

For generated scenarios (one source each): the coupled RANS solve (the case's own flow), then k-epsilon
solved on that frozen flow (:func:`dgse.physics.rans.solve_turbulence`) to residuals of 1e-4 and 1e-6.
Per criterion: iterations, the median ``nu_t`` over the coupled one's, and the log(1 + ppm) RMSE between
the plume on the coupled ``nu_t`` and the plume on the frozen one.  Diagnoses why ``dgse-phys --knowledge
wind`` missed test scenario 2005 (a nearly laminar flow); the tolerance itself was chosen with
``benchmarks/tune_projection.py`` on validation seeds.

    python benchmarks/frozen_turbulence.py --seeds 900-911,2005 \\
        -o benchmarks/results/frozen_turbulence.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from phys_robustness import parse_seeds  # this folder's

from dgse.files import write_text
from dgse.physics.constants import DEFAULT_PHYSICS
from dgse.physics.fv import build_mesh
from dgse.physics.rans import FlowSettings, solve_flow, solve_turbulence
from dgse.physics.scenario import random_cases
from dgse.physics.transport import TransportSolver

TOLERANCES = (1e-4, 1e-6)


def scenario_row(seed: int) -> dict:
    case = random_cases(seed, n_sources=1)[0]
    mesh = build_mesh(case.layout)
    st, info = solve_flow(case.layout, mesh, case.inlet_velocity)
    cells = [case.layout.grid.cell_of(*case.source)]
    phys = DEFAULT_PHYSICS

    def plume(nut: np.ndarray) -> np.ndarray:
        c = TransportSolver.build(mesh, st.F, nut, phys).solve_cells(cells, [case.release_rate])[0]
        return np.log1p(np.maximum(c * phys.ppm_per_gm3, 0.0))

    ref = plume(st.nut)
    row = {"seed": seed, "cells": int(mesh.n), "flow_iterations": info["iterations"]}
    row["nut_median"] = float(np.median(st.nut))
    for tol in TOLERANCES:
        settings = FlowSettings(tolerance=tol, max_iterations=5000)
        _, _, nut, t_info = solve_turbulence(mesh, st.ux, st.uy, st.F, phys, settings)
        d = plume(nut) - ref
        row[f"{tol:g}"] = {
            "iterations": t_info["iterations"],
            "converged": t_info["converged"],
            "nut_median_ratio": float(np.median(nut) / np.median(st.nut)),
            "plume_log_rmse": float(np.sqrt(np.mean(d[case.free] ** 2))),
        }
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=parse_seeds, default=[*range(900, 912), 2005], help="e.g. 900-911,2005")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/frozen_turbulence.json"))
    args = ap.parse_args()
    rows = []
    for seed in args.seeds:
        rows.append(scenario_row(seed))
        r = rows[-1]
        print(
            f"{seed}: median nu_t {r['nut_median']:.1e}; "
            + "; ".join(
                f"tol {t:g}: {r[f'{t:g}']['iterations']} it, nu_t x{r[f'{t:g}']['nut_median_ratio']:.2f}, "
                f"plume RMSE {r[f'{t:g}']['plume_log_rmse']:.3f}"
                for t in TOLERANCES
            ),
            flush=True,
        )
    write_text(args.out, json.dumps({"tolerances": TOLERANCES, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
