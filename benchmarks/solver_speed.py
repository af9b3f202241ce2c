"""Built-in solver against OpenFOAM, side by side on the same layouts; the built-in one at building scale.

Every solve runs in a fresh Python process (``--worker``), so the wall times
count process start-up and imports, for both engines; the layouts are drawn
beforehand and read from a file, as a user's own layout would be.  Layouts: the three
OpenFOAM reference layouts (accuracy against the reference files) and
random training-distribution layouts (accuracy of the built-in solver
against OpenFOAM's solution of the same layout); then a size sweep of
square random layouts from 100 x 100 to 400 x 400 cells and multi-room
floors (``random_layout_with_rooms``); then warm starts (the same map at
another inlet speed); then the time it takes to report a flow that does not
converge.

    python benchmarks/solver_speed.py --floors --repeat 4   # full run, ~20 min on 2 cores
    python benchmarks/solver_speed.py --random 1 --sizes 10 20 --floors   # quick look

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
#: the workers' environment: Python's bytecode cache on, as on a user's machine (where the
#: first run writes ``.pyc`` files).  A sandbox that sets ``PYTHONDONTWRITEBYTECODE`` would
#: otherwise make every worker of either engine compile dgse's modules from source (the dgse
#: modules' own import time in ``python -X importtime -c "import dgse.physics.builtin"``: 34-37
#: ms without ``.pyc`` files, 16-19 ms with them, 5 runs each); the untimed warm-up writes them.
WORKER_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


# ------------------------------------------------------------------------------ worker
def worker(args: argparse.Namespace) -> None:
    """Solve one layout with its first ``--sources`` sources and save the fields (runs in its own
    process, with the garbage-collector settings of the ``dgse`` console script, for either engine)."""
    from dgse.cli import process

    process.start()
    try:
        _solve_and_save(args)
    finally:
        process.finish()


def _solve_and_save(args: argparse.Namespace) -> None:
    from dgse.errors import ConvergenceError
    from dgse.physics.engines import Source

    layout, v_in, sources = _load_scenario(args.scenario)
    sources = sources[: args.sources]
    if args.warm:
        json.dump(warm_start(layout, v_in, args.warm), open(args.out + ".json", "w"))
        return
    # each engine's process imports only that engine (the other's imports are not its start-up)
    if args.engine == "builtin":
        from dgse.physics.builtin import BuiltinEngine
        from dgse.physics.rans import FlowSettings

        settings = FlowSettings(tolerance=args.tolerance) if args.tolerance else None
        engine = BuiltinEngine(settings=settings)
    else:
        from dgse.physics.engines import get_engine

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
                "cells": int(layout.free.sum()),
                **_flow_facts(e.info),
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
        "cells": int(layout.free.sum()),
        "flow_s": sol.info.get("wall_clock_s", {}).get("flow"),
        **_flow_facts(sol.flow.info),
    }
    json.dump(info, open(args.out + ".json", "w"))


def _flow_facts(info: dict) -> dict:
    """The built-in flow solve's start, coarse solves and pressure work (empty for OpenFOAM)."""
    if "attempts" not in info:
        return {}
    coarse, c = [], info.get("coarse")
    while c:
        coarse.append({"iterations": c["iterations"], "seconds": c["seconds"]})
        c = c.get("coarse")
    return {
        "start": info.get("start"),
        "coarse": coarse,
        "attempts": [
            {k: a[k] for k in ("iterations", "converged", "stalled", "seconds")} for a in info["attempts"]
        ],
        "pressure_factorizations": info.get("pressure_factorizations"),
        "pressure_cg_iterations": info.get("pressure_cg_iterations"),
        "gauss_seidel_sweeps": info.get("gauss_seidel_sweeps"),
    }


