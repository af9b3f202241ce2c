"""Write the model card of a shipped DGSE model from its training run and evaluations.

    python benchmarks/model_card.py --weights src/dgse/assets/models/dgse-s.safetensors \\
        --run RUN_DIR --eval val=VAL.json --eval test=TEST.json --eval reference=REF.json \\
        --command "dgse train ..." -o src/dgse/assets/models/dgse-s.md

Everything in the card comes from files: the checkpoint's metadata (variant,
configuration, training metadata), the run's ``history.csv`` (epochs, time,
validation curve) and ``dgse evaluate`` JSON files (aggregate metrics). Files and folders
are named by their own name only (the dataset ``dgse1000.h5``, not where it lay on the
machine that trained the model), so a card holds no machine's paths.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
from pathlib import Path

from dgse.files import write_text
from dgse.models.checkpoint import load_model, read_checkpoint_info
from dgse.models.networks import count_parameters


def _name(path: object) -> str:
    """A file or folder by its own name, without the folders it lay in (``?`` when unknown)."""
    return (Path(str(path)).name or "?") if path else "?"


def _row(agg: dict, n: str) -> str:
    a = agg[n]

    def f(key: str, fmt: str = ".3f") -> str:
        v = a.get(key)
        return "n/a" if v is None else format(v, fmt)

    return (
        f"| {n} | {f('sl_error_m_mean', '.2f')} | {f('sl_error_m_median', '.2f')} | {f('ce_mean', '.2f')} | "
        f"{f('wf_rmse_mean')} | {f('cf_rmse_mean')} | {f('seconds_per_estimate_median')} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", required=True, type=Path)
    ap.add_argument("--run", required=True, type=Path, help="training run directory (history.csv)")
    ap.add_argument("--eval", action="append", default=[], help="NAME=evaluation.json (repeatable)")
    ap.add_argument("--command", default="", help="the training command(s), for the card")
    ap.add_argument("-o", "--out", required=True, type=Path)
    args = ap.parse_args()

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
        lines += [_row(ev["aggregate"], n) for n in ev["aggregate"]]
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


if __name__ == "__main__":
    main()
