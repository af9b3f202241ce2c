"""How often the built-in flow solver converges on the training distribution.

Solves the flow of ``--count`` random training layouts (seeds ``--start`` ...)
with default settings and records iterations, attempts, time and how each
run ended (converged, stalled, diverged).

    python benchmarks/solver_robustness.py --start 100 --count 40

Writes ``benchmarks/results/solver_robustness.{json,md}``.

``--ser-small 0 0.9 0.95`` instead solves each layout once for every value of
``FlowSettings.alpha_turb_max_small`` (the turbulence relaxation bound of
paper-size maps; 0: no SER), back to back, and compares iterations, CPU
seconds and the wind against the first value's; it writes
``benchmarks/results/solver_ser_small.{json,md}`` (how the default was chosen).
``--variants "pressure_solver=lu" "pressure_solver=dic,p_rel_tol=0.03" --name NAME`` does the
same for any ``FlowSettings`` fields (JSON values) and writes ``NAME.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dgse.files import write_text
from dgse.physics.builtin import flow_and_transport
from dgse.world.generate import as_generator, random_inlet_velocity, random_layout

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--start", type=int, default=100)
    ap.add_argument("--count", type=int, default=40)
    ap.add_argument("--ser-small", type=float, nargs="+", default=None, metavar="ALPHA")
    ap.add_argument("--variants", nargs="+", default=None, metavar="FIELD=VALUE[,...]")
    ap.add_argument("--name", default="solver_variants", help="result file name of --variants")
    args = ap.parse_args()
    command = "python benchmarks/solver_robustness.py " + " ".join(sys.argv[1:])
    if args.ser_small:
        variants = [f"alpha_turb_max_small={a:g}" for a in args.ser_small]
        compare(args.start, args.count, variants, "solver_ser_small", command)
        return
    if args.variants:
        compare(args.start, args.count, args.variants, args.name, command)
        return
    rows = []
    for seed in range(args.start, args.start + args.count):
        rng = as_generator(seed)
        layout = random_layout(rng)
        v = random_inlet_velocity(rng)
        flow, _ = flow_and_transport(layout, v)
        i = flow.info
        rows.append(
            {
                "seed": seed,
                "shape": list(layout.grid.shape),
                "inlet_velocity": v,
                "iterations": i["iterations"],
                "attempts": len(i["attempts"]),
                "converged": i["converged"],
                "stalled": i["stalled"],
                "diverged": i["diverged"],
                "seconds": i["seconds"],
                "residuals": i["residuals"],
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    n_ok = sum(r["converged"] for r in rows)
    secs = sorted(r["seconds"] for r in rows)
    summary = {
        "layouts": len(rows),
        "converged": n_ok,
        "retried": sum(r["attempts"] > 1 for r in rows),
        "median_seconds": secs[len(secs) // 2],
        "max_seconds": secs[-1],
        "median_iterations": sorted(r["iterations"] for r in rows)[len(rows) // 2],
    }
    out = REPO / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "solver_robustness.json", json.dumps({"summary": summary, "runs": rows}, indent=1))
    md = [
        f"Seeds {args.start}-{args.start + args.count - 1}: {n_ok} of {len(rows)} flows converged "
        f"({summary['retried']} after a second attempt with stronger relaxation); "
        f"median {summary['median_iterations']} iterations, median {summary['median_seconds']:.2f} s, "
        f"slowest {summary['max_seconds']:.1f} s (flow only, warm process).",
        "",
        "| seed | cells | v_in m/s | iterations | attempts | converged | how it ended |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        end = (
            "converged"
            if r["converged"]
            else "stalled"
            if r["stalled"]
            else "diverged"
            if r["diverged"]
            else "limit"
        )
        md.append(
            f"| {r['seed']} | {r['shape'][1]}x{r['shape'][0]} | {r['inlet_velocity']:.2f} | "
            f"{r['iterations']} | {r['attempts']} | {r['converged']} | {end} |"
        )
    write_text(out / "solver_robustness.md", "\n".join(md) + "\n")
    print(md[0])


def _parse_variant(text: str) -> dict:
    """``"key=value,key=value"`` (values as JSON where they parse, else strings) -> FlowSettings fields."""
    from dataclasses import fields

    from dgse.cli.common import parse_params
    from dgse.errors import InputDataError
    from dgse.physics.rans import FlowSettings

    try:
        out = parse_params(list(filter(None, text.split(","))), "--variants")
    except InputDataError as e:
        raise SystemExit(str(e)) from None
    unknown = set(out) - {f.name for f in fields(FlowSettings)}
    if unknown:
        raise SystemExit(f"--variants: {sorted(unknown)} are not FlowSettings fields")
    return out


def compare(start: int, count: int, variants: list[str], name: str, command: str) -> None:
    """Each layout solved with every settings variant in turn (interleaved, so that a busy
    machine slows them alike); CPU seconds, as wall time on a shared machine is noisy; the
    wind against the first variant's."""
    import time

    import numpy as np

    from dgse.physics.rans import FlowSettings

    settings = [FlowSettings(**_parse_variant(v)) for v in variants]
    rows = []
    for seed in range(start, start + count):
        rng = as_generator(seed)
        layout = random_layout(rng)
        v = random_inlet_velocity(rng)
        if seed == start:
            flow_and_transport(layout, v)  # numba's kernels loaded: not timed
        winds = []
        for label, st in zip(variants, settings, strict=True):
            c = time.process_time()
            flow, _ = flow_and_transport(layout, v, settings=st)
            i = flow.info
            rows.append(
                {
                    "seed": seed,
                    "variant": label,
                    "cells": int(layout.free.sum()),
                    "iterations": i["iterations"],
                    "attempts": len(i["attempts"]),
                    "converged": i["converged"],
                    "cpu_s": time.process_time() - c,
                }
            )
            winds.append(flow.wind)
        for r, w in zip(rows[-len(variants) :], winds, strict=True):
            r["wind_rel_diff"] = float(np.linalg.norm(w - winds[0]) / np.linalg.norm(winds[0]))
        print(json.dumps(rows[-len(variants) :]), flush=True)
    first = [r for r in rows if r["variant"] == variants[0]]
    summary = []
    for label in variants:
        rr = [r for r in rows if r["variant"] == label]
        both = [(r, b) for r, b in zip(rr, first, strict=True) if r["converged"] and b["converged"]]
        summary.append(
            {
                "variant": label,
                "converged": sum(r["converged"] for r in rr),
                "retried": sum(r["attempts"] > 1 for r in rr),
                "median_iterations": float(np.median([r["iterations"] for r in rr])),
                "median_cpu_s": float(np.median([r["cpu_s"] for r in rr])),
                "total_cpu_s": float(sum(r["cpu_s"] for r in rr)),
                "more_iterations_than_first": sum(r["iterations"] > b["iterations"] for r, b in both),
                "median_wind_rel_diff": float(np.median([r["wind_rel_diff"] for r, _ in both])),
                "max_wind_rel_diff": float(max(r["wind_rel_diff"] for r, _ in both)),
            }
        )
    out = REPO / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / f"{name}.json", json.dumps({"summary": summary, "runs": rows}, indent=1))
    md = [
        f"Seeds {start}-{start + count - 1} (training-distribution layouts, all under 12k free cells), "
        f"each solved with every settings variant back to back (`{command}`); CPU seconds of the "
        "flow in a warm process; wind difference against the first variant's flow (where both converged).",
        "",
        "| settings | converged | retried | median iterations | median CPU s | total CPU s | "
        "more iterations than the first | wind rel. diff median / max |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in summary:
        md.append(
            f"| `{r['variant']}` | {r['converged']} of {count} | {r['retried']} | "
            f"{r['median_iterations']:.0f} | "
            f"{r['median_cpu_s']:.2f} | {r['total_cpu_s']:.1f} | {r['more_iterations_than_first']} | "
            f"{r['median_wind_rel_diff']:.1e} / {r['max_wind_rel_diff']:.1e} |"
        )
    write_text(out / f"{name}.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
