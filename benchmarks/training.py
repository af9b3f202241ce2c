"""The data, the networks and the baselines' tuning: throughput, curves, cards, latency, size.

One command per measurement (``python benchmarks/training.py COMMAND --help``), each writing
under ``benchmarks/results/`` (``benchmarks/gpu_train.sh`` is the one-lease GPU training run,
``benchmarks/results/gpu_training/``):

* ``throughput``: dataset generation throughput, paper-size layouts x 4 sources on 1 and 2
  Dask workers (:func:`dgse.data.generation.generate` into a fresh store): layouts stored per
  minute with and without the start-up, the mean task time per layout, bytes per layout, and
  the projected wall time for the paper's 3,750 layouts.  Writes
  ``generation_throughput.json``::

      python benchmarks/training.py throughput --layouts 16 --workers 1 2

* ``store-agreement``: a store rebuilt with ``dgse generate --split test`` (the same layouts,
  inlet speeds and sources, solved by today's solver) against the statistics recorded of the
  original, layout by layout and case by case::

      dgse generate --layouts 1000 --out dgse1000.h5 --split test
      python benchmarks/training.py store-agreement dgse1000.h5 benchmarks/results/dataset_stats.json \\
          -o benchmarks/results/store_agreement.json

* ``curves``: validation curves of the DGSE variants against the optimizer steps (like the
  paper's fig4), from the ``history.csv`` files ``dgse train`` writes; a CSV of the plotted
  values beside the figure::

      python benchmarks/training.py curves dgse-o=benchmarks/results/dgse-o-small_history.csv \\
          dgse-p=benchmarks/results/dgse-p-small_history.csv \\
          dgse-s=benchmarks/results/dgse-s-small_history.csv -o benchmarks/results/training_curves.png

* ``card``: the model card of a shipped model from its checkpoint's metadata, its run's
  ``history.csv`` and ``dgse evaluate`` JSON files (the ``dgse-s_*.json`` results are such
  evaluations)::

      python benchmarks/training.py card --weights src/dgse/assets/models/dgse-s.safetensors \\
          --run RUN_DIR --eval val=VAL.json --eval test=TEST.json --eval reference=REF.json \\
          --command "dgse train ..." -o src/dgse/assets/models/dgse-s.md

* ``eta``: the entropy-termination threshold of a model (the utility planner's ``stop.eta``:
  it stops when ``H(pi_s) <= eta log N``), chosen on the validation split: per threshold the
  share of validation estimates below it and their median localization error.  Writes
  ``eta_validation.json``::

      python benchmarks/training.py eta STORE

* ``few-readings``: how confident and how wrong the shipped DGSE-S is from very few random
  readings (why the planner's ``stop.min_observations``): its normalized source entropy and
  error per count::

      python benchmarks/training.py few-readings benchmarks/results/report/_scenarios/test-20 \\
          --counts 1 2 3 4 5 10 20 50 --trials 5 -o benchmarks/results/few_readings.json

* ``latency``: one full DGSE-S estimate (rasterize, network, belief) on a map with 100
  readings, median of ``--repeats``: float32 and bf16 + channels-last, 1 and 2 threads, then
  ``K = T`` and map-size sweeps.  Writes ``latency.{json,md}``::

      python benchmarks/training.py latency
      python benchmarks/training.py latency --quick --repeats 3 --out benchmarks/results/latency_avx2

* ``size-error``: DGSE-S's source-localization error against the map size per set of
  weights, on random multi-room layouts per size bin (seeds ``6000 + 100 bin + k``) and on
  generated office floors (:func:`dgse.bench.scenarios.office_floor_cases`), against the
  guess "the source is at the highest reading".  Writes ``OUT/size_error.{json,md,png}``::

      python benchmarks/training.py size-error --model default \\
          benchmarks/results/size_error/dgse-s-sizes.safetensors \\
          benchmarks/results/gpu_training/dgse-s-gpu.safetensors \\
          benchmarks/results/gpu_training/sizes/dgse-s-gpu-sizes.safetensors
      python benchmarks/training.py size-error --bins --floors 10 --model default ... \\
          -o benchmarks/results/size_error_floors

* ``gdm``: the GDM baselines' free parameters tuned on the validation split of a store
  (:mod:`dgse.bench.gdm_tuning`).  Writes ``gdm_tuning.json``, which the baselines read with
  ``tuning=``::

      python benchmarks/training.py gdm data/store.h5
      python benchmarks/training.py gdm data/store.h5 --methods ggmrf --max-cases 50

The results beside these that the ``dgse`` command made (their commands are in the README
where it cites them): ``dataset_stats.{json,png}`` (``dgse data stats STORE --plot``),
``dgse-s_*.json`` and ``dgse-s-equal-steps_test60.json`` (``dgse evaluate``),
``search_2threads_test6.json`` (``dgse search``), and the ``history.csv`` of the shipped
models' ``dgse train`` runs (``dgse-{o,p,s}-small_history.csv``,
``dgse-s-equal-steps_history.csv``, ``size_error/dgse-s-sizes_history.csv``).

PyTorch and matplotlib are imported by the commands that use them.
"""

