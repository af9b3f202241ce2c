"""Where a fresh process's time goes when it solves one paper-size layout with the built-in engine.

Each run is a new Python process (the benchmark's own ``--child``) that imports
the built-in engine, reads a layout drawn beforehand (``solver_speed``'s
scenarios), solves the flow and four gas sources and writes the fields, as
``solver_speed``'s workers do.  It records the wall time of each phase (the
shutdown: from the child's last timestamp until the parent sees it exit) and
every pass of the cyclic garbage collector (``gc.callbacks``).  Two settings
alternate, run by run: CPython's collector defaults, and the ``dgse`` console
script's (:mod:`dgse.cli.process`: first threshold 50,000, live objects frozen
before the shutdown).

    python benchmarks/process_startup.py --repeats 6

Writes ``benchmarks/results/process_startup.{json,md}``.  Run it on an idle machine,
in the interpreter whose start-up you want to know (``sys.executable`` runs the
children).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SETTINGS = ("cpython-defaults", "dgse-console-script")


def child(scenario_file: str, setting: str) -> None:
    """One process's solve, timed by phase; prints one JSON line."""
    t_start = time.time()
    import gc

    passes = {"n": 0, "s": 0.0, "t": 0.0}

    def on_gc(phase: str, _info: dict) -> None:
        if phase == "start":
            passes["t"] = time.perf_counter()
        else:
            passes["n"] += 1
            passes["s"] += time.perf_counter() - passes["t"]

    gc.callbacks.append(on_gc)
    from dgse.cli import process

    if setting == "dgse-console-script":
        process.start()
    import numpy as np

    sys.path.insert(0, str(REPO / "benchmarks"))
    from solver_speed import _load_scenario  # this folder's

    from dgse.physics.builtin import BuiltinEngine
    from dgse.physics.engines import Source

    t_imported = time.time()
    gc_imports = dict(passes)
    layout, v, sources = _load_scenario(scenario_file)
    sol = BuiltinEngine().solve(layout, v, [Source(p, q) for p, q in sources])
    t_solved = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        np.savez(Path(tmp) / "fields", wind=sol.flow.wind, conc=np.stack(sol.concentrations))
    if setting == "dgse-console-script":
        process.finish()
    record = {
        "start": t_start,
        "imports_s": t_imported - t_start,
        "solve_s": t_solved - t_imported,
        "flow_s": sol.flow.info["seconds"],
        "iterations": sol.flow.info["iterations"],
        "gc_passes_imports": gc_imports["n"],
        "gc_s_imports": gc_imports["s"],
        "gc_passes": passes["n"],
        "gc_s": passes["s"],
        "end": time.time(),
    }
    print(json.dumps(record), flush=True)


def run_once(scenario_file: Path, setting: str) -> dict:
    t0 = time.time()
    out = subprocess.run(
        [sys.executable, __file__, "--child", str(scenario_file), "--setting", setting],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
    )
    t1 = time.time()
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    rec["wall_s"] = t1 - t0
    rec["interpreter_start_s"] = rec.pop("start") - t0
    rec["shutdown_s"] = t1 - rec.pop("end")
    rec["setting"] = setting
    return rec


def main() -> None:
    from dgse.files import write_text

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--setting", default=SETTINGS[0], choices=SETTINGS, help=argparse.SUPPRESS)
    ap.add_argument("--scenario", default="rand:1002", help="a solver_speed scenario (default rand:1002)")
    ap.add_argument("--repeats", type=int, default=6)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args()
    if args.child:
        child(args.child, args.setting)
        return
    sys.path.insert(0, str(REPO / "benchmarks"))
    from solver_speed import prepare  # this folder's

    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        file = prepare(args.scenario, Path(tmp))
        run_once(file, SETTINGS[0])  # numba's cache written if it was not: not counted
        for rep in range(args.repeats):
            for setting in SETTINGS:
                runs.append(run_once(file, setting) | {"repeat": rep})
                print(json.dumps(runs[-1]), flush=True)
    keys = ("wall_s", "interpreter_start_s", "imports_s", "solve_s", "flow_s", "shutdown_s")
    keys += ("gc_s", "gc_passes")
    summary = {
        s: {k: statistics.median(r[k] for r in runs if r["setting"] == s) for k in keys} for s in SETTINGS
    }
    result = {
        "scenario": args.scenario,
        "python": platform.python_version(),
        "executable": sys.executable,
        "virtual_env": sys.prefix != sys.base_prefix,
        "summary": summary,
        "runs": runs,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "process_startup.json", json.dumps(result, indent=1))
    where = "a virtual environment" if result["virtual_env"] else "a system interpreter"
    md = [
        f"One built-in solve of `{args.scenario}` (flow and four gas sources) per fresh process, "
        f"{args.repeats} runs per collector setting, alternating; medians in seconds. Python "
        f"{result['python']} in {where} (`{sys.executable}`); "
        f"`python benchmarks/process_startup.py --repeats {args.repeats}`.",
        "",
        "| collector | wall | interpreter start | imports | solve (flow, gas) | of it the flow | shutdown | "
        "in the collector | collector passes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s, m in summary.items():
        md.append(
            f"| {s} | {m['wall_s']:.2f} | {m['interpreter_start_s']:.3f} | {m['imports_s']:.2f} | "
            f"{m['solve_s']:.2f} | {m['flow_s']:.2f} | {m['shutdown_s']:.3f} | {m['gc_s']:.3f} | "
            f"{m['gc_passes']:.0f} |"
        )
    md += [
        "",
        "The flow's seconds include numba's first compiled call (loading the cached kernels), "
        "which sets up numba's typing and lowering context once.",
    ]
    write_text(args.out / "process_startup.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
