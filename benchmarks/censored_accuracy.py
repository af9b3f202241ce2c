"""How exact the zeros' factor is in a search (issue 12): the compiled quadrature's three ways
(Gauss-Hermite over the log noise precision only, the default that scans where a probe
says that misses mass, the scan everywhere) against each other, and the scan against a
brute-force integral on a sample of candidates.

Runs one dgse-phys search episode per test scenario (knowledge ``openings``,
``SEARCH_PLANNER``), keeps the arguments of every ``every``-th call of
:func:`dgse.posterior.censored_kernel.censored_log_factor` (the candidates that hold
the posterior mass, as the correction hands them over), and replays them::

    python benchmarks/censored_accuracy.py --cases 2
    python benchmarks/censored_accuracy.py --cases 2 --search-estimator   # with SEARCH_ESTIMATOR

Writes ``benchmarks/results/censored_accuracy.json`` (``censored_accuracy_search.json`` with
``--search-estimator``, the noise-weight mixture the searches run): per scenario and way, the seconds
of the replay, the share of candidates scanned and the quantiles of the absolute error
(nats) against the scan; the sample's scan and brute-force values.  Calls before the
first positive reading are left out of the error (their noise prior is degenerate: its
scale comes from the readings' mean, see ``adjoint_log_evidence``) and counted.
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import time
from pathlib import Path

import numpy as np
from phys_search import cases_dir, record_calls
from scipy import special

from dgse.files import write_text
from dgse.posterior import adjoint, censored_kernel
from dgse.presets import PRESETS

WAYS = {"gauss-hermite": math.inf, "default": adjoint.CENSORED_SCAN_MARGIN, "scan": -math.inf}


#: The kernel's parameter names, to replace recorded arguments by name.
_PARAMS = list(inspect.signature(censored_kernel.censored_log_factor.py_func).parameters)


def _replay(call: list, margin: float) -> tuple[np.ndarray, np.ndarray, float]:
    scanned = np.zeros(call[1].size, dtype=np.uint8)
    args = dict(zip(_PARAMS, call, strict=False))
    args.update(scan_margin=margin, scanned=scanned)
    t = time.perf_counter()
    out = censored_kernel.censored_log_factor(*(args[k] for k in _PARAMS if k in args))
    return out, scanned, time.perf_counter() - t


def brute_force(call: list, s: int) -> float:
    """The factor of candidate ``s`` by a dense grid over ``log tau`` and the rate."""
    Bt, qhat, aa, beta_n, alpha_n, qmax, log_mass = call[:7]
    b, qh, a, bn = Bt[s], qhat[s], aa[s], beta_n[s]
    t0 = math.log(alpha_n / bn)
    ts = np.linspace(t0 - 40.0, t0 + 12.0, 1300)
    qs = np.unique(np.concatenate([np.linspace(0.0, qmax, 500), np.geomspace(1e-7 * qmax, qmax, 300)]))
    norm = alpha_n * math.log(bn) - special.gammaln(alpha_n) - 0.5 * math.log(2.0 * math.pi)
    rows = []
    for t in ts:
        tau = math.exp(t)
        lp = norm + alpha_n * t - bn * tau + 0.5 * t + 0.5 * math.log(a) - 0.5 * tau * a * (qs - qh) ** 2
        f = lp + special.log_ndtr(-np.outer(qs * math.sqrt(tau), b)).sum(axis=1)
        m = f.max()
        rows.append(m + math.log(np.trapezoid(np.exp(f - m), qs)) if np.isfinite(m) else -np.inf)
    r = np.array(rows)
    m = r.max()
    return float(m + math.log(np.trapezoid(np.exp(r - m), ts)) - log_mass[s])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=2)
    ap.add_argument("--every", type=int, default=3, help="keep every N-th call")
    ap.add_argument("--brute", type=int, default=12, help="candidates checked by brute force per scenario")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results"))
    ap.add_argument(
        "--search-estimator",
        action="store_true",
        help="episodes with the searches' estimator options (SEARCH_ESTIMATOR), not dgse-phys's defaults",
    )
    args = ap.parse_args()
    options = (
        PRESETS["dgse-phys"].estimator_options_at("openings", search=True) if args.search_estimator else {}
    )
    d = cases_dir(args.out / "phys_search", "test", args.cases)
    report = []
    rng = np.random.default_rng(0)
    for path in sorted(d.glob("*.npz")):
        calls = record_calls(censored_kernel, "censored_log_factor", path, args.every, options)
        kept = [list(a) for a, _ in calls]
        # no positive reading yet: beta_n at the prior's floor
        proper = [c for c in kept if c[3].min() > 1e-12]
        if not proper:  # no zero reading after a positive one in this episode
            print(json.dumps({"case": path.stem, "calls": 0}), flush=True)
            continue
        vals, secs, shares = {}, {}, {}
        for way, margin in WAYS.items():
            outs = [_replay(c, margin) for c in proper]
            vals[way] = np.concatenate([o[0] for o in outs]) if outs else np.zeros(0)
            shares[way] = float(np.concatenate([o[1] for o in outs]).mean()) if outs else 0.0
            secs[way] = float(sum(o[2] for o in outs))
        ref = vals["scan"]
        errors = {}
        for way in ("gauss-hermite", "default"):
            e = np.abs(vals[way] - ref)
            quantiles = (("p50", 0.5), ("p99", 0.99), ("p999", 0.999))
            errors[way] = {q: float(np.quantile(e, p)) for q, p in quantiles}
            errors[way]["max"] = float(e.max()) if e.size else 0.0
        # the sample: the largest Gauss-Hermite misses and random candidates
        sizes = np.cumsum([0] + [c[1].size for c in proper])
        miss = np.argsort(-np.abs(vals["gauss-hermite"] - ref))[: args.brute // 2]
        pick = np.unique(np.concatenate([miss, rng.choice(ref.size, args.brute - miss.size, replace=False)]))
        sample = []
        for g in pick:
            ci = int(np.searchsorted(sizes, g, side="right") - 1)
            s = int(g - sizes[ci])
            sample.append(
                {
                    "scan": float(ref[g]),
                    "gauss_hermite": float(vals["gauss-hermite"][g]),
                    "brute_force": brute_force(proper[ci], s),
                }
            )
        row = {
            "case": path.stem,
            "calls": len(proper),
            "calls_without_positive_readings": len(kept) - len(proper),
            "candidates": int(ref.size),
            "seconds": secs,
            "scanned_share": shares,
            "abs_error_vs_scan": errors,
            "scan_vs_brute_force_max": max(abs(r["scan"] - r["brute_force"]) for r in sample),
            "sample": sample,
        }
        report.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "sample"}), flush=True)
    out = args.out / ("censored_accuracy_search.json" if args.search_estimator else "censored_accuracy.json")
    body = {"scan_margin": adjoint.CENSORED_SCAN_MARGIN, "estimator_options": options, "episodes": report}
    write_text(out, json.dumps(body, indent=1))
    print("wrote", out)


if __name__ == "__main__":
    main()
