"""Validation curves of the DGSE variants against the epoch (like the paper's fig4).

    python benchmarks/training_curves.py \\
        dgse-o=benchmarks/results/dgse-o-small_history.csv \\
        dgse-p=benchmarks/results/dgse-p-small_history.csv \\
        dgse-s=benchmarks/results/dgse-s-small_history.csv \\
        -o benchmarks/results/training_curves.png

Reads the ``history.csv`` files ``dgse train`` writes (one row per epoch,
also for epochs cut short by a time budget) and plots the training and
validation source loss and the validation localization error against the
optimizer steps taken (batches of the same size), so variants are compared
at an equal training budget even when their epochs held different numbers
of steps (the shipped DGSE-S's first 18 epochs were smaller) or their runs
reached different lengths.  Also writes a CSV of the plotted values next to
the figure.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from dgse.bench.plots import style_of
from dgse.files import atomic_open, atomic_path


def _read(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="NAME=history.csv")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()
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


if __name__ == "__main__":
    main()