def warm_start(layout, v_in: float, factors: list[float]) -> dict:
    """Flow alone at ``v_in``, then at ``f * v_in`` for each factor, cold and warm from ``v_in``'s."""
    from dgse.physics.builtin import flow_and_transport

    t = time.perf_counter()
    base, _ = flow_and_transport(layout, v_in)
    out = {
        "v": v_in,
        "cells": int(layout.free.sum()),
        "base": _run_facts(base, time.perf_counter() - t),
        "runs": [],
    }
    for f in factors:
        row: dict = {"v": f * v_in}
        for mode in ("cold", "warm"):
            t = time.perf_counter()
            flow, _ = flow_and_transport(layout, f * v_in, warm_start=base if mode == "warm" else None)
            row[mode] = _run_facts(flow, time.perf_counter() - t)
            row[mode + "_wind"] = flow.wind
        d = row.pop("warm_wind") - row.pop("cold_wind")
        row["wind_rel_diff"] = float(np.linalg.norm(d) / np.linalg.norm(base.wind * f))
        out["runs"].append(row)
    return out


def _run_facts(flow, seconds: float) -> dict:
    i = flow.info
    return {
        "seconds": seconds,
        "iterations": i["iterations"],
        "converged": i["converged"],
        "start": i["start"],
    }


def _scenario(spec: str):
    """``ref:<layout>`` (a reference layout, its sources), ``rand:<seed>[:<side_m>]`` or
    ``rooms:<seed>:<side_m>:<rooms>`` (a square floor of that many rooms)."""
    from dgse.world.case import Case
    from dgse.world.generate import (
        as_generator,
        random_inlet_velocity,
        random_layout,
        random_layout_with_rooms,
        random_sources,
    )

    kind, _, rest = spec.partition(":")
    if kind == "ref":
        cases = [Case.load(p) for p in sorted(REFERENCE.glob(f"{rest}_src*.npz"))]
        sources = [((float(c.source[0]), float(c.source[1])), c.release_rate) for c in cases]
        return cases[0].layout, cases[0].inlet_velocity, sources
    if kind == "rooms":
        seed, side, rooms = rest.split(":")
        rng = as_generator(int(seed))
        r = (float(side), float(side))
        layout, _ = random_layout_with_rooms(
            rng, width_range=r, height_range=r, n_rooms=int(rooms), min_room_m=3.0
        )
        return layout, random_inlet_velocity(rng), random_sources(layout, rng, n=4)
    seed, _, side = rest.partition(":")
    rng = as_generator(int(seed))
    kw = {}
    if side:
        kw = {"width_range": (float(side), float(side)), "height_range": (float(side), float(side))}
    layout = random_layout(rng, **kw)
    v = random_inlet_velocity(rng)
    return layout, v, random_sources(layout, rng, n=4)


def _load_scenario(path: str):
    """What :func:`prepare` wrote: the layout, the inlet speed and the four sources."""
    from dgse.world.layout_io import load_layout

    meta = json.loads(Path(path).with_suffix(".json").read_text())
    return load_layout(path), meta["inlet_velocity"], [(tuple(p), q) for p, q in meta["sources"]]


# ------------------------------------------------------------------------------ driver
def prepare(scenario: str, tmp: Path) -> Path:
    """Draw the scenario once and write it where the workers read it: drawing a layout
    (which imports the generators and scipy.ndimage) is no part of either engine's start-up."""
    from dgse.world.layout_io import save_layout

    path = tmp / f"scenario_{scenario.replace(':', '_')}.npz"
    if not path.exists():
        layout, v, sources = _scenario(scenario)
        save_layout(layout, path)
        src = [[[float(x) for x in p], float(q)] for p, q in sources]
        path.with_suffix(".json").write_text(json.dumps({"inlet_velocity": float(v), "sources": src}))
    return path


def run(
    engine: str,
    scenario: str,
    tmp: Path,
    tolerance: float | None = None,
    warm: list[float] | None = None,
    sources: int = 4,
) -> dict:
    out = str(tmp / f"{engine}_{scenario.replace(':', '_')}{'_warm' if warm else ''}")
    file = str(prepare(scenario, tmp))
    cmd = [sys.executable, __file__, "--worker", "--engine", engine, "--scenario", file, "--out", out]
    cmd += ["--sources", str(sources)]
    if tolerance:
        cmd += ["--tolerance", str(tolerance)]
    if warm:
        cmd += ["--warm", *map(str, warm)]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=REPO, env=WORKER_ENV)
    wall = time.perf_counter() - t
    info = json.load(open(out + ".json"))
    info["wall_s"] = wall  # process start-up, imports, solve and writing
    if info.get("converged"):
        with np.load(out + ".npz") as d:
            info["_wind"], info["_conc"] = d["wind"], d["conc"]
    return info