from __future__ import annotations

import copy
import csv
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from dgse.bench.commands import command_parser, run_command
from dgse.files import atomic_open, atomic_path, write_text

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"


def _name(path: object) -> str:
    """A file or folder by its own name, without the folders it lay in (``?`` when unknown), so
    that a model card holds no machine's paths."""
    return (Path(str(path)).name or "?") if path else "?"


_parser = partial(command_parser, "training.py")


#: The paper's dataset size, layouts.
PAPER_LAYOUTS = 3750


def throughput_run(n_layouts: int, workers: int, seed: int, directory: Path) -> dict:
    """One generation run into a fresh store and its rates."""
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


def throughput(argv: list[str]) -> None:
    """``throughput``: dataset generation throughput with 1 and 2 Dask workers (module doc)."""
    ap = _parser("throughput", "dataset generation throughput: paper-size layouts x 4 sources")
    ap.add_argument("--layouts", type=int, default=12)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "generation_throughput.json")
    args = ap.parse_args(argv)
    results = []
    with tempfile.TemporaryDirectory() as d:
        for w in args.workers:
            r = throughput_run(args.layouts, w, args.seed, Path(d))
            print(json.dumps(r))
            results.append(r)
    import scipy

    doc = {
        "benchmark": "dataset generation throughput (paper-size layouts, 4 sources each)",
        "command": "python benchmarks/training.py throughput "
        f"--layouts {args.layouts} --workers {' '.join(map(str, args.workers))} --seed {args.seed}",
        "machine": {
            "cpus": len(os.sched_getaffinity(0)),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
        },
        "date": time.strftime("%Y-%m-%d"),
        "results": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


#: Per-layout quantities that the draws alone decide, and those the solver decides too.
DRAWN = ("width_m", "height_m", "inlet_velocity")
SOLVED_LAYOUT = ("max_speed",)
SOLVED_CASE = ("max_ppm", "mean_ppm")


def store_agreement(argv: list[str]) -> None:
    """``store-agreement``: a rebuilt store against the statistics recorded of the original (module doc)."""
    from dgse.data.stats import dataset_stats
    from dgse.data.store import DatasetStore

    ap = _parser(
        "store-agreement", "how a rebuilt dataset store compares with the statistics recorded of the original"
    )
    ap.add_argument("store", type=Path, help="the rebuilt store")
    ap.add_argument("recorded", type=Path, help="dataset_stats JSON of the original store")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "store_agreement.json")
    args = ap.parse_args(argv)
    old = json.loads(args.recorded.read_text())["values"]
    new = dataset_stats(args.store)["values"]
    with DatasetStore(args.store, "r") as s:
        index = [int(lid.rsplit("-", 1)[1]) for lid in s.layouts()]
        n_src = [s.n_sources(lid) for lid in s.layouts()]
    per_source = len(old["release_rate_gps"]) // len(old["width_m"])
    cases = [per_source * i + k for i, n in zip(index, n_src, strict=True) for k in range(n)]
    report: dict[str, object] = {"store": str(args.store), "recorded": str(args.recorded)}
    report["layouts"] = len(index)
    pairs = [(q, index) for q in DRAWN] + [("release_rate_gps", cases)]
    same = [np.allclose([old[q][i] for i in where], new[q], rtol=1e-12, atol=0) for q, where in pairs]
    report["drawn_equal"] = bool(all(same))
    for q, where in [*((q, index) for q in SOLVED_LAYOUT), *((q, cases) for q in SOLVED_CASE)]:
        ratio = np.asarray(new[q], float) / np.asarray([old[q][i] for i in where], float)
        report[q] = {
            "n": int(ratio.size),
            "within_1pct": float(np.mean(np.abs(ratio - 1) < 0.01)),
            "within_5pct": float(np.mean(np.abs(ratio - 1) < 0.05)),
            "ratio_min": float(ratio.min()),
            "ratio_max": float(ratio.max()),
        }
    write_text(args.out, json.dumps(report, indent=1) + "\n")
    print(json.dumps(report, indent=1))


