"""Is one method's calibration error really above another's?  A bootstrap over scenarios.

``benchmarks/phys_robustness.py`` journals hold the truth's credible level of every
estimate.  This pairs two methods' estimates of the same readings (variant, scenario,
count, trial), and gives the difference of their credible sets' calibration errors with a
90 % interval from resampling whole scenarios (:func:`dgse.evaluation.calibration.
calibration_difference`): a scenario's trials share its flow and source, so the chance level
of independent estimates understates how much the difference moves::

    python benchmarks/calibration_difference.py \\
        benchmarks/results/phys_calibration50_tilt dgse-phys@openings \\
        benchmarks/results/phys_calibration50_mixture dgse-s@map --n 50

With ``--b-variant steady`` the second method's steady estimates stand for the variants it
lacks (DGSE-S against ``dgse-phys@wind`` told a perturbed wind: the same readings).
Prints one line per variant and writes ``benchmarks/results/calibration_difference.json``
(the entry of these two runs replaced, the others kept).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from phys_robustness import journal_rows  # this folder's

from dgse.evaluation.calibration import calibration_difference
from dgse.files import write_text

Key = tuple[str, str, int, int]


def levels(folder: Path, method: str) -> dict[Key, float]:
    """``{(variant, case, n, trial): credible level}`` of ``method@knowledge`` in a run's journals."""
    name, _, level = method.partition("@")
    out = {
        (v, case, int(n), int(trial)): float(r["credible_level"])
        for (v, m, lv, case, n, trial), r in journal_rows(folder).items()
        if (m, lv) == (name, level)
    }
    if not out:
        raise SystemExit(f"no estimates of {method} in {folder}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_a", type=Path, help="a phys_robustness output folder")
    ap.add_argument("method_a", help="method@knowledge in it")
    ap.add_argument("run_b", type=Path)
    ap.add_argument("method_b")
    ap.add_argument("--n", type=int, default=None, help="only this many readings (default: each count)")
    ap.add_argument(
        "--b-variant",
        default=None,
        help="for the variants the second run lacks, take its estimates of this variant (the wind_* "
        "variants change only what is told at 'wind': DGSE-S's steady estimates saw their readings)",
    )
    ap.add_argument("--boot", type=int, default=2000, help="bootstrap resamples")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/calibration_difference.json"))
    args = ap.parse_args()
    a, b = levels(args.run_a, args.method_a), levels(args.run_b, args.method_b)
    if args.b_variant is not None:
        own = {k[0] for k in b}
        stand_in = {k: b.get((args.b_variant, *k[1:])) for k in a if k[0] not in own}
        b.update({k: x for k, x in stand_in.items() if x is not None})
    both = sorted(k for k in set(a) & set(b) if args.n is None or k[2] == args.n)
    if not both:
        raise SystemExit("the two runs have no estimate of the same readings in common")
    rows: list[dict[str, Any]] = []
    for variant, n in sorted({(k[0], k[2]) for k in both}):
        keys = [k for k in both if k[0] == variant and k[2] == n]
        d = calibration_difference(
            [a[k] for k in keys], [b[k] for k in keys], [k[1] for k in keys], n_boot=args.boot
        )
        # each scenario's mean credible level of the truth (0.5 when calibrated): the spread
        # that a pooled calibration error can hide when scenarios err both ways
        spread = {}
        for name, run in (("a", a), ("b", b)):
            per = {}
            for k in keys:
                per.setdefault(k[1], []).append(run[k])
            means = [float(np.mean(v)) for v in per.values()]
            spread[f"scenario_mean_level_{name}"] = [min(means), max(means)]
        rows.append({"variant": variant, "n": n, "estimates": len(keys), **d, **spread})
        print(
            f"{variant} n={n}: {args.method_a} {d['a']:.3f}, {args.method_b} {d['b']:.3f}, difference "
            f"{d['difference']:+.3f} (90 % over {int(d['groups'])} scenarios: "
            f"{d['low']:+.3f} to {d['high']:+.3f}; {len(keys)} estimates); the scenarios' mean credible "
            "levels range over {:.2f}-{:.2f} and {:.2f}-{:.2f}".format(
                *spread["scenario_mean_level_a"], *spread["scenario_mean_level_b"]
            )
        )
    entry = {
        "a": {"run": str(args.run_a), "method": args.method_a},
        "b": {"run": str(args.run_b), "method": args.method_b},
        "b_variant": args.b_variant,
        "bootstrap": args.boot,
        "rows": rows,
    }
    old = json.loads(args.out.read_text()) if args.out.exists() else []
    same = ("a", "b", "b_variant")
    kept = [e for e in old if any(e.get(f) != entry[f] for f in same)]
    write_text(args.out, json.dumps([*kept, entry], indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