def errors(wind, conc, ref_wind, ref_conc, free) -> dict:
    vel = float(np.linalg.norm((wind - ref_wind)[:, free]) / np.linalg.norm(ref_wind[:, free]))
    diffs = [(np.log1p(a) - np.log1p(b))[free] for a, b in zip(conc, ref_conc, strict=True)]
    rmse = [float(np.sqrt(np.mean(d**2))) for d in diffs]
    return {"velocity_rel_l2": vel, "log_conc_rmse": rmse}


def main() -> None:
    from dgse.files import write_text

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--engine", default="builtin")
    ap.add_argument("--scenario", default="")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results"))
    ap.add_argument("--tolerance", type=float, default=None)
    ap.add_argument("--random", type=int, default=3, help="random training layouts (both engines)")
    ap.add_argument("--sizes", type=float, nargs="*", default=[10, 20, 30, 40], help="square sides, m")
    ap.add_argument("--floors", action="store_true", help="multi-room floors 20 x 20 and 30 x 30 m too")
    ap.add_argument("--warm", type=float, nargs="*", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--shared", default="", help="a note on other work running on the machine meanwhile")
    ap.add_argument("--no-openfoam", action="store_true")
    ap.add_argument("--repeat", type=int, default=1, help="side-by-side passes (timing only after the first)")
    ap.add_argument(
        "--sources", type=int, default=4, choices=range(1, 5), help="gas sources per paper-size layout (1-4)"
    )
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
            # the interpreter both engines' workers run in: a virtual environment made by the
            # README's install holds only the project's dependencies (a system Python with more
            # packages can start slower: numba imports cffi, NumPy's f2py charset_normalizer,
            # where they are installed)
            "executable": sys.executable,
            "virtual_env": sys.prefix != sys.base_prefix,
            # whether this run's environment disables Python's bytecode cache; the workers
            # run with it on either way (WORKER_ENV)
            "dont_write_bytecode_in_env": "PYTHONDONTWRITEBYTECODE" in os.environ,
        },
        "openfoam": use_foam,
        "sources": args.sources,
        "shared": args.shared,
        "layouts": [],
        "repeats": [],
        "sizes": [],
        "floors": [],
        "warm_start": None,
        "non_converging": None,
    }
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        # warm the numba cache, both engines' bytecode caches and OpenFOAM's files: not timed
        run("builtin", "rand:0:5", tmp)
        if use_foam:
            run("openfoam", "rand:0:5", tmp)
        scenarios = [f"ref:s1_l00{i}" for i in range(3)] + [f"rand:{1000 + i}" for i in range(args.random)]
        for sc in scenarios:
            row: dict = {"scenario": sc}
            b = run("builtin", sc, tmp, sources=args.sources)
            row["builtin"] = {k: v for k, v in b.items() if not k.startswith("_")}
            if sc.startswith("ref:"):
                refs = [Case.load(p) for p in sorted(REFERENCE.glob(f"{sc[4:]}_src*.npz"))][: args.sources]
                free = refs[0].free
                ref_wind = refs[0].wind
                ref_conc = np.stack([c.concentration for c in refs])
                row["builtin_vs_reference"] = errors(b["_wind"], b["_conc"], ref_wind, ref_conc, free)
                row["reference_openfoam_s"] = refs[0].meta["wall_clock_s"]["layout_total"]
            if use_foam:
                f = run("openfoam", sc, tmp, sources=args.sources)
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
        # more passes, timing only: on a 2-core machine one pass's times vary by tens of percent
        for rep in range(1, args.repeat if use_foam else 1):
            for sc in scenarios:
                b = run("builtin", sc, tmp, sources=args.sources)
                f = run("openfoam", sc, tmp, sources=args.sources)
                rrow = {"pass": rep + 1, "scenario": sc, "builtin_s": b["wall_s"], "openfoam_s": f["wall_s"]}
                rrow["speedup"] = f["wall_s"] / b["wall_s"]
                results["repeats"].append(rrow)
                print(json.dumps(rrow), flush=True)
        for side in args.sizes:
            for seed in (7, 8) if side < 40 else (7,):  # 400 x 400: one seed (minutes each)
                b = run("builtin", f"rand:{seed}:{side:g}", tmp)
                row = {
                    "side_m": side,
                    "seed": seed,
                    "grid": round(side / 0.1) ** 2,
                    "builtin": {k: v for k, v in b.items() if not k.startswith("_")},
                }
                results["sizes"].append(row)
                print(json.dumps(row, default=float), flush=True)
        for side, rooms in ((20, 6), (30, 9)) if args.floors else ():
            sc = f"rooms:11:{side}:{rooms}"
            b = run("builtin", sc, tmp)
            row = {
                "scenario": sc,
                "grid": round(side / 0.1) ** 2,
                "builtin": {k: v for k, v in b.items() if not k.startswith("_")},
            }
            results["floors"].append(row)
            print(json.dumps(row, default=float), flush=True)
        if args.sizes:
            side = max(s for s in args.sizes if s <= 20)
            results["warm_start"] = run("builtin", f"rand:7:{side:g}", tmp, warm=[0.5, 1.25])
            print(json.dumps(results["warm_start"], default=float), flush=True)
        nc = run("builtin", "rand:25", tmp)  # an oscillating flow (see solver_robustness)
        results["non_converging"] = {k: v for k, v in nc.items() if not k.startswith("_")}
        print(json.dumps(results["non_converging"], default=float), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "solver_speed.json", json.dumps(results, indent=1, default=float))
    write_text(out / "solver_speed.md", markdown(results))
    print(markdown(results))


