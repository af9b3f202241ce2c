"""How much of DGSE-S's source belief to keep in dgse-phys's, by level and count: validation only.

dgse-phys mixes the network's source posterior into its own at ``map`` with weight
``max(learned_floor, 0.9 (1 - m / 50))`` for ``m`` readings (``learned_weight``,
``learned_readings``, ``learned_floor``; none at the other levels).  A floor above 0
keeps a little of the network from 50 readings on, which bounds how sure of a wrong
spot the physics can be (the source CE) at some cost in sharpness.  This benchmark
records, for every estimate of the validation scenarios (seeds 900-923 by default,
steady and filament readings), the physics' posterior alone and the network's, so
that any weight can be scored without estimating again::

    python benchmarks/tune_phys_fusion.py --knowledge openings --counts 20 50 150 --trials 5
    python benchmarks/tune_phys_fusion.py --knowledge map --counts 50 150 --trials 2

Each journal line (``OUT/journal-LEVEL.jsonl``) holds, per weight of :data:`WEIGHTS`,
the SL error of the mixture's mean, its CE and the truth's credible level; an
interrupted run resumes.  ``--summary-only`` rewrites ``OUT/summary.json`` and
``OUT/summary.md`` from the journals: calibration error / mean SL error / mean CE per
level, variant, count and weight.  The test split is never read here.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from phys_robustness import parse_seeds, variant_case

from dgse.cli.common import parse_params
from dgse.errors import InputDataError
from dgse.estimators.knowledge import Knowledge
from dgse.estimators.registry import get_estimator
from dgse.evaluation.calibration import (
    calibration_error,
    chance_calibration_error,
    coverage_curve,
    credible_level,
)
from dgse.evaluation.evaluate import draw_observations
from dgse.evaluation.metrics import PROB_FLOOR
from dgse.world.case import Case

#: The network's weights in the mixture ``(1 - w) physics + w network`` that are scored.
WEIGHTS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)


def scores(p: np.ndarray, case: Case) -> dict[str, float]:
    """SL error of ``p``'s mean position (m), CE of the true cell (nats), the truth's credible level."""
    H, W = p.shape
    ii, jj = np.mgrid[:H, :W]
    x = float(((jj + 0.5) * case.resolution * p).sum())
    y = float(((ii + 0.5) * case.resolution * p).sum())
    sx, sy = case.source
    i, j = case.source_cell
    return {
        "sl_m": math.hypot(x - sx, y - sy),
        "ce": -math.log(max(float(p[i, j]), PROB_FLOOR)),
        "credible_level": credible_level(p, case.source_cell),
    }


def write_summary(out: Path) -> None:
    groups: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
    for path in sorted(out.glob("journal-*.jsonl")):
        for line in path.read_text().splitlines():
            r = json.loads(line)
            groups.setdefault((r["knowledge"], r["variant"], r["n"]), []).append(r)
    summary: dict[str, Any] = {"weights": list(WEIGHTS), "cells": []}
    lines = [
        "# DGSE-S's weight in dgse-phys's source posterior (validation scenarios)",
        "",
        "`python benchmarks/tune_phys_fusion.py` (module doc): calibration error / mean SL error (m) / "
        "mean CE (nats) of `(1 - w) physics + w network`; the last column is the chance calibration error.",
        "",
        "| level | variant | n | estimates | " + " | ".join(f"w {w:g}" for w in WEIGHTS) + " | chance |",
        "|---|---|---|---|" + "---|" * len(WEIGHTS) + "---|",
    ]
    for (level, variant, n), rr in sorted(groups.items()):
        cell: dict[str, Any] = {"knowledge": level, "variant": variant, "n": n, "estimates": len(rr)}
        texts = []
        for w in WEIGHTS:
            got = [r["by_weight"][f"{w:g}"] for r in rr]
            ce = calibration_error(coverage_curve([g["credible_level"] for g in got]))
            sl = float(np.mean([g["sl_m"] for g in got]))
            xe = float(np.mean([g["ce"] for g in got]))
            cell[f"w {w:g}"] = {"calibration_error": ce, "sl_mean_m": sl, "ce_mean": xe}
            texts.append(f"{ce:.3f} / {sl:.2f} / {xe:.2f}")
        chance = chance_calibration_error(len(rr))
        cell["chance_calibration_error"] = chance
        summary["cells"].append(cell)
        lines.append(f"| {level} | {variant} | {n} | {len(rr)} | " + " | ".join(texts) + f" | {chance:.3f} |")
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=parse_seeds, default=parse_seeds("900-923"))
    ap.add_argument("--counts", type=int, nargs="+", default=[20, 50, 150])
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--variants", nargs="+", default=["steady", "filament"], choices=["steady", "filament"])
    ap.add_argument("--knowledge", default="openings", choices=["map", "openings", "wind"])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_fusion_tuning"))
    ap.add_argument(
        "--cache",
        type=Path,
        default=Path("benchmarks/results/phys_robustness/_cases_validation"),
        help="where the scenario files are kept",
    )
    ap.add_argument("-E", "--estimator-option", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--summary-only", action="store_true")
    args = ap.parse_args()
    if any(s >= 2000 for s in args.seeds):
        ap.error("tuning reads validation seeds only (the test split starts at 2000)")
    if any(n < 1 for n in args.counts):
        ap.error("--counts must be positive")
    try:
        # the physics alone: the mixtures are formed here
        options = {"learned_levels": (), **parse_params(args.estimator_option, "-E")}
    except InputDataError as exc:
        ap.error(str(exc))
    args.out.mkdir(parents=True, exist_ok=True)
    if args.summary_only:
        write_summary(args.out)
        return
    from dgse.physics.scenario import random_cases

    journal = args.out / f"journal-{args.knowledge}.jsonl"
    done = set()
    if journal.exists():
        for line in journal.read_text().splitlines():
            r = json.loads(line)
            done.add((r["variant"], r["case"], r["n"], r["trial"]))
    phys = get_estimator("dgse-phys", **options)
    # the network as dgse-phys builds it for its own mixture
    net = get_estimator("dgse-s", model="default", seed=0, dtype="auto", channels_last=True)
    args.cache.mkdir(parents=True, exist_ok=True)
    with journal.open("a") as jf:
        for seed in args.seeds:
            path = args.cache / f"test{seed}.npz"
            if not path.exists():
                random_cases(seed, n_sources=1)[0].save(path)
            base = Case.load(path)
            phys.set_knowledge(Knowledge.from_case(base, args.knowledge))
            for variant in args.variants:
                truth = variant_case(base, variant, args.cache, f"test{seed}")
                for n in args.counts:
                    for trial in range(args.trials):
                        if (variant, f"test{seed}", n, trial) in done:
                            continue
                        obs = draw_observations(truth, n, seed=0, case_id=f"test{seed}", trial=trial)
                        p_phys = np.asarray(phys.estimate(base.occupancy, base.resolution, obs).source_probs)
                        p_net = np.asarray(net.estimate(base.occupancy, base.resolution, obs).source_probs)
                        p_phys = p_phys / p_phys.sum()
                        p_net = p_net / p_net.sum()
                        mixed = {f"{w:g}": scores((1 - w) * p_phys + w * p_net, base) for w in WEIGHTS}
                        rec = {
                            "variant": variant,
                            "knowledge": args.knowledge,
                            "case": f"test{seed}",
                            "n": n,
                            "trial": trial,
                            "options": {
                                k: list(v) if isinstance(v, tuple) else v for k, v in options.items()
                            },
                            "by_weight": mixed,
                        }
                        jf.write(json.dumps(rec) + "\n")
                        jf.flush()
                        print(f"{variant} test{seed} n={n} trial {trial}", flush=True)
    write_summary(args.out)


if __name__ == "__main__":
    main()