def _read(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def curves(argv: list[str]) -> None:
    """``curves``: validation curves of the DGSE variants against the optimizer steps (module doc)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dgse.bench.plots import style_of

    ap = _parser("curves", "validation curves of the DGSE variants against the optimizer steps")
    ap.add_argument("runs", nargs="+", help="NAME=history.csv")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args(argv)
    panels = [
        ("train/source_loss", "training source loss (CE)"),
        ("val/source_loss", "validation source loss (CE)"),
        ("val/loc_error_m", "validation localization error (m)"),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    table = []
    for spec in args.runs:
        name, _, file = spec.partition("=")
        rows = _read(Path(file))
        st = style_of(name)
        for ax, (key, label) in zip(axes, panels, strict=True):
            steps = [int(r["global_step"]) for r in rows if r.get(key)]
            ys = [float(r[key]) for r in rows if r.get(key)]
            ax.plot(steps, ys, marker=st["marker"], color=st["color"], label=st["label"], ms=3)
            ax.set_xlabel("optimizer steps")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        for r in rows:
            table.append(
                {"method": name, "epoch": r["epoch"], "global_step": r["global_step"]}
                | {k: r.get(k) for k, _ in panels}
            )
    axes[0].legend()
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        fig.savefig(tmp, dpi=110)
    with atomic_open(args.out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["method", "epoch", "global_step", *(k for k, _ in panels)])
        w.writeheader()
        w.writerows(table)
    print(f"wrote {args.out} and {args.out.with_suffix('.csv')}")


def _card_row(agg: dict, n: str) -> str:
    a = agg[n]

    def f(key: str, fmt: str = ".3f") -> str:
        v = a.get(key)
        return "n/a" if v is None else format(v, fmt)

    return (
        f"| {n} | {f('sl_error_m_mean', '.2f')} | {f('sl_error_m_median', '.2f')} | {f('ce_mean', '.2f')} | "
        f"{f('wf_rmse_mean')} | {f('cf_rmse_mean')} | {f('seconds_per_estimate_median')} |"
    )


def card(argv: list[str]) -> None:
    """``card``: the model card of a shipped DGSE model from files (module doc)."""
    from dgse.models.checkpoint import load_model, read_checkpoint_info
    from dgse.models.networks import count_parameters

    ap = _parser("card", "write the model card of a shipped DGSE model from its training run and evaluations")
    ap.add_argument("--weights", required=True, type=Path)
    ap.add_argument("--run", required=True, type=Path, help="training run directory (history.csv)")
    ap.add_argument("--eval", action="append", default=[], help="NAME=evaluation.json (repeatable)")
    ap.add_argument("--command", default="", help="the training command(s), for the card")
    ap.add_argument("-o", "--out", required=True, type=Path)
    args = ap.parse_args(argv)

    info = read_checkpoint_info(args.weights)
    n_params = count_parameters(load_model(args.weights))
    cpu = platform.processor() or "x86_64"
    rows = list(csv.DictReader(open(args.run / "history.csv")))
    train_s = sum(float(r["time_s"]) for r in rows)
    best = min(rows, key=lambda r: float(r["val/source_loss"] or "inf"))
    lines = [
        f"# Model card: {args.weights.name}",
        "",
        f"- **Model:** {info.variant} (`{info.config}`), "
        f"{n_params / 1e6:.3f} M parameters; weights in safetensors, "
        "loadable as `--model default`.",
        f"- **Data:** `{_name(info.training.get('data'))}`, 1,000 generated layouts made by "
        "`dgse generate --layouts 1000 --seed 0` with the built-in solver "
        "(800 / 133 / 67 train / val / test layouts, 4 sources each).",
        f"- **Training:** {len(rows)} epochs, {int(rows[-1]['global_step'])} steps, "
        f"{train_s / 3600:.2f} h of wall time on {os.cpu_count()} CPU cores ({cpu}), "
        "shared with other jobs; checkpoint of the lowest validation source loss "
        f"(epoch {best['epoch']}).",
        f"- **Command:** `{args.command}`" if args.command else "",
        "",
        "## Validation during training (history.csv)",
        "",
        "| epoch | train loss | val source loss (CE) | val wind NLL | val conc NLL | val loc. error m |",
        "|---|---|---|---|---|---|",
    ]

    def num(v: str | None, fmt: str = ".3f") -> str:
        return "n/a" if not v else format(float(v), fmt)

    for r in rows:
        lines.append(
            f"| {r['epoch']} | {num(r['train/loss'])} | {num(r['val/source_loss'])} | "
            f"{num(r.get('val/wind_nll'))} | {num(r.get('val/conc_nll'))} | "
            f"{num(r['val/loc_error_m'], '.2f')} |"
        )
    for spec in args.eval:
        name, _, path = spec.partition("=")
        ev = json.load(open(path))
        source = ev.get("split") or _name(ev["cases_source"])
        lines += [
            "",
            f"## {name}: `dgse evaluate` on {ev['n_cases']} cases ({source}), "
            f"{ev['trials']} trials, seed {ev['seed']}",
            "",
            "| observations | SL error mean m | SL error median m | CE | wind RMSE m/s | log(1+ppm) RMSE | "
            "s per estimate |",
            "|---|---|---|---|---|---|---|",
        ]
        lines += [_card_row(ev["aggregate"], n) for n in ev["aggregate"]]
    lines += [
        "",
        "## Limits",
        "",
        f"Trained on a CPU for {train_s / 3600:.1f} h ({len(rows)} epochs) on 1,000 layouts: far less than "
        "the paper's 100 epochs on "
        "3,000 layouts with 30 configurations per environment. It is a working default, not the paper's "
        "accuracy; `configs/train/` and `dgse train --resume` continue from here on better hardware.",
    ]
    write_text(args.out, "\n".join(x for x in lines if x is not None) + "\n")
    print(args.out.read_text())


def eta(argv: list[str]) -> None:
    """``eta``: a model's entropy-termination threshold, tuned on the validation split (module doc)."""
    from dgse.evaluation.evaluate import evaluate

    ap = _parser("eta", "entropy-termination threshold of a model, tuned on the validation split only")
    ap.add_argument("store")
    ap.add_argument("--model", default="default")
    ap.add_argument("--limit", type=int, default=120)
    ap.add_argument("--counts", type=int, nargs="*", default=[25, 50, 100])
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "eta_validation.json")
    args = ap.parse_args(argv)
    res = evaluate(
        args.store,
        "dgse-s",
        args.counts,
        trials=1,
        seed=1,
        split="val",
        limit=args.limit,
        estimator_kwargs={"model": args.model, "dtype": "bf16"},
    )
    table = {}
    for n in args.counts:
        recs = [r for r in res["per_case"] if r["n_obs"] == n]
        ent = np.array([r["normalized_entropy"] for r in recs])
        err = np.array([r["sl_error_m"] for r in recs])
        rows = {}
        for threshold in (0.65, 0.7, 0.75, 0.78, 0.8, 0.82, 0.85):
            below = ent <= threshold
            rows[str(threshold)] = {
                "share_below": float(below.mean()),
                "median_error_below_m": float(np.median(err[below])) if below.any() else None,
            }
        table[str(n)] = {
            "estimates": len(recs),
            "median_normalized_entropy": float(np.median(ent)),
            "median_error_m": float(np.median(err)),
            "thresholds": rows,
        }
        print(n, json.dumps(table[str(n)]))
    out = args.out
    write_text(
        out,
        json.dumps(
            {
                "store": args.store,
                "model": args.model,
                "split": "val",
                "limit": args.limit,
                "by_observations": table,
            },
            indent=1,
        ),
    )
    print(f"wrote {out}")


