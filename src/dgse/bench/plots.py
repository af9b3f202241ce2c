"""Figure helpers shared by the suites (matplotlib, headless)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure

__all__ = ["curves_vs_observations", "seconds_bars", "style_of"]


def style_of(method: str) -> dict[str, Any]:
    """Colour, marker and label of ``method`` in every figure (its registry entry,
    :data:`dgse.estimators.registry.ESTIMATORS`; a grey cross for names it does not know)."""
    from dgse.estimators.registry import ESTIMATORS

    if method not in ESTIMATORS:
        return {"color": None, "marker": "x", "label": method}
    e = ESTIMATORS.entry(method)
    return {"color": e.color, "marker": e.marker, "label": e.display}


def curves_vs_observations(
    results: Mapping[str, Mapping[str, Any]],
    panels: Sequence[tuple[str, str]],
    ncols: int = 3,
    title: str | None = None,
) -> Figure:
    """One panel per metric: its mean against the observation count, one line per method.

    Args:
        results: method name -> :func:`dgse.evaluation.evaluate` result.
        panels: ``(metric key, axis label)``; the key's ``_mean`` and ``_std`` and
            ``_count`` statistics of ``aggregate`` are plotted (band: standard error).
        ncols: panels per row.
    """
    n = len(panels)
    nrows = (n + ncols - 1) // ncols
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.2 * nrows), squeeze=False)
    for ax, (key, label) in zip(axes.flat, panels, strict=False):
        for method, res in results.items():
            agg = res["aggregate"]
            counts = sorted(int(k) for k in agg)
            xs, ys, es = [], [], []
            for c in counts:
                a = agg[str(c)]
                m, s, k = a.get(f"{key}_mean"), a.get(f"{key}_std"), a.get(f"{key}_count") or 0
                if m is None:
                    continue
                xs.append(c)
                ys.append(m)
                es.append((s or 0.0) / max(k, 1) ** 0.5)
            if not xs:
                continue
            st = style_of(method)
            ax.plot(xs, ys, marker=st["marker"], color=st["color"], label=st["label"], ms=4)
            lo = [y - e for y, e in zip(ys, es, strict=True)]
            hi = [y + e for y, e in zip(ys, es, strict=True)]
            ax.fill_between(xs, lo, hi, color=st["color"], alpha=0.15, lw=0)
        ax.set_xlabel("observations")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    seen: dict[str, Any] = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            seen.setdefault(lab, h)
    handles, labels = list(seen.values()), list(seen)
    if handles:
        fig.legend(handles, labels, loc="upper center", ncol=len(handles), frameon=False)
    if title:
        fig.suptitle(title, y=1.04)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    return fig


def seconds_bars(
    methods: Sequence[str],
    seconds: Sequence[float],
    upper: Sequence[float] | None = None,
    hatched: Sequence[bool] | None = None,
    figsize: tuple[float, float] = (5.2, 3.2),
) -> Figure:
    """Bars of the median seconds per estimate of each method, log scale, values written on top.

    Args:
        methods: method names (labels and colours from :func:`style_of`).
        seconds: the bar heights.
        upper: optional upper whiskers (added to the bar height, e.g. p90 - median).
        hatched: which bars to hatch (e.g. oracles).
    """
    fig, ax = plt.subplots(figsize=figsize)
    labels = [style_of(m)["label"].replace(" (", "\n(") for m in methods]
    colors = [style_of(m)["color"] for m in methods]
    yerr = None if upper is None else [[0.0] * len(methods), list(upper)]
    bars = ax.bar(labels, seconds, color=colors, yerr=yerr, capsize=3)
    for k, (b, v) in enumerate(zip(bars, seconds, strict=True)):
        if hatched is not None and hatched[k]:
            b.set_hatch("//")
            b.set_edgecolor("k")
        ax.text(b.get_x() + b.get_width() / 2, v, f"{v:.3g} s", ha="center", va="bottom", fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("seconds per estimate (median)")
    ax.grid(axis="y", alpha=0.3)
    ax.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    return fig
