"""Tuning of the GDM baselines' free parameters on the validation split of a dataset store.

:func:`tune` runs a grid search, one method at a time, over a few parameters each
(:data:`DEFAULT_GRIDS`): the kernel width (and wind stretch) of Kernel DM+V(/W), the smoothness
(and observation) sigma of the GMRFs, GaBP+'s smoothness precision.  Every parameter not
searched keeps its published value.  Each setting maps every validation sample; the chosen
setting minimizes the mean concentration RMSE in ppm over the free cells (``criterion="nll"``:
the mean Gaussian NLL in ppm, for the methods whose variance is a predictive one, G-GMRF and
GW-GMRF; the others always use RMSE).

Samples: every case of the ``val`` split (``max_cases`` to limit) with the store's fixed
validation sensor configurations (``mode="fixed"``, the first ``configs_per_env`` per
environment, noise as :class:`dgse.data.torch_dataset.FixedSet` draws it) or seeded random
ones (``mode="random"``: ``counts`` sensors per sample, Table I noise, seeded by ``seed`` and
the case's position in the split).  The test split and the reference cases are never read.

Every method's published defaults (its parameter class's values of the searched parameters)
are scored on the same samples.  A setting replaces them only when the change is justified on
the validation samples: its mean score is at least ``min_gain`` (default 5 %) better than the
defaults' AND it beats the defaults on more than half of the samples (paired, same readings).
Otherwise the defaults are kept.

The returned document (``benchmarks/results/gdm_tuning.json``, written by ``python
benchmarks/training.py gdm STORE``): ``methods`` holds the chosen values per method (what
``tuning=`` of the estimators reads, :func:`dgse.mapping.load_tuning`: the best setting where
justified, else the published defaults), ``best`` the best setting per method whether
justified or not, ``decision`` per method the default's and the best setting's scores, the
relative gain, the paired win fraction and whether the defaults were replaced, and ``search``
every setting's scores.
"""

from __future__ import annotations

import datetime as _dt
import itertools
import math
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dgse.errors import InputDataError

__all__ = ["DEFAULT_GRIDS", "MIN_GAIN", "NLL_METHODS", "SPLIT", "tune"]

#: The only split the tuning reads.
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
#: Smallest relative improvement of the mean score over the defaults that justifies a change.
MIN_GAIN = 0.05


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
        raise InputDataError(f"{store_path}: no cases in split {SPLIT!r}")
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


def _default_setting(cls: Any, names: Sequence[str]) -> dict[str, Any]:
    """The published defaults of the searched parameters (the estimator's parameter class)."""
    params = cls().params
    return {n: getattr(params, n) for n in names}


def _same(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return a.keys() == b.keys() and all(
        math.isclose(float(a[k]), float(b[k]), rel_tol=1e-9)
        if isinstance(a[k], (int, float)) and isinstance(b[k], (int, float))
        else a[k] == b[k]
        for k in a
    )


def _decide(default: dict[str, Any], best: dict[str, Any], key: str, min_gain: float) -> dict[str, Any]:
    """Whether ``best`` justifiably replaces ``default`` (module docstring)."""
    d = np.asarray(default[f"per_sample_{key}"], dtype=float)
    b = np.asarray(best[f"per_sample_{key}"], dtype=float)
    ok = np.isfinite(d) & np.isfinite(b)
    d_mean, b_mean = float(default[key]), float(best[key])
    # relative gain of a lower-is-better score (NLL can be negative: relative to |default|)
    gain = (d_mean - b_mean) / abs(d_mean) if d_mean != 0 else 0.0
    wins = float(np.mean(b[ok] < d[ok])) if ok.any() else 0.0
    same = _same(default["params"], best["params"])
    replace = (not same) and gain >= min_gain and wins > 0.5
    return {
        "criterion": key,
        "default_params": default["params"],
        "default_score": d_mean,
        "best_params": best["params"],
        "best_score": b_mean,
        "relative_gain": gain,
        "win_fraction": wins,
        "min_gain": min_gain,
        "replace_defaults": bool(replace),
    }


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
    log: Callable[[str], None] = lambda _: None,
    min_gain: float = MIN_GAIN,
) -> dict[str, Any]:
    """Run the grid search; returns the tuning document (module doc).  ``log`` is told each
    setting's scores and each method's decision as they are made."""
    from dgse.estimators.registry import ESTIMATORS
    from dgse.mapping import TUNING_FORMAT

    GDM_ESTIMATORS = ESTIMATORS.names(tag="gdm")

    unknown = sorted(set(methods) - set(GDM_ESTIMATORS))
    if unknown:
        raise InputDataError(f"unknown method(s) {unknown}; known: {sorted(GDM_ESTIMATORS)}")
    samples = list(_samples(store_path, mode, configs_per_env, counts, seed, max_cases))
    log(f"{len(samples)} validation samples from {store_path}")
    chosen: dict[str, dict[str, Any]] = {}
    bests: dict[str, dict[str, Any]] = {}
    decisions: dict[str, dict[str, Any]] = {}
    search: dict[str, list[dict[str, Any]]] = {}
    for method in methods:
        cls = ESTIMATORS.factory(method)
        settings = _settings(grids[method])
        default = _default_setting(cls, list(grids[method]))
        if not any(_same(default, st) for st in settings):
            settings.append(default)
        rows: list[dict[str, Any]] = []
        for setting in settings:
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
                "default": _same(setting, default),
                "rmse": float(np.mean(rmses)),
                "nll": float(np.mean(nlls)) if method in NLL_METHODS else None,
                "seconds_per_estimate": float(np.mean(secs)),
                "per_sample_rmse": rmses,
                "per_sample_nll": nlls if method in NLL_METHODS else None,
            }
            rows.append(row)
            log(
                f"  {method} {setting}{' (default)' if row['default'] else ''}: rmse {row['rmse']:.4g} "
                f"nll {row['nll']} ({row['seconds_per_estimate']:.3f} s)"
            )
        key = "nll" if criterion == "nll" and method in NLL_METHODS else "rmse"
        finite = [r for r in rows if r[key] is not None and math.isfinite(r[key])]
        if not finite:
            raise InputDataError(f"{method}: no setting gave a finite {key}")
        best = min(finite, key=lambda r: r[key])
        default_row = next(r for r in rows if r["default"])
        decision = _decide(default_row, best, key, min_gain)
        bests[method] = dict(best["params"])
        decisions[method] = decision
        chosen[method] = dict(best["params"] if decision["replace_defaults"] else default_row["params"])
        search[method] = rows
        log(
            f"{method}: best {best['params']} ({key} {best[key]:.4g}), defaults {default_row['params']} "
            f"({key} {default_row[key]:.4g}): gain {decision['relative_gain']:+.1%}, wins "
            f"{decision['win_fraction']:.0%} -> "
            + ("REPLACE the defaults" if decision["replace_defaults"] else "keep the defaults")
        )
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
        "min_gain": min_gain,
        "methods": chosen,
        "best": bests,
        "decision": decisions,
        "search": search,
    }
