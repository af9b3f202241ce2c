"""Built-in solver against OpenFOAM, side by side on the same layouts.

Every solve runs in a fresh Python process (``--worker``), so the wall times
count process start-up and imports, for both engines.  Layouts: the three
OpenFOAM reference layouts (accuracy against the reference files) and
random training-distribution layouts (accuracy of the built-in solver
against OpenFOAM's solution of the same layout); then a size sweep from
50 x 50 to 200 x 200 cells; then the time it takes to report a flow that
does not converge.

    python benchmarks/solver_speed.py                  # full run, ~10 min
    python benchmarks/solver_speed.py --random 1 --sizes 50 100   # quick look

Writes ``benchmarks/results/solver_speed.json`` and ``solver_speed.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
REFERENCE = Path(os.environ.get("DGSE_REFERENCE_CASES", REPO.parent / "shared" / "reference-cases"))


# ------------------------------------------------------------------------------ worker
def worker(args: argparse.Namespace) -> None:
    """Solve one layout with four sources and save the fields (runs in its own process)."""
    from dgse.errors import ConvergenceError
    from dgse.physics.builtin import BuiltinEngine
    from dgse.physics.engines import Source, get_engine
    from dgse.physics.rans import FlowSettings

    layout, v_in, sources = _scenario(args.scenario)
    if args.engine == "builtin":
        settings = FlowSettings(tolerance=args.tolerance) if args.tolerance else None
        engine = BuiltinEngine(settings=settings)
    else:
        engine = get_engine(args.engine)
    t = time.perf_counter()
    try:
        sol = engine.solve(layout, v_in, [Source(p, q) for p, q in sources])
    except ConvergenceError as e:
        json.dump(
            {
                "converged": False,
                "error": str(e),
                "seconds": time.perf_counter() - t,
                "iterations": e.info.get("iterations"),
            },
            open(args.out + ".json", "w"),
        )
        return
    np.savez(args.out, wind=sol.flow.wind, conc=np.stack(sol.concentrations))
    info = {
        "converged": True,
        "seconds": time.perf_counter() - t,
        "outlet_flux_ratio": sol.outlet_flux_ratio,
        "iterations": sol.info.get("flow_iterations", sol.flow.info.get("iterations")),
    }
    json.dump(info, open(args.out + ".json", "w"))


def _scenario(spec: str):
    """``ref:<layout>`` (a reference layout, its sources) or ``rand:<seed>[:<side_m>]``."""
    from dgse.world.case import Case
    from dgse.world.generate import as_generator, random_inlet_velocity, random_layout, random_sources

    kind, _, rest = spec.partition(":")
    if kind == "ref":
        cases = [Case.load(p) for p in sorted(REFERENCE.glob(f"{rest}_src*.npz"))]
        sources = [((float(c.source[0]), float(c.source[1])), c.release_rate) for c in cases]
        return cases[0].layout, cases[0].inlet_velocity, sources
    seed, _, side = rest.partition(":")
    rng = as_generator(int(seed))
    kw = {}
    if side:
        kw = {"width_range": (float(side), float(side)), "height_range": (float(side), float(side))}
    layout = random_layout(rng, **kw)
    v = random_inlet_velocity(rng)
    return layout, v, random_sources(layout, rng, n=4)


# ------------------------------------------------------------------------------ driver
def run(engine: str, scenario: str, tmp: Path, tolerance: float | None = None) -> dict:
    out = str(tmp / f"{engine}_{scenario.replace(':', '_')}")
    cmd = [sys.executable, __file__, "--worker", "--engine", engine, "--scenario", scenario, "--out", out]
    if tolerance:
        cmd += ["--tolerance", str(tolerance)]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=REPO)
    wall = time.perf_counter() - t
    info = json.load(open(out + ".json"))
    info["wall_s"] = wall  # process start-up, imports, solve and writing
    if info["converged"]:
        with np.load(out + ".npz") as d:
            info["_wind"], info["_conc"] = d["wind"], d["conc"]
    return info


def errors(wind, conc, ref_wind, ref_conc, free) -> dict:
    vel = float(np.linalg.norm((wind - ref_wind)[:, free]) / np.linalg.norm(ref_wind[:, free]))
    diffs = [(np.log1p(a) - np.log1p(b))[free] for a, b in zip(conc, ref_conc, strict=True)]
    rmse = [float(np.sqrt(np.mean(d**2))) for d in diffs]
    return {"velocity_rel_l2": vel, "log_conc_rmse": rmse}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--engine", default="builtin")
    ap.add_argument("--scenario", default="")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results"))
    ap.add_argument("--tolerance", type=float, default=None)
    ap.add_argument("--random", type=int, default=3, help="random training layouts (both engines)")
    ap.add_argument("--sizes", type=float, nargs="*", default=[5, 7.5, 10, 15, 20], help="square sides, m")
    ap.add_argument("--no-openfoam", action="store_true")
    args = ap.parse_args()
    if args.worker:
        worker(args)
        return

    from dgse.physics.engines import engine_names
    from dgse.world.case import Case

    use_foam = "openfoam" in engine_names() and not args.no_openfoam
    results: dict = {
        "machine": {
            "cpu_count": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
        },
        "openfoam": use_foam,
        "layouts": [],
        "sizes": [],
        "non_converging": None,
    }
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        run("builtin", "rand:0:5", tmp)  # warm the numba cache: not timed
        scenarios = [f"ref:s1_l00{i}" for i in range(3)] + [f"rand:{1000 + i}" for i in range(args.random)]
        for sc in scenarios:
            row: dict = {"scenario": sc}
            b = run("builtin", sc, tmp)
            row["builtin"] = {k: v for k, v in b.items() if not k.startswith("_")}
            if sc.startswith("ref:"):
                refs = [Case.load(p) for p in sorted(REFERENCE.glob(f"{sc[4:]}_src*.npz"))]
                free = refs[0].free
                ref_wind = refs[0].wind
                ref_conc = np.stack([c.concentration for c in refs])
                row["builtin_vs_reference"] = errors(b["_wind"], b["_conc"], ref_wind, ref_conc, free)
                row["reference_openfoam_s"] = refs[0].meta["wall_clock_s"]["layout_total"]
            if use_foam:
                f = run("openfoam", sc, tmp)
                row["openfoam"] = {k: v for k, v in f.items() if not k.startswith("_")}
                row["speedup"] = f["wall_s"] / b["wall_s"]
                if f["converged"] and b["converged"]:
                    free = _scenario(sc)[0].free
                    row["builtin_vs_openfoam"] = errors(b["_wind"], b["_conc"], f["_wind"], f["_conc"], free)
                    if sc.startswith("ref:"):
                        fw, fc = f["_wind"], f["_conc"]
                        row["openfoam_vs_reference"] = errors(fw, fc, ref_wind, ref_conc, free)
            results["layouts"].append(row)
            print(json.dumps(row, default=float)[:400], flush=True)
        for side in args.sizes:
            for seed in (7, 8):
                b = run("builtin", f"rand:{seed}:{side:g}", tmp)
                row = {
                    "side_m": side,
                    "seed": seed,
                    "cells": round(side / 0.1) ** 2,
                    "builtin": {k: v for k, v in b.items() if not k.startswith("_")},
                }
                results["sizes"].append(row)
                print(json.dumps(row, default=float), flush=True)
        nc = run("builtin", "rand:25", tmp)  # an oscillating flow (see solver_robustness)
        results["non_converging"] = {k: v for k, v in nc.items() if not k.startswith("_")}
        print(json.dumps(results["non_converging"], default=float), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "solver_speed.json").write_text(json.dumps(results, indent=1, default=float))
    (out / "solver_speed.md").write_text(markdown(results))
    print(markdown(results))


def markdown(r: dict) -> str:
    lines = [
        "Wall seconds per layout with four sources, each in a fresh process (start-up included); "
        "accuracy of the built-in solution against OpenFOAM's on the same layout.",
        "",
        "| layout | built-in s | OpenFOAM s | speed-up | built-in iterations | velocity rel. L2 | "
        "log(1+ppm) RMSE (max over sources) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in r["layouts"]:
        b = row["builtin"]
        f = row.get("openfoam", {})
        acc = row.get("builtin_vs_openfoam") or row.get("builtin_vs_reference") or {}
        lines.append(
            f"| {row['scenario']} | {b['wall_s']:.2f} | {f.get('wall_s', float('nan')):.2f} | "
            f"{row.get('speedup', float('nan')):.1f} | {b.get('iterations')} | "
            f"{acc.get('velocity_rel_l2', float('nan')):.3f} | "
            f"{max(acc.get('log_conc_rmse', [float('nan')])):.3f} |"
        )
    sp = [row["speedup"] for row in r["layouts"] if "speedup" in row]
    if sp:
        lines.append(f"\nMedian speed-up {statistics.median(sp):.1f}x (min {min(sp):.1f}x).")
    lines += [
        "",
        "Growth with the map size (square random layouts, built-in solver, two seeds each):",
        "",
        "| cells | seed | wall s (incl. start-up) | solve s | iterations | ms per iteration | converged |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in r["sizes"]:
        b = row["builtin"]
        its = b.get("iterations") or 0
        per_it = 1e3 * b["seconds"] / its if its else float("nan")
        lines.append(
            f"| {row['cells']} | {row['seed']} | {b['wall_s']:.2f} | {b['seconds']:.2f} | {its} | "
            f"{per_it:.1f} | {b['converged']} |"
        )
    nc = r.get("non_converging")
    if nc:
        lines.append(
            f"\nNon-converging flow (random layout, seed 25, an oscillating flow): reported after "
            f"{nc['wall_s']:.1f} s, {nc.get('iterations')} iterations: {nc.get('error', '')}"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
