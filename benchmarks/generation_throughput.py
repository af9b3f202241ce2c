"""Dataset generation throughput: paper-size layouts x 4 sources with 1 and 2 Dask workers.

Every run generates the same ``--layouts`` layouts (same seed) into a fresh
store with :func:`dgse.data.generation.generate` on a local cluster, and
reports:

* ``layouts_per_minute``: layouts stored per minute of wall time, cluster
  start-up, numba loading and commits included (what a user sees);
* ``steady_layouts_per_minute``: the rate between the first and the last
  result (start-up excluded; what 3,750 layouts approach);
* the mean task time per layout, failures, bytes per layout in the store;
* the projected wall time for the paper's 3,750 layouts at the steady rate.

    python benchmarks/generation_throughput.py                 # 12 layouts, 1 and 2 workers
    python benchmarks/generation_throughput.py --layouts 4 --workers 2   # quick look

Writes ``benchmarks/results/generation_throughput.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PAPER_LAYOUTS = 3750


def run(n_layouts: int, workers: int, seed: int, directory: Path) -> dict:
    from dgse.data.generation import generate
    from dgse.data.store import DatasetStore

    out = directory / f"bench-{workers}w.h5"
    t0 = time.perf_counter()
    report = generate(n_layouts, out, workers=workers, seed=seed, progress=True)
    wall = time.perf_counter() - t0
    with DatasetStore(out) as s:
        cells = [s.layout_info(lid)["summary"]["shape"] for lid in s.layouts()]
    size = out.stat().st_size
    n_done = report.n_new + report.n_failed_new
    # the steady rate: from the first result to the end of the run
    first = report.first_result_s
    steady = (
        60.0 * (n_done - 1) / (report.seconds - first)
        if n_done > 1 and first is not None and report.seconds > first
        else float("nan")
    )
    return {
        "workers": workers,
        "layouts": n_layouts,
        "stored": report.n_layouts,
        "failed": report.n_failures,
        "wall_s": round(wall, 2),
        "first_result_s": None if first is None else round(first, 2),
        "layouts_per_minute": round(60.0 * n_done / wall, 2),
        "steady_layouts_per_minute": round(steady, 2),
        "mean_task_s_per_layout": round(report.solve_seconds / max(n_done, 1), 2),
        "mean_task_cpu_s_per_layout": round(report.cpu_seconds / max(n_done, 1), 2),
        "mean_cells": round(sum(h * w for h, w in cells) / max(len(cells), 1)),
        "store_bytes_per_layout": round(size / max(report.n_layouts, 1)),
        "projected_hours_for_3750": round(PAPER_LAYOUTS / steady / 60.0, 2)
        if steady == steady and steady > 0
        else None,
    }


def main() -> None:
    from dgse.files import write_text

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--layouts", type=int, default=12)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--out", type=Path, default=REPO / "benchmarks" / "results" / "generation_throughput.json"
    )
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as d:
        for w in args.workers:
            r = run(args.layouts, w, args.seed, Path(d))
            print(json.dumps(r))
            results.append(r)
    import numpy
    import scipy

    doc = {
        "benchmark": "dataset generation throughput (paper-size layouts, 4 sources each)",
        "command": "python benchmarks/generation_throughput.py "
        f"--layouts {args.layouts} --workers {' '.join(map(str, args.workers))} --seed {args.seed}",
        "machine": {
            "cpus": len(os.sched_getaffinity(0)),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "numpy": numpy.__version__,
            "scipy": scipy.__version__,
        },
        "date": time.strftime("%Y-%m-%d"),
        "results": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
