"""How much of DGSE-S's source belief to keep in dgse-phys's, by level and count: validation only.

dgse-phys mixes the network's source posterior into its own at ``map`` with weight
``max(floor, 0.9 (1 - m / 50))`` for ``m`` readings (``fusion.weight``, ``fusion.readings``,
``fusion.floor``; weight 0 at the other levels).  A floor above 0
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

import json
from pathlib import Path
from typing import Any

import numpy as np
from validation_tuning import checked_options, pooled, scores, tuning_parser, validation_readings

from dgse.belief.knowledge import Knowledge
from dgse.estimators.registry import get_estimator
from dgse.evaluation.calibration import (
    chance_calibration_error,
)
from dgse.files import write_text

#: The network's weights in the mixture ``(1 - w) physics + w network`` that are scored.
WEIGHTS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)


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
            cell[f"w {w:g}"], text = pooled([r["by_weight"][f"{w:g}"] for r in rr])
            texts.append(text)
        chance = chance_calibration_error(len(rr))
        cell["chance_calibration_error"] = chance
        summary["cells"].append(cell)
        lines.append(f"| {level} | {variant} | {n} | {len(rr)} | " + " | ".join(texts) + f" | {chance:.3f} |")
    write_text(out / "summary.json", json.dumps(summary, indent=1) + "\n")
    write_text(out / "summary.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


def main() -> None:
    ap = tuning_parser(__doc__, "benchmarks/results/phys_fusion_tuning", [20, 50, 150])
    args = ap.parse_args()
    # the physics alone: the mixtures are formed here
    options = checked_options(ap, args, {"fusion.weight": 0.0, "fusion.floor": 0.0})
    args.out.mkdir(parents=True, exist_ok=True)
    if args.summary_only:
        write_summary(args.out)
        return
    journal = args.out / f"journal-{args.knowledge}.jsonl"
    phys = get_estimator("dgse-phys", **options)
    # the network as dgse-phys builds it for its own mixture
    net = get_estimator("dgse-s", model="default", seed=0, dtype="auto", channels_last=True)
    recorded = {k: list(v) if isinstance(v, tuple) else v for k, v in options.items()}
    with journal.open("a") as jf:
        for case, key, obs in validation_readings(
            args, journal, lambda c: phys.set_knowledge(Knowledge.from_case(c, args.knowledge))
        ):
            p_phys = np.asarray(phys.estimate(case.occupancy, case.resolution, obs).source_probs)
            p_net = np.asarray(net.estimate(case.occupancy, case.resolution, obs).source_probs)
            p_phys, p_net = p_phys / p_phys.sum(), p_net / p_net.sum()
            mixed = {f"{w:g}": scores((1 - w) * p_phys + w * p_net, case) for w in WEIGHTS}
            jf.write(json.dumps({**key, "options": recorded, "by_weight": mixed}) + "\n")
            jf.flush()
            print(f"{key['variant']} {key['case']} n={key['n']} trial {key['trial']}", flush=True)
    write_summary(args.out)


if __name__ == "__main__":
    main()