def _repeats_markdown(r: dict) -> list[str]:
    """The speed-up of every pass per layout, each pass's median, and the ratio of the median times."""
    reps = r.get("repeats") or []
    if not reps:
        return []
    passes: dict[int, dict[str, dict]] = {1: {}}
    for row in r["layouts"]:
        if "speedup" in row:
            passes[1][row["scenario"]] = {
                "builtin_s": row["builtin"]["wall_s"],
                "openfoam_s": row["openfoam"]["wall_s"],
                "speedup": row["speedup"],
            }
    for row in reps:
        passes.setdefault(row["pass"], {})[row["scenario"]] = row
    names = list(passes[1])
    lines = [
        "",
        f"The same side by side in {len(passes)} passes (timing only after the first; speed-up per pass, "
        "then OpenFOAM's median time over the built-in solver's):",
        "",
        "| layout | " + " | ".join(f"pass {k}" for k in passes) + " | median times |",
        "|---|" + "---|" * (len(passes) + 1),
    ]
    ratios = []
    for name in names:
        b = statistics.median(p[name]["builtin_s"] for p in passes.values())
        f = statistics.median(p[name]["openfoam_s"] for p in passes.values())
        ratios.append(f / b)
        cells = " | ".join(f"{p[name]['speedup']:.1f}" for p in passes.values())
        lines.append(f"| {name} | {cells} | {f / b:.1f} ({f:.2f} / {b:.2f} s) |")
    meds = [statistics.median(p[n]["speedup"] for n in names) for p in passes.values()]
    lines.append(
        "| median | " + " | ".join(f"{m:.1f}" for m in meds) + f" | {statistics.median(ratios):.1f} |"
    )
    return lines