def few_readings(argv: list[str]) -> None:
    """``few-readings``: how confident and how wrong DGSE-S is from very few readings (module doc)."""
    from dgse.estimators.registry import get_estimator
    from dgse.sensing.sensors import random_observations
    from dgse.world.case import Case

    ap = _parser("few-readings", "how confident and how wrong DGSE-S is from very few random readings")
    ap.add_argument("cases", type=Path, help="folder of case files (.npz)")
    ap.add_argument("--counts", type=int, nargs="+", default=[1, 2, 3, 4, 5, 10, 20, 50])
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument(
        "--eta", type=float, default=0.78, help="threshold to count estimates below (as stop.eta)"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args(argv)

    est = get_estimator("dgse-s", model="default", dtype="bf16", channels_last=True)
    files = sorted(args.cases.glob("*.npz"))
    if not files:
        raise SystemExit(f"no case files in {args.cases}")
    per_case = []
    pooled: dict[int, dict[str, list[float]]] = {n: {"h": [], "err": []} for n in args.counts}
    for k, f in enumerate(files):
        case = Case.load(f)
        rng = np.random.default_rng([args.seed, k])
        row: dict[str, object] = {"case": f.stem}
        for n in args.counts:
            hs, errs = [], []
            for _ in range(args.trials):
                b = est.estimate(case.occupancy, case.resolution, random_observations(case, n, rng))
                hs.append(float(b.normalized_entropy()))
                errs.append(float(np.hypot(*(np.asarray(b.source_estimate()) - case.source))))
            row[str(n)] = {"entropy": hs, "error_m": errs}
            pooled[n]["h"] += hs
            pooled[n]["err"] += errs
        per_case.append(row)
    summary = {}
    print(f"{'readings':>8} {'H/logN median':>14} {'min':>6} {'below eta':>10} {'err below eta (m)':>18}")
    for n in args.counts:
        h, e = np.array(pooled[n]["h"]), np.array(pooled[n]["err"])
        below = h <= args.eta
        summary[str(n)] = {
            "estimates": int(h.size),
            "normalized_entropy_median": float(np.median(h)),
            "normalized_entropy_min": float(h.min()),
            "share_below_eta": float(below.mean()),
            "error_m_mean": float(e.mean()),
            "error_m_mean_below_eta": float(e[below].mean()) if below.any() else None,
        }
        s = summary[str(n)]
        eb = "-" if s["error_m_mean_below_eta"] is None else f"{s['error_m_mean_below_eta']:.2f}"
        print(
            f"{n:>8} {s['normalized_entropy_median']:>14.3f} {s['normalized_entropy_min']:>6.3f} "
            f"{s['share_below_eta']:>10.2f} {eb:>18}"
        )
    out = {
        "cases": str(args.cases),
        "trials": args.trials,
        "eta": args.eta,
        "seed": args.seed,
        "model": "default (dgse-s), bf16",
        "pooled": summary,
        "per_case": per_case,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps(out, indent=1))
    print(f"wrote {args.out}")


#: The readings of each timed estimate.
N_SENSORS = 100
#: label -> (dtype, channels_last) of ``latency``'s sweeps
LATENCY_CONFIGS = {"float32": ("float32", False), "bf16+cl": ("bfloat16", True)}


def latency_model(spec: str) -> tuple[Any, str]:
    """The DGSE-S network to time and a description of where it came from."""
    import torch

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
        from dgse.models.networks import create_model

        return create_model("dgse-s", "paper"), "paper preset, random weights"
    return load(spec, variant="dgse-s"), f"checkpoint {spec}"


def make_map(n: int, seed: int = 0) -> tuple[np.ndarray, Any]:
    """An ``n x n`` cell map (three rooms: walls at 1/3 and 2/3 with doors) and 100 readings."""
    from dgse.sensing.sensors import Observations

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
    model: Any,
    n: int,
    K: int,
    T: int,
    dtype: str,
    channels_last: bool,
    threads: int,
    repeats: int,
    with_inference: bool = False,
) -> dict[str, Any]:
    """One configuration's timings: the full estimate (and the network alone)."""
    import torch

    from dgse.data.rasterize import rasterize
    from dgse.estimators.dgse import DGSEEstimator

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


