"""DGSE-S's source-localization error against map size, per set of weights (issue 14).

Scenarios: random multi-room layouts of the training generator
(:func:`dgse.physics.scenario.random_cases`) whose sides are drawn from each
size bin (``--bins``, m, at 0.1 m cells), the first ``--cases`` per bin whose flow
converges, seeds 6000 + 100 * bin + k (no dataset or tuning run uses them), made once into
``OUT/_cases/``.  Per scenario and trial, ``--readings`` random readings with
Table I noise (:func:`dgse.evaluation.evaluate.draw_observations`); the error
of each model (``--model``: ``default`` for the shipped DGSE-S, or a weights
file, e.g. a fine-tuned one) and of the guess "the source is at the highest
reading", from the same readings.  ``--floors N`` adds the first ``N`` office floors of
``benchmarks/building_search.py`` (20-30 m, 0.2 m cells, made once into its ``_cases_0.2m/``):
the networks, trained on 0.1 m cells, see each floor cell as 2 x 2 of theirs
(:class:`dgse.estimators.dgse.DGSEEstimator`'s refinement).

    python benchmarks/size_error.py --model default benchmarks/results/size_error/dgse-s-sizes.safetensors
    python benchmarks/size_error.py --bins --floors 10 -o benchmarks/results/size_error_floors

writes ``OUT/size_error.json``, ``OUT/size_error.md`` and ``OUT/size_error.png``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from dgse.errors import ConvergenceError
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.files import atomic_path, write_text
from dgse.physics.scenario import random_cases
from dgse.world.case import Case

BINS = [(5.0, 10.0), (10.0, 15.0), (15.0, 20.0)]


def bin_cases(out: Path, b: int, lo: float, hi: float, n: int) -> list[tuple[str, Case]]:
    """The first ``n`` scenarios of size bin ``b`` (sides in ``[lo, hi]`` m) whose flow converges.

    Seeds ``6000 + 100 b + k`` in order; each is solved once and kept (a seed whose flow
    does not converge is marked ``.failed`` and skipped, as ``dgse generate`` skips it).
    """
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


def floor_cases(n: int, resolution: float, size: tuple[float, float]) -> list[tuple[str, Case]]:
    """The first ``n`` office floors of ``building_search.py`` (made once, into its own folder)."""
    from building_search import make_cases

    d = make_cases(Path("benchmarks/results/building_search"), n, resolution, size)
    return [(p.stem, Case.load(p)) for p in sorted(d.glob("building*_src0.npz"))[:n]]


def highest_reading_error(case: Case, obs) -> float:
    """Distance from the source to the reading cell with the most gas, m."""
    i, j = obs.cells[int(np.argmax(obs.gas))]
    x, y = case.grid.center_of(int(i), int(j))
    return float(np.hypot(x - case.source[0], y - case.source[1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", nargs="+", default=["default"], help="DGSE-S weights: default or files")
    ap.add_argument("--cases", type=int, default=8, help="scenarios per size bin")
    ap.add_argument("--trials", type=int, default=4, help="reading sets per scenario")
    ap.add_argument("--readings", type=int, default=50)
    ap.add_argument("--bins", type=float, nargs="*", default=[v for b in BINS for v in b], metavar="LO HI")
    ap.add_argument("--floors", type=int, default=0, help="office floors of building_search.py (a bin)")
    ap.add_argument("--floor-size", type=float, nargs=2, default=(20.0, 30.0), metavar=("MIN_M", "MAX_M"))
    ap.add_argument("--floor-resolution", type=float, default=0.2)
    ap.add_argument(
        "--dtype",
        default="auto",
        help="inference dtype: auto (bf16 where the CPU computes it natively), float32, bf16",
    )
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/size_error"))
    ap.add_argument("--report-only", action="store_true", help="rewrite OUT's table and plot from its JSON")
    args = ap.parse_args()
    if args.report_only:
        write_report(json.loads((args.out / "size_error.json").read_text()), args.out)
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
    write_report(result, args.out)


def write_report(result: dict, out: Path) -> None:
    """``OUT/size_error.{json,md,png}`` of one run's ``result`` (main's dictionary)."""
    models, settings, summary = result["models"], result["settings"], result["mean_error_m"]
    write_text(out / "size_error.json", json.dumps(result, indent=1))
    lines = [
        "# DGSE-S error against map size",
        "",
        f"`python benchmarks/size_error.py --model {' '.join(models)}{_options(settings)}`: mean "
        "source-localization "
        f"error (m) from {settings['readings']} random readings, scenarios x trials per bin: "
        + ", ".join(f"{name} {_count(result['rows'], name)} x {settings['trials']}" for name in summary)
        + f"; inference in {settings.get('dtype_ran', 'bf16')}.",
        "",
        "| map side (m) | " + " | ".join(_label(k) for k in _keys(models)) + " |",
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
                + ", ".join(f"{_label(k)} {_mean(result['rows'], name, f'{k}_s'):.2f}" for k in times)
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


def _label(key: str) -> str:
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
        ax.plot(names, [summary[n][key] for n in names], marker="o", label=_label(key))
    ax.set_xlabel("map side (m)")
    ax.set_ylabel("mean SL error (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)


if __name__ == "__main__":
    main()
