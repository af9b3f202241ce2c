"""Source localization from random readings per knowledge level: DGSE-S, adjoint, dgse-phys, oracle.

Issue 12's table: mean (and median) source-localization error and source
cross-entropy from 5, 20, 50, 150 and 300 random readings (Table I noise),
each method at the knowledge level it is run with (``--knowledge``):

* ``dgse-s`` and ``dgse-phys`` at ``map`` (openings proposed from the wind readings);
* ``adjoint`` and ``dgse-phys`` at ``openings``;
* ``dgse-phys`` at ``wind`` (the case's wind as the user's CFD, openings from the wind);
* ``adjoint-oracle`` at ``wind`` (the true flow re-solved).

Case sets: ``reference`` = ``../shared/reference-cases`` (OpenFOAM solutions:
the physics estimators' model differs from the generating solver), ``test``
= generated scenarios with seeds 2000-2007 (a seed range kept for testing,
never used for tuning).  Every finished estimate is kept in a journal beside
each JSON file, so an interrupted run resumes.

    python benchmarks/phys_gsl.py --trials 2 -o benchmarks/results/phys_gsl
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from dgse.evaluation.evaluate import evaluate, write_json
from dgse.journal import journal_path

COUNTS = [5, 20, 50, 150, 300]
METHODS = [
    ("dgse-s", "map"),
    ("dgse-phys", "map"),
    ("adjoint", "openings"),
    ("dgse-phys", "openings"),
    ("dgse-phys", "wind"),
    ("adjoint-oracle", "wind"),
]
TEST_SEEDS = range(2000, 2008)


def _test_cases(out: Path) -> Path:
    """The generated test scenarios as case files (made once)."""
    from dgse.physics.scenario import random_cases

    d = out / "_test_cases"
    d.mkdir(parents=True, exist_ok=True)
    for seed in TEST_SEEDS:
        path = d / f"test{seed}_src0.npz"
        if not path.exists():
            random_cases(seed, n_sources=1)[0].save(path)
    return d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_gsl"))
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--sets", nargs="+", default=["reference", "test"], choices=["reference", "test"])
    ap.add_argument(
        "--methods",
        nargs="+",
        default=None,
        metavar="METHOD@LEVEL",
        help="only these rows, e.g. dgse-phys@openings adjoint-oracle@wind (default: all)",
    )
    ap.add_argument(
        "--reference",
        type=Path,
        default=Path(
            os.environ.get(
                "DGSE_REFERENCE_CASES", Path(__file__).resolve().parents[2] / "shared" / "reference-cases"
            )
        ),
    )
    ap.add_argument("--summary-only", action="store_true", help="summarize the folder's results, run nothing")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = METHODS
    if args.methods:
        known = {f"{m}@{lv}": (m, lv) for m, lv in METHODS}
        bad = [x for x in args.methods if x not in known]
        if bad:
            ap.error(f"unknown rows {bad}; choose from {sorted(known)}")
        rows = [known[x] for x in args.methods]
    table: dict = {}
    sets = [] if args.summary_only else args.sets
    sources = {name: args.reference if name == "reference" else _test_cases(args.out) for name in sets}
    for name in sets:
        for method, level in rows:
            out = args.out / f"{name}_{method}_{level}.json"
            res = evaluate(
                sources[name], method, COUNTS, trials=args.trials, seed=0, knowledge=level,
                journal=journal_path(out), progress=True,
            )  # fmt: skip
            write_json(res, out)
    # the summary covers every row in the folder, this run's and earlier runs' (one method per
    # process is the way to use both cores)
    for name in ("reference", "test"):
        for method, level in METHODS:
            path = args.out / f"{name}_{method}_{level}.json"
            if not path.exists():
                continue
            res = json.loads(path.read_text())
            table.setdefault(name, {})[f"{method}@{level}"] = {
                n: {
                    k: res["aggregate"][str(n)].get(k)
                    for k in ("sl_error_m_mean", "sl_error_m_median", "ce_mean")
                }
                for n in COUNTS
            }
    lines = []
    for name, rows in table.items():
        lines += [
            f"## {name} ({args.trials} trials per case)",
            "",
            "SL error mean / median (m), CE mean (nats)",
            "",
        ]
        lines.append("| method@knowledge | " + " | ".join(str(n) for n in COUNTS) + " |")
        lines.append("|---|" + "---|" * len(COUNTS))
        for key, by_n in rows.items():
            cells = [
                f"{v['sl_error_m_mean']:.2f} / {v['sl_error_m_median']:.2f} / {v['ce_mean']:.1f}"
                for v in by_n.values()
            ]
            lines.append(f"| {key} | " + " | ".join(cells) + " |")
        lines.append("")
    (args.out / "summary.md").write_text("\n".join(lines))
    (args.out / "summary.json").write_text(json.dumps(table, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