def latency(argv: list[str]) -> None:
    """``latency``: one full DGSE-S estimate timed (module doc)."""
    import torch

    from dgse.bench.core import cpu_model
    from dgse.models.inference import native_bf16
    from dgse.models.networks import count_parameters

    p = _parser("latency", "latency of one full DGSE-S estimate: rasterize + network inference + belief")
    p.add_argument("--model", default="auto", help="auto, random, default or a checkpoint path")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per configuration")
    p.add_argument("--quick", action="store_true", help="main grid only")
    p.add_argument("--configs", default="float32,bf16+cl", help="sweep configurations")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--markdown-only", action="store_true", help="re-write latency.md from latency.json")
    args = p.parse_args(argv)
    if args.markdown_only:
        write_markdown(json.loads((args.out / "latency.json").read_text()), args.out / "latency.md")
        return

    t_start = time.perf_counter()
    model, source = latency_model(args.model)
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

    def timed(key: str, **kw: Any) -> None:
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
        dtype, cl = LATENCY_CONFIGS[label]
        for threads in (1, 2):
            timed(
                "main", n=100, K=5, T=5, dtype=dtype, channels_last=cl, threads=threads, with_inference=True
            )
    if not args.quick:
        for label in args.configs.split(","):
            dtype, cl = LATENCY_CONFIGS[label]
            for k in (1, 2, 5, 10):
                timed("kt_sweep", n=100, K=k, T=k, dtype=dtype, channels_last=cl, threads=1)
            for n in (50, 100, 150, 200):
                timed("size_sweep", n=n, K=5, T=5, dtype=dtype, channels_last=cl, threads=1)
    result["machine"]["load_after"] = _load()
    result["seconds_total"] = time.perf_counter() - t_start
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "latency.json", json.dumps(result, indent=1) + "\n")
    write_markdown(result, args.out / "latency.md")
    print(f"wrote {args.out / 'latency.json'} and latency.md in {result['seconds_total']:.0f} s")