def markdown(r: dict) -> str:
    n_src = r.get("sources", 4)
    lines = [
        f"Wall seconds per layout with {n_src} gas source{'s' if n_src > 1 else ''}, "
        "each in a fresh process (start-up included); "
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
    lines += _repeats_markdown(r)
    lines += [
        "",
        "Growth with the map size (square random layouts by seed; multi-room floors "
        "`rooms:seed:side_m:rooms`; the built-in flow alone is the `flow s` column; "
        "`fine it` are the SIMPLEC iterations on the map's own grid, `coarse it` those of the coarse "
        "start on grids 2x, 4x, ... coarser, when used):",
        "",
        "| grid | free cells | seed | wall s (incl. start-up, gas) | flow s | fine it | coarse it | "
        "ms per fine iteration | pressure CG its | converged |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in r["sizes"] + r.get("floors", []):
        lines.append(_size_row(row))
    w = r.get("warm_start")
    if w:
        b0 = w["base"]
        lines += [
            "",
            f"Warm start: one {w['cells']} free-cell map (random layout, seed 7) solved at "
            f"{w['v']:.2f} m/s ({b0['iterations']} iterations, {b0['seconds']:.1f} s), then at other "
            "inlet speeds from rest (cold) and from that solution scaled (warm, "
            "`flow_and_transport(..., warm_start=flow)`):",
            "",
            "| inlet m/s | cold it | cold s | warm it | warm s | saved | wind rel. diff warm vs cold |",
            "|---|---|---|---|---|---|---|",
        ]
        for x in w["runs"]:
            c, h = x["cold"], x["warm"]
            lines.append(
                f"| {x['v']:.2f} | {c['iterations']} | {c['seconds']:.1f} | {h['iterations']} | "
                f"{h['seconds']:.1f} | {1 - h['seconds'] / c['seconds']:.0%} | {x['wind_rel_diff']:.1e} |"
            )
    nc = r.get("non_converging")
    if nc:
        lines.append(
            f"\nNon-converging flow (random layout, seed 25, an oscillating flow): reported after "
            f"{nc['wall_s']:.1f} s, {nc.get('iterations')} iterations: {nc.get('error', '')}"
        )
    m = r["machine"]
    if r.get("shared"):
        lines.append(f"\nMachine: {m['cpu_count']} cores, shared: {r['shared']}.")
    if "virtual_env" in m:
        where = "a virtual environment" if m["virtual_env"] else "a system interpreter"
        lines.append(f"Python {m['python']} in {where} (`{m['executable']}`).")
    if m.get("dont_write_bytecode_in_env"):
        lines.append(
            "This environment sets PYTHONDONTWRITEBYTECODE; the workers of both engines ran without "
            "it, with the bytecode cache a user's Python keeps (written by the untimed warm-up run)."
        )
    lines.append("\n" + DIAGNOSIS)
    return "\n".join(lines) + "\n"


def _size_row(row: dict) -> str:
    b = row["builtin"]
    its = b.get("iterations") or 0
    flow_s = b.get("flow_s") or b["seconds"]
    fine_s = sum(a["seconds"] for a in b.get("attempts", [])) or flow_s
    per_it = 1e3 * fine_s / its if its else float("nan")
    coarse = "+".join(str(c["iterations"]) for c in b.get("coarse", [])) or "-"
    name = row.get("scenario") or row["seed"]
    side = round(row["grid"] ** 0.5)
    return (
        f"| {side}x{side} | {b.get('cells', '')} | {name} | {b['wall_s']:.1f} | {flow_s:.1f} | {its} | "
        f"{coarse} | {per_it:.0f} | {b.get('pressure_cg_iterations', '')} | {b['converged']} |"
    )


#: what was measured to choose the solver strategy (issue 14); the commands are in the commit messages
DIAGNOSIS = """\
## Why large maps did not converge, and what was measured (issue 14)

Measured on the same 2-core machine, shared with another engineer's benchmarks
(timings within one comparison were taken back to back; CPU seconds where the
load varied).  Random layout seed 7, 15 x 15 m = 150 x 150 cells (22,096 free),
inlet 4.07 m/s, unless stated.

* **Not the pressure solve, not an oscillation, not divergence.**  From rest the
  residuals fall steadily but slowly (worst 5.9e-3 at 100 iterations, 9.7e-4 at
  300, 3.6e-4 at 600, 1.6e-4 at 800) and reach the tolerance at 926 iterations if
  let run.  The stall test (worst residual not halved in 200 iterations) stopped
  it at 476 and the retry at relaxation 0.7 was slower still: "not converged after
  877".  The unconverged residual sits in the largest room's recirculating eddy
  (and a dead-end room whose k decays); the big eddy moves by a small pseudo-time
  step per SIMPLEC iteration.
* **Inner tolerances do not matter** (worst residual after 400 iterations, base
  6.5e-4): transport rel_tol 0.1 -> 0.01: 6.7e-4; pressure rel_tol 0.1 -> 0.01:
  6.5e-4; upwind instead of linear-upwind: 4.7e-4.
* **Relaxation does**: alpha_u 0.8: 1.4e-3; alpha_turb 0.9: 6.0e-4, 0.95: 3.0e-4;
  (alpha_u, alpha_turb) = (0.97, 0.95): converged in 373 iterations, (0.97, 0.99):
  221.  But alpha_u enters the Rhie-Chow face fluxes (rAtU), so it changes the
  converged flow (0.8 % in velocity on a small map at tolerance 1e-5):
  the momentum relaxation stays 0.9.  The k-epsilon fixed point does not depend on
  its relaxation, so maps over 12k free cells ramp alpha_turb from 0.8 to 0.99 by
  switched evolution relaxation (pseudo-time step ~ r0 / r, r the worst residual,
  r0 that of the first iterations: a warm or coarse start begins at 0.8): 382
  iterations at 150 x 150 (926 before), 250 at 100 x 100 (567).  Not below 12k
  cells: on 10 training layouts it saved 11 % of the iterations but one did not
  converge and two converged to flows 3-7 % apart (sensitive flows).
* **Stall test**: now "not halved in 200 iterations AND at the rate of those 200
  it would not reach the tolerance within max_iterations"; an oscillating flow
  (seed 25) is still reported after the same 802 iterations.
* **Pressure (200 x 200, 39,446 cells, 150 iterations, CPU)**: stale SuperLU +
  CG: 31 ms per iteration (11 factorizations of 138 ms, 4.7 CG iterations of
  4.7 ms per solve); Ruge-Stuben AMG (PyAMG) rebuilt when CG needs > 8 its:
  38 ms (a stale hierarchy needs 15-20 CG its 40 iterations later);
  smoothed aggregation set-up 65 ms, Ruge-Stuben 45 ms; **AMG whose coarse
  operators R A P are recomputed each solve on a fixed coarsening: 21 ms** (one
  set-up, 1.4 CG its per solve).  Used above 12k cells; LU below (faster there).
* **Coarse-grid start** (solve on a 2x coarser grid, any-solid coarsening,
  bilinear prolongation): 200 x 200: 251 fine iterations instead of 697; 300 x 300:
  necessary (without it: not converged in 1500 iterations); 150 x 150: 468
  instead of 382 and 100 x 100: 385 instead of 250 (worse): used above 30k free
  cells.  Piecewise-constant injection made k-epsilon blow up at 300 x 300.
* **Transport sweeps**: capping Gauss-Seidel at 20 sweeps under SER left the k
  residual on a floor at 1.1e-4 at 300 x 300 (stalled); with the usual 50 it
  converged.  At alpha_turb 0.99 the k solve takes most of the 50 sweeps: the
  largest remaining cost per iteration.
* **Later (same issue, idle machine): sweeps capped at 10 and lifted on a stall.**
  On maps over 12k free cells Gauss-Seidel multiplies by the inverse diagonal
  instead of dividing (the division sat on the sweep's dependency chain): 1.45-1.53
  ms against 2.09-2.12 ms per symmetric sweep on 89k cells. Not on smaller grids
  (paper-size maps, coarse starts): the last bits change, and the recorded dgse-phys
  searches took other paths (test 2000: 29 readings instead of 9). Capping the k and
  epsilon solves under SER, random 300 x 300 seed 7 (flow alone): cap 50: 358 fine
  iterations, 96 s; 20: 504, 96 s; 10: 439, 73 s; 5: 747, 108 s (before the kernel
  change). With the cap 10 alone, random 200 x 200 seed 8 stalled with k at 1.3e-4
  and needed the relaxation retry (78 s against 38 s uncapped), and `rooms:11:20:6`
  converged in 25 s where the uncapped run stalled and retried (63 s). So the cap is
  lifted when the capped iteration stalls, and the iteration goes on from where it
  is (stall test on half the window after that): 200 x 200 seed 8: 51 s; rooms: 21
  s; 300 x 300 seed 7: 70 s, seed 8: 106 s (flow alone, idle). The slow test's
  multi-room map stalls capped and uncapped and converges on the retry: 1322
  iterations, 73 s (1121, 81 s before). Converged flows of the same map with
  different caps differ by 0.8-1.4 % in velocity and 1-6 % in nu_t (300 x 300): the
  residual criteria do not pin large flows down more tightly than that.
* **Multi-room 20 x 20 m** (`random_layout_with_rooms(3)`, 39,620 free cells, the
  slow test): the SER attempt oscillates (k residual 1.7e-3 -> 1.8e-2 -> 1.4e-3)
  and stalls at 401 iterations; the retry (relaxation 0.7, no SER, same coarse
  start) converges: 1121 fine iterations in all.  A stronger SER back-off (step
  cut by (r_min / r)^2) did not stop the oscillation.
* **Cost per iteration (2026-11-26, idle machine; the machine's own noise is +-10-15 %).**
  Profile of 300 x 300 seed 7 before: Gauss-Seidel 32 %, the AMG's coarse operators
  `R A P` (two sparse matrix products per level, every solve) 13 %, k-epsilon's NumPy
  work 8 %, gradients 5 %.  (1) `R A P` is linear in `A`'s values and `A`'s pattern is
  the mesh's stencil: a sparse matrix from the fine values to the coarse ones, built
  once per hierarchy, gives every level (`GalerkinMap`; the same operators to 1e-12
  relative, tested).  (2) Gauss-Seidel adds the neighbour just updated (west going
  forward, east going back) last and multiplies by the reciprocal diagonal: the
  dependency chain from one cell to the next loses three additions; paper-size maps use
  it too.  (3) The k-epsilon production and wall values in one kernel.  Kernels alone
  (`python benchmarks/solver_kernels.py`, `benchmarks/results/solver_kernels.json`,
  best of 5): a symmetric sweep on 89k cells 1.05 ms against 2.05 ms with the division
  (one right-hand side), 1.42 against 2.10 ms (two); the coarse operators at 200 x 200
  (5 levels) 1.8 ms against 8.0 ms by products (map built in 0.30 s); paper-size flows
  0.81 / 0.71 s against 0.90 / 0.76 s (random 1001 / 1002; winds 7e-8 and 4e-11
  apart).  Timed with throwaway scripts (not kept): whole solves, old and new code
  alternated, 200 x 200 seed 7: 24.2-26.0 s against 28.9 s (same iterations); 300 x
  300 seed 7: 71 s (540 fine iterations) against 79 s (510); slower kernel variants: a
  padded branch-free neighbour loop and two half-domain sweeps interleaved; not kept
  either: AMG on paper-size maps (1.16-1.46 s against 0.82-1.18 s with the stale LU), a
  forward/backward AMG smoother (within the noise), a turbulence sweep cap of 20
  instead of 10 (200 x 200 seed 7: 248 fine iterations against 399; but 300 x 300
  seed 7 took more iterations with 20 than with 10 above: the cap's effect depends on
  the map).
* **Start-up.**  `get_engine(name)` imports only that engine's module (before, both:
  `dgse solve --engine openfoam` loaded numba and SciPy's sparse solvers it never
  used), and each worker of this benchmark imports only its engine, so the OpenFOAM
  column no longer carries the built-in solver's imports.  `scipy.ndimage` (0.17 s)
  is imported only by the coarse start.  What stays: Python and NumPy/SciPy imports
  (~0.6 s), numba's first compiled call (~0.25 s to set up its JIT, then ~5 ms per
  cached kernel).

Before this work (commit 6088505, same machine, not shared then as far as known):

| grid | seed | solve s | iterations | converged |
|---|---|---|---|---|
| 100x100 | 7 | 4.87 | 567 | True |
| 100x100 | 8 | 5.31 | 580 | True |
| 150x150 | 7 | 16.29 | 877 | False |
| 150x150 | 8 | 18.33 | 833 | False |
| 200x200 | 7 | 45.23 | 1069 | False |
| 200x200 | 8 | 40.82 | 937 | False |
"""


if __name__ == "__main__":
    main()
