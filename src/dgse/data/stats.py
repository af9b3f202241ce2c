"""Statistics of a dataset store, and their figure.

:func:`dataset_stats` computes from the per-layout summaries the store keeps in
its attributes, about a second for the paper's 3,750 layouts; with
``verify=True`` it first reads every array
(:meth:`~dgse.data.store.DatasetStore.verify`), so that the statistics of a
damaged file are never reported as healthy.  :func:`plot_stats` draws
histograms of the result on a :class:`matplotlib.figure.Figure` that needs no
display (save it with ``fig.savefig``; the Agg canvas is attached).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dgse.data.store import SPLITS, DatasetStore

__all__ = ["dataset_stats", "plot_stats", "summarize"]


def summarize(values: Sequence[float | None]) -> dict[str, float | int]:
    """``count, min, max, mean, std, p05, median, p95`` of the finite values (NaN if none)."""
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        nan = float("nan")
        return {
            "count": 0,
            "min": nan,
            "max": nan,
            "mean": nan,
            "std": nan,
            "p05": nan,
            "median": nan,
            "p95": nan,
        }
    p05, med, p95 = np.percentile(v, [5, 50, 95])
    return {
        "count": int(v.size),
        "min": float(v.min()),
        "max": float(v.max()),
        "mean": float(v.mean()),
        "std": float(v.std()),
        "p05": float(p05),
        "median": float(med),
        "p95": float(p95),
    }


def _failure_kind(rec: dict[str, Any]) -> str:
    return str(rec.get("error") or "unknown")


def dataset_stats(store: DatasetStore | str | Path, verify: bool = False) -> dict[str, Any]:
    """Distributions of a dataset: layout sizes, inlet speeds, release rates, concentrations.

    Args:
        store: an open store or the path of one.
        verify: read and check every array first (:meth:`DatasetStore.verify`).

    Returns:
        A JSON-able dict:

            * ``n_layouts``, ``n_cases``;
            * ``splits``: ``{split: {"layouts": n, "cases": n}}``;
            * ``failures``: ``{"count": n, "by_error": {error type: n}}``;
            * ``width_m``, ``height_m``, ``cells`` (H x W), ``free_fraction``,
              ``inlet_velocity`` (m/s), ``max_speed`` (m/s, per layout),
              ``release_rate_gps``, ``max_ppm``, ``mean_ppm`` (per case, over free
              cells): each a :func:`summarize` dict;
            * ``values``: the raw per-layout and per-case lists behind them (for plots).

    Raises:
        InputDataError: a missing or damaged store (``verify`` finds what the summaries hide).
    """
    if not isinstance(store, DatasetStore):
        with DatasetStore(store, "r") as s:
            return dataset_stats(s, verify)
    if verify:
        store.verify()
    per_layout: dict[str, list[float | None]] = {
        k: [] for k in ("width_m", "height_m", "cells", "free_fraction", "inlet_velocity", "max_speed")
    }
    per_case: dict[str, list[float | None]] = {k: [] for k in ("release_rate_gps", "max_ppm", "mean_ppm")}
    splits = {s: {"layouts": 0, "cases": 0} for s in SPLITS}
    n_cases = 0
    layout_ids = store.layouts()
    for lid in layout_ids:
        info = store.layout_info(lid)
        summ = info["summary"]
        splits[info["split"]]["layouts"] += 1
        splits[info["split"]]["cases"] += info["n_sources"]
        n_cases += info["n_sources"]
        H, W = summ["shape"]
        per_layout["width_m"].append(summ["width_m"])
        per_layout["height_m"].append(summ["height_m"])
        per_layout["cells"].append(float(H * W))
        per_layout["free_fraction"].append(summ["free_fraction"])
        per_layout["inlet_velocity"].append(summ.get("inlet_velocity"))
        per_layout["max_speed"].append(summ.get("max_speed"))
        for src in summ["sources"]:
            per_case["release_rate_gps"].append(src.get("release_rate_gps"))
            per_case["max_ppm"].append(src.get("max_ppm"))
            per_case["mean_ppm"].append(src.get("mean_ppm"))
    failures = store.failures()
    out: dict[str, Any] = {
        "path": str(store.path),
        "n_layouts": len(layout_ids),
        "n_cases": n_cases,
        "splits": splits,
        "failures": {
            "count": len(failures),
            "by_error": dict(Counter(_failure_kind(r) for r in failures)),
        },
    }
    for k, v in {**per_layout, **per_case}.items():
        out[k] = summarize(v)
    out["values"] = {
        k: [None if x is None else float(x) for x in v] for k, v in {**per_layout, **per_case}.items()
    }
    return out


def plot_stats(stats: dict[str, Any]):
    """Histograms of :func:`dataset_stats`: sizes, free fraction, speeds, rates, concentrations.

    Returns a :class:`matplotlib.figure.Figure` (Agg canvas; no display needed).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 4)
    vals = stats.get("values", {})

    def hist(ax, key: str, label: str, log: bool = False) -> None:
        v = np.array([x for x in vals.get(key, []) if x is not None], dtype=np.float64)
        if log:
            v = v[v > 0]
        if v.size == 0:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        elif log:
            lo, hi = v.min(), v.max()
            bins = np.geomspace(lo, hi if hi > lo else lo * 10, 30)
            ax.hist(v, bins=bins, color="tab:blue", alpha=0.8)
            ax.set_xscale("log")
        else:
            ax.hist(v, bins=30, color="tab:blue", alpha=0.8)
        ax.set_xlabel(label)
        ax.set_ylabel("count")

    ax = axes[0, 0]
    w = [x for x in vals.get("width_m", []) if x is not None]
    h = [x for x in vals.get("height_m", []) if x is not None]
    if w:
        ax.hist([w, h], bins=20, label=["width", "height"], color=["tab:blue", "tab:orange"])
        ax.legend()
    ax.set_xlabel("domain side [m]")
    ax.set_ylabel("count")
    hist(axes[0, 1], "free_fraction", "free fraction")
    hist(axes[0, 2], "inlet_velocity", "inlet velocity [m/s]")
    hist(axes[0, 3], "max_speed", "max wind speed [m/s]")
    hist(axes[1, 0], "release_rate_gps", "release rate [g/s]")
    hist(axes[1, 1], "max_ppm", "max concentration [ppm]", log=True)
    hist(axes[1, 2], "mean_ppm", "mean concentration [ppm]", log=True)
    ax = axes[1, 3]
    names = [*SPLITS, "failed"]
    counts = [*(stats["splits"][s]["layouts"] for s in SPLITS), stats["failures"]["count"]]
    bars = ax.bar(names, counts, color=["tab:blue", "tab:orange", "tab:green", "tab:red"])
    ax.bar_label(bars)
    ax.set_ylabel("layouts")
    fig.suptitle(
        f"{Path(str(stats.get('path', 'dataset'))).name}: {stats['n_layouts']} layouts, "
        f"{stats['n_cases']} cases, {stats['failures']['count']} failures"
    )
    return fig