#: The size bins of ``size-error``, sides in m.
BINS = [(5.0, 10.0), (10.0, 15.0), (15.0, 20.0)]


def bin_cases(out: Path, b: int, lo: float, hi: float, n: int) -> list[tuple[str, Any]]:
    """The first ``n`` scenarios of size bin ``b`` (sides in ``[lo, hi]`` m) whose flow converges.

    Seeds ``6000 + 100 b + k`` in order; each is solved once and kept (a seed whose flow
    does not converge is marked ``.failed`` and skipped, as ``dgse generate`` skips it).
    """
    from dgse.errors import ConvergenceError
    from dgse.physics.scenario import random_cases
    from dgse.world.case import Case

    d = out / "_cases"
    d.mkdir(parents=True, exist_ok=True)
    cases = []
    for k in range(100):
        if len(cases) == n:
            break
        seed = 6000 + 100 * b + k
        path = d / f"size{lo:g}-{hi:g}_{seed}.npz"
        failed = path.with_suffix(".failed")
        if failed.exists():
            continue
        if not path.exists():
            t0 = time.perf_counter()
            try:
                case = random_cases(seed, n_sources=1, width_range=(lo, hi), height_range=(lo, hi))[0]
            except ConvergenceError as e:
                write_text(failed, str(e))
                print(f"  skipped seed {seed}: {e}")
                continue
            case.save(path)
            print(f"  solved {path.name}: {case.occupancy.shape} cells in {time.perf_counter() - t0:.0f} s")
        cases.append((path.stem, Case.load(path)))
    return cases


def floor_cases(n: int, resolution: float, size: tuple[float, float]) -> list[tuple[str, Any]]:
    """The first ``n`` office floors (:func:`dgse.bench.scenarios.office_floor_cases`, made once)."""
    from dgse.bench.scenarios import office_floor_cases
    from dgse.world.case import Case

    d = office_floor_cases(RESULTS / "building_search", n, resolution, size)
    return [(p.stem, Case.load(p)) for p in sorted(d.glob("building*_src0.npz"))[:n]]


def highest_reading_error(case: Any, obs: Any) -> float:
    """Distance from the source to the reading cell with the most gas, m."""
    i, j = obs.cells[int(np.argmax(obs.gas))]
    x, y = case.grid.center_of(int(i), int(j))
    return float(np.hypot(x - case.source[0], y - case.source[1]))


