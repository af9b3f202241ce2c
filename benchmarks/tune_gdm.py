"""Tune the free parameters of the GDM baselines on the VALIDATION split of a dataset store.

Grid search, one method at a time, over a few parameters each (defaults below,
``--grid`` to replace them): the kernel width (and wind stretch) of Kernel
DM+V(/W), the smoothness (and observation) sigma of the GMRFs, GaBP+'s
smoothness precision.  Every parameter not searched keeps its published value.
Each setting maps every validation sample; the chosen setting minimizes the
mean concentration RMSE in ppm over the free cells (``--criterion nll``: the
mean Gaussian NLL in ppm, for the methods whose variance is a predictive one,
G-GMRF and GW-GMRF; the others always use RMSE).

Samples: every case of the ``val`` split (``--max-cases`` to limit) with the
store's fixed validation sensor configurations (``--observations fixed``, the
first ``--configs-per-env`` per environment, noise as
:class:`dgse.data.torch_dataset.FixedSet` draws it) or seeded random ones
(``--observations random``: ``--counts`` sensors per sample, Table I noise,
seeded by ``--seed`` and the case's position in the split).  The test split
and the reference cases are never read: they are for honest evaluation.

    python benchmarks/tune_gdm.py data/store.h5                        # all methods
    python benchmarks/tune_gdm.py data/store.h5 --methods ggmrf --max-cases 50

Writes ``benchmarks/results/gdm_tuning.json`` (``--out``): ``methods`` holds the
chosen values per method (what ``tuning=`` of the estimators reads), ``search``
every setting's scores.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import itertools
import json
import math
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "benchmarks" / "results" / "gdm_tuning.json"
SPLIT = "val"

#: Default search grids: method -> parameter -> values (published value included).
DEFAULT_GRIDS: dict[str, dict[str, list[Any]]] = {
    "kdmv": {"sigma": [0.1, 0.2, 0.38, 0.6, 1.0]},
    "kdmvw": {"sigma": [0.1, 0.2, 0.38, 0.6, 1.0], "gamma": [0.1, 0.33, 1.0]},
    "ggmrf": {"sigma_r": [0.1, 0.3, 1.128, 3.0, 10.0], "sigma_z": [0.03, 0.1, 0.3]},
    "gwgmrf": {"sigma_r": [0.3, 1.128, 3.0]},
    "gabp": {"lambda_p": [0.05, 0.5, 5.0]},
}
#: Methods whose variance is a predictive one (the paper's NLL comparison).
NLL_METHODS = ("ggmrf", "gwgmrf")


def _samples(
    store_path: Path, mode: str, configs_per_env: int, counts: Sequence[int], seed: int, max_cases: int | None
) -> Iterator[tuple[str, Any, Any]]:
    """``(label, case, observations)`` for every validation sample."""
    from dgse.data.store import DatasetStore
    from dgse.sensing.noise import NoiseModel
    from dgse.sensing.sensors import measure, random_observations

    noise = NoiseModel()
    with DatasetStore(store_path, "r") as s:
        entries = list(s.iter_cases(SPLIT))
        fixed = s.fixed_configurations(SPLIT) if mode == "fixed" else None
    if not entries:
        raise SystemExit(f"{store_path}: no cases in split {SPLIT!r}")
    if max_cases is not None:
        entries = entries[:max_cases]
    for e, (layout_id, k, case) in enumerate(entries):
        if fixed is not None:
            for c, cfg in enumerate(fixed.for_env(layout_id, k)[:configs_per_env]):
                rng = cfg.rng()
                params = noise.draw(rng, float(case.concentration[case.free].mean()))
                yield f"{layout_id}/{k}/fixed{c}", case, measure(case, cfg.cells, params, rng)
        else:
            for n in counts:
                rng = np.random.default_rng(np.random.SeedSequence([seed, e, int(n)]))
                n_eff = min(int(n), int(case.free.sum()))
                yield f"{layout_id}/{k}/random{n}", case, random_observations(case, n_eff, rng, noise)


def _scores(gm: Any, case: Any) -> tuple[float, float]:
    """RMSE (ppm) and mean Gaussian NLL (ppm) over the free cells."""
    free = case.free
    truth = case.concentration[free].astype(np.float64)
    mean = gm.mean_ppm[free]
    rmse = float(np.sqrt(np.mean((mean - truth) ** 2)))
    nll = float("nan")
    if gm.var_ppm is not None:
        var = np.maximum(gm.var_ppm[free], 1e-9)
        nll = float(np.mean(0.5 * np.log(2 * math.pi * var) + (truth - mean) ** 2 / (2 * var)))
    return rmse, nll


def _settings(grid: dict[str, list[Any]]) -> list[dict[str, Any]]:
    names = list(grid)
    return [dict(zip(names, vals, strict=True)) for vals in itertools.product(*(grid[n] for n in names))]


def tune(
    store_path: Path,
    methods: Sequence[str],
    grids: dict[str, dict[str, list[Any]]],
    mode: str = "fixed",
    configs_per_env: int = 3,
    counts: Sequence[int] = (50, 100, 150, 200, 250),
    seed: int = 0,
    max_cases: int | None = None,
    criterion: str = "rmse",
    log: Any = print,
) -> dict[str, Any]:
    """Run the grid search; returns the tuning document (see the module docstring)."""
    from dgse.mapping import TUNING_FORMAT
    from dgse.mapping.register import GDM_ESTIMATORS

    unknown = sorted(set(methods) - set(GDM_ESTIMATORS))
    if unknown:
        raise SystemExit(f"unknown method(s) {unknown}; known: {sorted(GDM_ESTIMATORS)}")
    samples = list(_samples(store_path, mode, configs_per_env, counts, seed, max_cases))
    log(f"{len(samples)} validation samples from {store_path}")
    chosen: dict[str, dict[str, Any]] = {}
    search: dict[str, list[dict[str, Any]]] = {}
    for method in methods:
        module, _, cls_name = GDM_ESTIMATORS[method].partition(":")
        cls = getattr(__import__(module, fromlist=[cls_name]), cls_name)
        rows: list[dict[str, Any]] = []
        for setting in _settings(grids[method]):
            est = cls(**setting)
            rmses, nlls, secs = [], [], []
            for _, case, obs in samples:
                t0 = time.perf_counter()
                gm = est.map(case.occupancy, case.resolution, obs)
                secs.append(time.perf_counter() - t0)
                r, n = _scores(gm, case)
                rmses.append(r)
                nlls.append(n)
            row: dict[str, Any] = {
                "params": setting,
                "rmse": float(np.mean(rmses)),
                "nll": float(np.mean(nlls)) if method in NLL_METHODS else None,
                "seconds_per_estimate": float(np.mean(secs)),
            }
            rows.append(row)
            log(
                f"  {method} {setting}: rmse {row['rmse']:.4g} nll {row['nll']} "
                f"({row['seconds_per_estimate']:.3f} s)"
            )
        key = "nll" if criterion == "nll" and method in NLL_METHODS else "rmse"
        finite = [r for r in rows if r[key] is not None and math.isfinite(r[key])]
        if not finite:
            raise SystemExit(f"{method}: no setting gave a finite {key}")
        best = min(finite, key=lambda r: r[key])
        chosen[method] = dict(best["params"])
        search[method] = rows
        log(f"{method}: chose {best['params']} ({key} {best[key]:.4g})")
    return {
        "format": TUNING_FORMAT,
        "version": 1,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "store": str(store_path),
        "split": SPLIT,
        "observations": {
            "mode": mode,
            "configs_per_env": configs_per_env,
            "counts": list(counts),
            "seed": seed,
        },
        "n_samples": len(samples),
        "criterion": criterion,
        "methods": chosen,
        "search": search,
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store", type=Path, help="dataset store (.h5); only its 'val' split is read")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--methods", nargs="+", default=list(DEFAULT_GRIDS), choices=list(DEFAULT_GRIDS))
    ap.add_argument("--observations", choices=("fixed", "random"), default="fixed")
    ap.add_argument("--configs-per-env", type=int, default=3)
    ap.add_argument("--counts", type=int, nargs="+", default=[50, 100, 150, 200, 250])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-cases", type=int, default=None)
    ap.add_argument("--criterion", choices=("rmse", "nll"), default="rmse")
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
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_name(args.out.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    tmp.replace(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
