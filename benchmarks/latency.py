"""Latency of one full DGSE-S estimate: rasterize + network inference + belief on the map.

What is timed: :meth:`dgse.estimators.dgse.DGSEEstimator.estimate` on a map
with 100 random sensor readings (``time.perf_counter``, median of
``--repeats`` runs after one warm-up run), i.e. what a robot pays per
estimate.  The network part alone (:meth:`DGSEEstimator.predict_canvas` on
the rasterized canvas) is timed too for the main grid, so the rest
(rasterize, crop, belief) can be read off.

Runs:

1. main grid at ``K = T = 5`` on a 100 x 100 cell map (100 x 100 canvas):
   float32 and bf16 + channels-last, 1 and 2 PyTorch threads;
2. ``K = T`` in 1, 2, 5, 10 on the 100 x 100 map;
3. square maps of 50, 100, 150 and 200 cells (canvases 100, 100, 160, 208)
   at ``K = T = 5``;

sweeps 2 and 3 with 1 thread, in float32 and bf16 + channels-last.

Model: ``--model auto`` (default) uses the shipped weights
``dgse/assets/models/dgse-s.safetensors`` when installed, else the paper
preset with random weights (``--model random``; latency does not depend on
the weight values); or a checkpoint path.

    python benchmarks/latency.py                 # ~3-5 min on 2 cores
    python benchmarks/latency.py --repeats 3 --quick

Writes ``benchmarks/results/latency.json`` and ``latency.md``.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dgse.bench.core import cpu_model
from dgse.data.rasterize import rasterize
from dgse.estimators.dgse import DGSEEstimator
from dgse.files import write_text
from dgse.models.inference import native_bf16
from dgse.models.networks import DGSEModel, count_parameters, create_model
from dgse.sensing.sensors import Observations

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
N_SENSORS = 100
#: (label, dtype, channels_last)
CONFIGS = {"float32": ("float32", False), "bf16+cl": ("bfloat16", True)}


def load_model(spec: str) -> tuple[DGSEModel, str]:
    """The DGSE-S network to time and a description of where it came from."""
    from dgse.errors import UnsupportedError
    from dgse.estimators.dgse import default_model_path
    from dgse.models.checkpoint import load_model as load

    if spec in ("auto", "default"):
        try:
            path = default_model_path("dgse-s")
        except UnsupportedError:
            if spec == "default":
                raise
        else:
            return load(path, variant="dgse-s"), f"shipped weights {path.name}"
    if spec in ("auto", "random"):
        torch.manual_seed(0)
        return create_model("dgse-s", "paper"), "paper preset, random weights"
    return load(spec, variant="dgse-s"), f"checkpoint {spec}"


def make_map(n: int, seed: int = 0) -> tuple[np.ndarray, Observations]:
    """An ``n x n`` cell map (three rooms: walls at 1/3 and 2/3 with doors) and 100 readings."""
    occ = np.zeros((n, n), np.uint8)
    a, b = n // 3, 2 * n // 3
    occ[:, a] = 1
    occ[b, a:] = 1
    occ[n // 2 - 5 : n // 2 + 5, a] = 0  # doors
    occ[b, (a + n) // 2 - 5 : (a + n) // 2 + 5] = 0
    rng = np.random.default_rng(seed)
    free = np.flatnonzero(occ == 0)
    flat = rng.choice(free, size=min(N_SENSORS, free.size), replace=False)
    cells = np.stack([flat // n, flat % n], axis=1)
    gas = rng.lognormal(2.0, 1.5, size=len(cells))
    wind = rng.normal(0.0, 0.5, size=(len(cells), 2))
    return occ, Observations(cells, gas, wind)


def time_estimate(
    model: DGSEModel,
    n: int,
    K: int,
    T: int,
    dtype: str,
    channels_last: bool,
    threads: int,
    repeats: int,
    with_inference: bool = False,
) -> dict[str, Any]:
    torch.set_num_threads(threads)
    est = DGSEEstimator(copy.deepcopy(model), K=K, T=T, seed=0, dtype=dtype, channels_last=channels_last)
    occ, obs = make_map(n)
    est.estimate(occ, 0.1, obs)  # warm-up (oneDNN kernel selection, allocations)
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        est.estimate(occ, 0.1, obs)
        runs.append(time.perf_counter() - t0)
    canvas = est.canvas_shape(occ.shape)
    row: dict[str, Any] = {
        "map_cells": n,
        "canvas": list(canvas),
        "K": K,
        "T": T,
        "dtype": dtype,
        "channels_last": channels_last,
        "threads": threads,
        "median_s": statistics.median(runs),
        "min_s": min(runs),
        "max_s": max(runs),
        "runs_s": runs,
    }
    if with_inference:
        x = rasterize(occ, obs, canvas)
        inf = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            est.predict_canvas(x)
            inf.append(time.perf_counter() - t0)
        row["inference_median_s"] = statistics.median(inf)
    return row


def _load() -> list[float]:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:  # pragma: no cover - not on every platform
        return []


def _label(r: dict[str, Any]) -> str:
    return "bf16 + channels-last" if r["dtype"] == "bfloat16" else "float32"


def write_markdown(result: dict[str, Any], path: Path) -> None:
    m = result["machine"]
    lines = [
        "# DGSE-S estimate latency (CPU)",
        "",
        f"One full estimate (rasterize + network + belief, `DGSEEstimator.estimate`), median of "
        f"{result['repeats']} runs after a warm-up; {N_SENSORS} sensors; model: {result['model']['source']} "
        f"({result['model']['parameters'] / 1e6:.2f} M parameters).",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, PyTorch {m['torch']} (CPU capability "
        f"{m.get('cpu_capability', 'not recorded')}, native bf16: {m.get('native_bf16', 'not recorded')}); "
        "load average "
        f"{m['load_before']} before, {m['load_after']} after (**shared machine**: other jobs ran on the "
        "same cores, so absolute numbers are pessimistic and noisy; compare rows, not machines).",
        "",
        "## K = T = 5, 100 x 100 cell map",
        "",
        "| precision | threads | estimate median [s] | min | max | network only [s] |",
        "|---|---|---|---|---|---|",
    ]
    for r in result["main"]:
        lines.append(
            f"| {_label(r)} | {r['threads']} | {r['median_s']:.3f} | {r['min_s']:.3f} | {r['max_s']:.3f} "
            f"| {r.get('inference_median_s', float('nan')):.3f} |"
        )
    lines += ["", "## Growth with K = T (100 x 100 map, 1 thread)", ""]
    kts = sorted({r["K"] for r in result["kt_sweep"]})
    labels = sorted({_label(r) for r in result["kt_sweep"]}, reverse=True)
    lines += [
        "| K = T | " + " | ".join(f"{lb} [s]" for lb in labels) + " |",
        "|---" * (len(labels) + 1) + "|",
    ]
    for k in kts:
        cells = [
            f"{r['median_s']:.3f}"
            for lb in labels
            for r in result["kt_sweep"]
            if r["K"] == k and _label(r) == lb
        ]
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    lines += ["", "## Growth with the map (K = T = 5, 1 thread)", ""]
    sizes = sorted({r["map_cells"] for r in result["size_sweep"]})
    labels = sorted({_label(r) for r in result["size_sweep"]}, reverse=True)
    lines += [
        "| map [cells] | canvas | " + " | ".join(f"{lb} [s]" for lb in labels) + " |",
        "|---" * (len(labels) + 2) + "|",
    ]
    for n in sizes:
        rows = [r for r in result["size_sweep"] if r["map_cells"] == n]
        cells = [f"{r['median_s']:.3f}" for lb in labels for r in rows if _label(r) == lb]
        lines.append(
            f"| {n} x {n} | {rows[0]['canvas'][0]} x {rows[0]['canvas'][1]} | " + " | ".join(cells) + " |"
        )
    lines += [
        "",
        "Notes: DGSE-S runs its wind network once, the concentration network on K canvases and the "
        "source network on K T canvases (batched), so the cost grows like 1 + K + K T U-Net passes "
        "(31 at K = T = 5, 111 at K = T = 10) and with the canvas area (maps up to 100 x 100 cells "
        "share the 100 x 100 canvas).  On cores shared with other jobs one PyTorch thread is faster "
        "than two (OpenMP barriers wait for the busy core).  The network-only column is a separate "
        "timing; where it exceeds the full estimate, that is the machine's noise.",
        "",
        f"Total benchmark time {result['seconds_total']:.0f} s.",
        "",
    ]
    write_text(path, "\n".join(lines))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default="auto", help="auto, random, default or a checkpoint path")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per configuration")
    p.add_argument("--quick", action="store_true", help="main grid only")
    p.add_argument("--configs", default="float32,bf16+cl", help="sweep configurations")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--markdown-only", action="store_true", help="re-write latency.md from latency.json")
    args = p.parse_args()
    if args.markdown_only:
        write_markdown(json.loads((args.out / "latency.json").read_text()), args.out / "latency.md")
        return

    t_start = time.perf_counter()
    model, source = load_model(args.model)
    model.eval()
    result: dict[str, Any] = {
        "machine": {
            "cpu": cpu_model(),
            "cores": os.cpu_count(),
            "torch": torch.__version__,
            "cpu_capability": torch.backends.cpu.get_cpu_capability(),
            "native_bf16": native_bf16("cpu"),
            "platform": platform.platform(),
            "load_before": _load(),
        },
        "model": {"source": source, "preset": model.config.preset, "parameters": count_parameters(model)},
        "repeats": args.repeats,
        "n_sensors": N_SENSORS,
        "main": [],
        "kt_sweep": [],
        "size_sweep": [],
    }

    def run(key: str, **kw: Any) -> None:
        row = time_estimate(model, repeats=args.repeats, **kw)
        result[key].append(row)
        print(
            f"{key:10s} map {row['map_cells']:3d} K=T={row['K']:2d} {_label(row):21s} "
            f"threads {row['threads']}: "
            f"{row['median_s']:.3f} s"
            + (f" (network {row['inference_median_s']:.3f} s)" if "inference_median_s" in row else ""),
            flush=True,
        )

    for label in ("float32", "bf16+cl"):
        dtype, cl = CONFIGS[label]
        for threads in (1, 2):
            run("main", n=100, K=5, T=5, dtype=dtype, channels_last=cl, threads=threads, with_inference=True)
    if not args.quick:
        for label in args.configs.split(","):
            dtype, cl = CONFIGS[label]
            for k in (1, 2, 5, 10):
                run("kt_sweep", n=100, K=k, T=k, dtype=dtype, channels_last=cl, threads=1)
            for n in (50, 100, 150, 200):
                run("size_sweep", n=n, K=5, T=5, dtype=dtype, channels_last=cl, threads=1)
    result["machine"]["load_after"] = _load()
    result["seconds_total"] = time.perf_counter() - t_start
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "latency.json", json.dumps(result, indent=1) + "\n")
    write_markdown(result, args.out / "latency.md")
    print(f"wrote {args.out / 'latency.json'} and latency.md in {result['seconds_total']:.0f} s")


if __name__ == "__main__":
    main()