def size_error(argv: list[str]) -> None:
    """``size-error``: DGSE-S's error against the map size, per set of weights (module doc)."""
    from dgse.estimators.registry import get_estimator
    from dgse.evaluation.evaluate import draw_observations

    ap = _parser("size-error", "DGSE-S's source-localization error against map size, per set of weights")
    ap.add_argument("--model", nargs="+", default=["default"], help="DGSE-S weights: default or files")
    ap.add_argument("--cases", type=int, default=8, help="scenarios per size bin")
    ap.add_argument("--trials", type=int, default=4, help="reading sets per scenario")
    ap.add_argument("--readings", type=int, default=50)
    ap.add_argument("--bins", type=float, nargs="*", default=[v for b in BINS for v in b], metavar="LO HI")
    ap.add_argument("--floors", type=int, default=0, help="office floors (a bin of their own)")
    ap.add_argument("--floor-size", type=float, nargs=2, default=(20.0, 30.0), metavar=("MIN_M", "MAX_M"))
    ap.add_argument("--floor-resolution", type=float, default=0.2)
    ap.add_argument(
        "--dtype",
        default="auto",
        help="inference dtype: auto (bf16 where the CPU computes it natively), float32, bf16",
    )
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "size_error")
    ap.add_argument("--report-only", action="store_true", help="rewrite OUT's table and plot from its JSON")
    args = ap.parse_args(argv)
    if args.report_only:
        size_report(json.loads((args.out / "size_error.json").read_text()), args.out)
        return
    if len(args.bins) % 2:
        ap.error("--bins takes pairs LO HI")
    bins = list(zip(args.bins[::2], args.bins[1::2], strict=True))
    args.out.mkdir(parents=True, exist_ok=True)
    estimators = {
        m: get_estimator("dgse-s", model=m, seed=0, dtype=args.dtype, channels_last=True) for m in args.model
    }
    groups = [
        (f"{lo:g}-{hi:g}", lambda b=b, lo=lo, hi=hi: bin_cases(args.out, b, lo, hi, args.cases))
        for b, (lo, hi) in enumerate(bins)
    ]
    if args.floors:
        lo, hi = args.floor_size
        name = f"floors {lo:g}-{hi:g} ({args.floor_resolution:g} m cells)"
        groups.append((name, lambda: floor_cases(args.floors, args.floor_resolution, (lo, hi))))
    rows = []
    for label, make in groups:
        print(f"bin {label} m")
        for name, case in make():
            for t in range(args.trials):
                obs = draw_observations(case, args.readings, seed=0, case_id=name, trial=t)
                row = {
                    "bin": label,
                    "case": name,
                    "cells": list(case.occupancy.shape),
                    "resolution_m": case.resolution,
                    "trial": t,
                    "highest_reading": highest_reading_error(case, obs),
                }
                for m, est in estimators.items():
                    t0 = time.perf_counter()
                    belief = est.estimate(case.occupancy, case.resolution, obs)
                    row[m] = belief.localization_error(case.source)
                    row[f"{m}_s"] = time.perf_counter() - t0
                rows.append(row)
        print("  " + ", ".join(f"{k}: {_mean(rows, label, k):.2f} m" for k in _keys(args.model)), flush=True)
    summary = {label: {k: _mean(rows, label, k) for k in _keys(args.model)} for label, _ in groups}
    settings = {
        "readings": args.readings,
        "trials": args.trials,
        "cases_per_bin": args.cases,
        "bins": bins,
        "floors": args.floors,
        "floor_size_m": list(args.floor_size),
        "floor_resolution_m": args.floor_resolution,
        "dtype": args.dtype,
        "dtype_ran": str(next(iter(estimators.values())).dtype).removeprefix("torch."),
    }
    result = {"settings": settings, "models": args.model, "mean_error_m": summary, "rows": rows}
    size_report(result, args.out)


def size_report(result: dict, out: Path) -> None:
    """``OUT/size_error.{json,md,png}`` of one run's ``result`` (main's dictionary)."""
    models, settings, summary = result["models"], result["settings"], result["mean_error_m"]
    write_text(out / "size_error.json", json.dumps(result, indent=1))
    lines = [
        "# DGSE-S error against map size",
        "",
        f"`python benchmarks/training.py size-error --model {' '.join(models)}{_options(settings)}`: mean "
        "source-localization "
        f"error (m) from {settings['readings']} random readings, scenarios x trials per bin: "
        + ", ".join(f"{name} {_count(result['rows'], name)} x {settings['trials']}" for name in summary)
        + f"; inference in {settings.get('dtype_ran', 'bf16')}.",
        "",
        "| map side (m) | " + " | ".join(_model_label(k) for k in _keys(models)) + " |",
        "|---" * (len(models) + 2) + "|",
    ]
    for name, means in summary.items():
        lines.append(f"| {name} | " + " | ".join(f"{v:.2f}" for v in means.values()) + " |")
    times = [k for k in _keys(models)[:-1] if any(f"{k}_s" in r for r in result["rows"])]
    if times:
        lines += [
            "",
            "Seconds per estimate (mean): "
            + "; ".join(
                f"{name}: "
                + ", ".join(f"{_model_label(k)} {_mean(result['rows'], name, f'{k}_s'):.2f}" for k in times)
                for name in summary
                if all(f"{k}_s" in r for r in result["rows"] if r["bin"] == name for k in times)
            ),
        ]
    write_text(out / "size_error.md", "\n".join(lines) + "\n")
    _plot(summary, out / "size_error.png")
    print("\n".join(lines))
    print(f"wrote {out}/size_error.{{json,md,png}}")


