"""How often the built-in flow solver converges on the training distribution.

Solves the flow of ``--count`` random training layouts (seeds ``--start`` ...)
with default settings and records iterations, attempts, time and how each
run ended (converged, stalled, diverged).

    python benchmarks/solver_robustness.py --start 100 --count 40

Writes ``benchmarks/results/solver_robustness.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dgse.physics.builtin import flow_and_transport
from dgse.world.generate import as_generator, random_inlet_velocity, random_layout

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--start", type=int, default=100)
    ap.add_argument("--count", type=int, default=40)
    args = ap.parse_args()
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
    (out / "solver_robustness.json").write_text(json.dumps({"summary": summary, "runs": rows}, indent=1))
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
    (out / "solver_robustness.md").write_text("\n".join(md) + "\n")
    print(md[0])


if __name__ == "__main__":
    main()
