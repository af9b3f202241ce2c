"""How much of the source posterior the zeros' cut moves: the censored correction with its
default ``tail`` (candidates ranked by the plug-in value) against the same correction
computed for every candidate.

Runs one dgse-phys search episode (knowledge ``openings``, the preset's planner) on a test
scenario, keeps the arguments of every ``every``-th call of
:func:`dgse.posterior.adjoint.censored_correction`, and for each reports the total
variation between the cut posterior and the full one, and how many candidates got
the integrated factor::

    python benchmarks/censored_cut.py --case test2001_src0

Writes ``benchmarks/results/censored_cut.json``.  (An exact ranking by an upper bound was
compared here too and removed: ``docs/decisions.md``.)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from phys_search import cases_dir, record_calls

from dgse.files import write_text
from dgse.posterior import adjoint, mixture


def _posterior(logl: np.ndarray, factor: np.ndarray) -> np.ndarray:
    x = logl + factor
    p = np.exp(x - x.max())
    return p / p.sum()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="test2001_src0")
    ap.add_argument("--every", type=int, default=8, help="keep every N-th call")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results"))
    args = ap.parse_args()
    path = cases_dir(args.out / "phys_search", "test", None) / f"{args.case}.npz"
    # the estimator calls it by keyword (through dgse.posterior.mixture); the tail is what is compared
    calls = record_calls(mixture, "censored_correction", path, args.every)
    kept = [{k: v for k, v in kw.items() if k not in ("tail", "memo")} for _, kw in calls]
    evaluated = [0]
    factor = adjoint._censored_log_factor

    def count(Bt, *a):
        evaluated[0] += Bt.shape[0]
        return factor(Bt, *a)

    adjoint._censored_log_factor = count
    rows = []
    try:
        for kw in kept:
            full = adjoint.censored_correction(**kw, tail=0.0)
            p_full = _posterior(kw["logl"], full)
            z = kw["z"]
            row = {"readings": int(z.size), "zeros": int((z <= 0).sum()), "candidates": int(kw["logl"].size)}
            evaluated[0] = 0
            cut = adjoint.censored_correction(**kw)
            row["plug-in"] = {
                "integrated": evaluated[0],
                "total_variation": float(0.5 * np.abs(_posterior(kw["logl"], cut) - p_full).sum()),
            }
            rows.append(row)
    finally:
        adjoint._censored_log_factor = factor
    for r in rows:
        a = r["plug-in"]
        print(
            f"{r['readings']:4d} readings ({r['zeros']:3d} zeros) of {r['candidates']} candidates: "
            f"{a['integrated']:5d} integrated, TV {a['total_variation']:.3f}"
        )
    out = args.out / "censored_cut.json"
    summary = {"plug-in": max(r["plug-in"]["total_variation"] for r in rows) if rows else None}
    print("largest TV:", summary)
    write_text(
        out,
        json.dumps(
            {"case": args.case, "tail": adjoint.CENSORED_TAIL, "ranking": "plug-in",
             "largest_total_variation": summary, "calls": rows},
            indent=1,
        ),
    )  # fmt: skip
    print("wrote", out)


if __name__ == "__main__":
    main()