def _options(settings: dict) -> str:
    """The command-line options of a run other than ``--model`` (where not the defaults)."""
    bins = [v for b in settings["bins"] for v in b]
    opts = "" if bins == [v for b in BINS for v in b] else " ".join([" --bins", *(f"{v:g}" for v in bins)])
    if settings.get("floors"):
        opts += f" --floors {settings['floors']}"
    return opts


def _count(rows: list[dict], name: str) -> int:
    """Scenarios in bin ``name``."""
    return len({r["case"] for r in rows if r["bin"] == name})


def _model_label(key: str) -> str:
    """A model's short name: ``default``, ``highest_reading`` or a weights file's stem."""
    return Path(key).stem


def _keys(models: list[str]) -> list[str]:
    return [*models, "highest_reading"]


def _mean(rows: list[dict], name: str, key: str) -> float:
    return float(np.mean([r[key] for r in rows if r["bin"] == name]))


def _plot(summary: dict[str, dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary)
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    for key in next(iter(summary.values())):
        ax.plot(names, [summary[n][key] for n in names], marker="o", label=_model_label(key))
    ax.set_xlabel("map side (m)")
    ax.set_ylabel("mean SL error (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)


def gdm(argv: list[str]) -> int:
    """``gdm``: the GDM baselines' free parameters tuned on the validation split (module doc)."""
    from dgse.bench.gdm_tuning import DEFAULT_GRIDS, MIN_GAIN, tune

    ap = _parser("gdm", "tune the free parameters of the GDM baselines on the validation split of a store")
    ap.add_argument("store", type=Path, help="dataset store (.h5); only its 'val' split is read")
    ap.add_argument("--out", type=Path, default=RESULTS / "gdm_tuning.json")
    ap.add_argument("--methods", nargs="+", default=list(DEFAULT_GRIDS), choices=list(DEFAULT_GRIDS))
    ap.add_argument("--observations", choices=("fixed", "random"), default="fixed")
    ap.add_argument("--configs-per-env", type=int, default=3)
    ap.add_argument("--counts", type=int, nargs="+", default=[50, 100, 150, 200, 250])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-cases", type=int, default=None)
    ap.add_argument("--criterion", choices=("rmse", "nll"), default="rmse")
    ap.add_argument(
        "--min-gain",
        type=float,
        default=MIN_GAIN,
        help="relative gain over the defaults that justifies replacing them (also needs > 50 %% wins)",
    )
    ap.add_argument(
        "--grid",
        type=Path,
        default=None,
        help="JSON {method: {param: [values]}} replacing the default grids of those methods",
    )
    args = ap.parse_args(argv)
    if not args.store.is_file():
        raise SystemExit(f"{args.store}: no such store file")
    grids = {k: dict(v) for k, v in DEFAULT_GRIDS.items()}
    if args.grid is not None:
        grids.update(json.loads(args.grid.read_text()))
    doc = tune(
        args.store,
        args.methods,
        grids,
        args.observations,
        args.configs_per_env,
        args.counts,
        args.seed,
        args.max_cases,
        args.criterion,
        log=print,
        min_gain=args.min_gain,
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


COMMANDS: dict[str, Callable[[list[str]], Any]] = {
    "throughput": throughput,
    "store-agreement": store_agreement,
    "curves": curves,
    "card": card,
    "eta": eta,
    "few-readings": few_readings,
    "latency": latency,
    "size-error": size_error,
    "gdm": gdm,
}


def main(argv: list[str] | None = None) -> int:
    run_command(__doc__, COMMANDS, sys.argv[1:] if argv is None else argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
