"""Time of the zeros' factor kernel a candidate, on calls recorded in a search (issue 12, part 4).

Runs one dgse-phys search episode (knowledge ``openings``, ``SEARCH_PLANNER``, the searches'
``SEARCH_ESTIMATOR``) on a test scenario, keeps every ``every``-th call of
:func:`dgse.posterior.censored_kernel.censored_log_factor`, and replays them (best of
``--repeats``, one thread): microseconds a candidate, and the share of the zeros that enter
through their power sums (faint at the candidate's cap, ``censored_kernel._split_zeros``).
``--against DIR`` replays the same calls with the kernel of another checkout's ``src``
(``git worktree add DIR REV``), where the call signature is the same, and reports the
largest difference of the factors::

    python benchmarks/censored_kernel_time.py --case 2005 --every 400
    python benchmarks/censored_kernel_time.py --case 2005 --every 400 --against /tmp/old

Writes ``benchmarks/results/censored_kernel_time.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from phys_search import cases_dir, record_calls

from dgse.files import write_text
from dgse.posterior import censored_kernel
from dgse.presets import PRESETS


def _replay(kernel: ModuleType, calls: list[tuple], repeats: int) -> tuple[float, list[np.ndarray]]:
    """The best total seconds over ``repeats`` replays of ``calls``, and the factors."""
    kernel.censored_log_factor(*calls[0])  # compiled or loaded from the cache
    best, outs = np.inf, []
    for _ in range(repeats):
        t = time.perf_counter()
        outs = [kernel.censored_log_factor(*c) for c in calls]
        best = min(best, time.perf_counter() - t)
    return best, outs


def _faint_share(calls: list[tuple]) -> float:
    """The share of (candidate, zero) pairs that enter through the power sums."""
    faint = total = 0
    mom = np.empty(censored_kernel._SERIES_ORDER + 1)
    for Bt, qhat, aa, beta_n, alpha_n, qmax, *_ in calls:
        row = np.empty(Bt.shape[1])
        for s in range(Bt.shape[0]):
            cap = censored_kernel._lambda_cap(qhat[s], aa[s], beta_n[s], alpha_n, qmax)
            faint += Bt.shape[1] - censored_kernel._split_zeros(Bt[s], cap, row, mom)
            total += Bt.shape[1]
    return faint / max(total, 1)


def _kernel_of(src: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "other_censored_kernel", src / "src" / "dgse" / "localization" / "censored_kernel.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=int, default=2005, help="test scenario (2000-2019)")
    ap.add_argument("--every", type=int, default=400, help="keep every N-th call")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--against", type=Path, default=None, help="another checkout to replay the calls with")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results"))
    args = ap.parse_args()
    d = cases_dir(args.out / "phys_search", "test")
    path = d / f"test{args.case}_src0.npz"
    options = PRESETS["dgse-phys"].estimator_options_at("openings", search=True)
    kept = record_calls(censored_kernel, "censored_log_factor", path, args.every, options)
    calls = [a for a, _ in kept]
    n = sum(c[0].shape[0] for c in calls)
    secs, outs = _replay(censored_kernel, calls, args.repeats)
    row: dict[str, Any] = {
        "case": path.stem,
        "calls": len(calls),
        "candidates": n,
        "zeros_per_call": [int(c[0].shape[1]) for c in calls],
        "us_per_candidate": 1e6 * secs / n,
        "faint_share": _faint_share(calls),
    }
    if args.against is not None:
        other_secs, other = _replay(_kernel_of(args.against), calls, args.repeats)
        row["against"] = str(args.against)
        row["against_us_per_candidate"] = 1e6 * other_secs / n
        diffs = [np.abs(a - b).max() for a, b in zip(outs, other, strict=True)]
        row["max_abs_difference_nats"] = float(max(diffs))
    print(json.dumps({k: v for k, v in row.items() if k != "zeros_per_call"}), flush=True)
    out = args.out / "censored_kernel_time.json"
    write_text(out, json.dumps(row, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
