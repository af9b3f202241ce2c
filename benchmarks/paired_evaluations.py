"""Paired comparison of ``dgse evaluate`` results on the same readings.

``dgse evaluate`` seeds every estimate's readings by (seed, case, count, trial), so two runs
with the same seed on the same cases saw the same readings, estimate by estimate.  This prints,
per count, the first result's mean / median SL error and CE and, against each other result,
the ratio of the mean SL errors and the paired difference (mean +- standard error, m) over the
estimates both have (``--by-case``: and each case's means)::

    python benchmarks/paired_evaluations.py NEW.json OLD.json ORACLE.json

A result is an evaluation JSON (``--json``), its journal (``.journal.jsonl``) or a gzipped
journal (``.journal.jsonl.gz``); a JSON with several counts gives each of them.
"""

from __future__ import annotations

import argparse
import gzip
import json
from pathlib import Path

import numpy as np

Key = tuple[str, int, int]


def records(path: Path) -> dict[Key, dict]:
    """``{(case, n_obs, trial): record}`` of an evaluation JSON or journal."""
    if path.name.endswith((".jsonl", ".jsonl.gz")):
        opener = gzip.open if path.suffix == ".gz" else open
        with opener(path, "rt") as f:
            rows = [json.loads(line)["record"] for line in f if '"record"' in line]
    else:
        rows = json.loads(path.read_text())["per_case"]
    return {(r["case"], int(r["n_obs"]), int(r["trial"])): r for r in rows}


def compare(
    first: dict[Key, dict], others: list[tuple[str, dict[Key, dict]]], by_case: bool = False
) -> list[str]:
    lines = []
    for n in sorted({k[1] for k in first}):
        keys = [k for k in first if k[1] == n]
        sl = np.array([first[k]["sl_error_m"] for k in keys])
        ce = np.array([first[k]["ce"] for k in keys])
        lines.append(
            f"{n} readings, {len(keys)} estimates: SL error {sl.mean():.3f} / {np.median(sl):.3f} m "
            f"(mean / median), CE {ce.mean():.2f} nats"
        )
        for name, other in others:
            both = [k for k in keys if k in other]
            if len(both) < 2:
                lines.append(f"  against {name}: fewer than 2 shared estimates")
                continue
            a = np.array([first[k]["sl_error_m"] for k in both])
            b = np.array([other[k]["sl_error_m"] for k in both])
            d = a - b
            se = d.std(ddof=1) / np.sqrt(len(d))
            lines.append(
                f"  against {name}: ratio {a.mean() / b.mean():.2f} ({a.mean():.3f} / {b.mean():.3f} m), "
                f"difference {d.mean():+.3f} +- {se:.3f} m on {len(both)}"
            )
            if by_case:
                for case in sorted({k[0] for k in both}):
                    mine = [i for i, k in enumerate(both) if k[0] == case]
                    lines.append(f"    {case}: {a[mine].mean():.2f} against {b[mine].mean():.2f} m")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("first", type=Path)
    ap.add_argument("others", type=Path, nargs="+")
    ap.add_argument("--by-case", action="store_true", help="each case's mean SL errors too")
    args = ap.parse_args()
    others = [(str(p), records(p)) for p in args.others]
    print("\n".join(compare(records(args.first), others, args.by_case)))


if __name__ == "__main__":
    main()
