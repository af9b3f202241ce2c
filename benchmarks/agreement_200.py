"""Built-in solver against OpenFOAM on one 200 x 200 cell multi-room floor (issue 14).

The floor is ``rooms:11:20:6`` of ``benchmarks/solver_speed.py`` (20 x 20 m at 0.1 m,
six rooms, four sources), solved by both engines in fresh processes.  Criteria of the
reference cases: velocity relative L2 at most 0.15 and ``log(1 + ppm)`` RMSE at most
0.3 per source.  Writes ``benchmarks/results/agreement_200.json``::

    python benchmarks/agreement_200.py
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from solver_speed import REPO, _scenario, errors, run

SCENARIO = "rooms:11:20:6"


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        b = run("builtin", SCENARIO, tmp)
        f = run("openfoam", SCENARIO, tmp)
        layout = _scenario(SCENARIO)[0]
        row = {
            "scenario": SCENARIO,
            "cells": list(layout.occupancy.shape),
            "cpu_count": os.cpu_count(),
            "builtin": {k: v for k, v in b.items() if not k.startswith("_")},
            "openfoam": {k: v for k, v in f.items() if not k.startswith("_")},
        }
        if b.get("converged") and f.get("converged"):
            e = errors(b["_wind"], b["_conc"], f["_wind"], f["_conc"], layout.free)
            row["builtin_vs_openfoam"] = e
            row["meets_criteria"] = e["velocity_rel_l2"] <= 0.15 and max(e["log_conc_rmse"]) <= 0.3
        row["speedup"] = f["wall_s"] / b["wall_s"]
    path = REPO / "benchmarks" / "results" / "agreement_200.json"
    path.write_text(json.dumps(row, indent=1, default=float))
    print(json.dumps(row, indent=1, default=float))


if __name__ == "__main__":
    main()
