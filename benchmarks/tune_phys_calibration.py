"""How much to flatten dgse-phys's source posterior, and when: chosen on validation scenarios.

With filament readings (an intermittent plume) dgse-phys at ``openings`` is sure of
itself too soon: the true source lies in the outer part of its credible sets more
often than their levels say.  This benchmark records, for every estimate of the
validation scenarios (seeds 900-923 by default, steady and filament readings),
the source posterior flattened by a power ``p**(1/tau)`` for a grid of ``tau``
together with statistics of how well the best flow explains the readings, so that
a rule ``tau = f(statistics)`` can be chosen without estimating again::

    python benchmarks/tune_phys_calibration.py --seeds 900-923 --counts 50 150 --trials 5

Every estimate is journaled (``OUT/journal.jsonl``), so an interrupted run resumes;
``--summary-only`` rewrites ``OUT/summary.json`` and ``OUT/summary.md``: the
calibration error, mean SL error and CE per variant, count and rule.  The
scenarios are only ever read from the validation split here: the test split is
for ``benchmarks/phys_robustness.py``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from validation_tuning import checked_options, pooled, scores, tuning_parser, validation_readings

from dgse.belief.knowledge import Knowledge
from dgse.errors import InputDataError
from dgse.estimators.registry import get_estimator
from dgse.evaluation.calibration import (
    chance_calibration_error,
)
from dgse.files import write_text
from dgse.posterior.mixture import standardized_residuals
from dgse.world.grid import Grid

TAUS = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0)
#: Thresholds of the wind-misfit rules (:func:`rules`).
WIND_MISFITS = (0.4, 0.5, 0.6, 0.7)
#: Radii (m) of the gas residuals' neighbour correlation recorded per estimate.
CORRELATION_RADII = (0.5, 1.0, 2.0)
#: Thresholds of the neighbour-correlation rules (radius 1 m; :func:`rules`).
CORRELATIONS = (0.2, 0.3, 0.4, 0.5)


def flattened(probs: np.ndarray, tau: float) -> np.ndarray:
    """``probs ** (1 / tau)``, normalized (zeros stay zero): the same mode, less sure."""
    p = np.asarray(probs, dtype=np.float64)
    lp = np.full(p.shape, -np.inf)
    pos = p > 0
    lp[pos] = np.log(p[pos]) / float(tau)
    q = np.exp(lp - lp.max())
    return q / q.sum()


def neighbour_correlation(xy: np.ndarray, residuals: np.ndarray, radius: float) -> float:
    """How alike the residuals of readings at most ``radius`` apart are: ``mean(r_i r_j)`` over
    such pairs ``i < j`` (at different places) over ``mean(r^2)``: about 0 for independent
    noise, toward 1 where a model error shared by neighbouring places makes them.  ``xy``:
    ``(m, 2)`` positions, ``radius`` in their unit; 0 when no such pair exists or every
    residual is 0."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(residuals, dtype=np.float64).reshape(-1)
    if p.shape[0] != r.size:
        raise InputDataError(f"{p.shape[0]} positions for {r.size} residuals")
    scale = float(np.mean(r * r))
    if r.size < 2 or not scale > 0:
        return 0.0
    d2 = ((p[:, None, :] - p[None, :, :]) ** 2).sum(axis=-1)
    i, j = np.nonzero(np.triu((d2 <= radius * radius) & (d2 > 0), k=1))
    if i.size == 0:
        return 0.0
    return float(np.mean(r[i] * r[j]) / scale)


def residual_statistics(belief: Any, observations: Any, resolution: float) -> dict[str, float]:
    """The neighbour correlation (:func:`neighbour_correlation`) of the
    gas readings' standardized residuals about the belief's most probable source, per radius
    of :data:`CORRELATION_RADII` (``"corr1"``: 1 m)."""
    model = belief.info["response_model"]
    i, j = np.unravel_index(int(np.argmax(belief.source_probs)), belief.source_probs.shape)
    cells = observations.cells
    mean = model.mean_readings(cells)[:, i, j]
    r = standardized_residuals(mean, observations.gas, model)
    xy = Grid(belief.source_probs.shape, resolution).centers_of(cells)
    return {f"corr{d:g}": neighbour_correlation(xy, r, d) for d in CORRELATION_RADII}


def rules() -> dict[str, Callable[[dict[str, float]], float]]:
    """The flattening rules the summary compares: ``tau`` from the estimate's ``fit`` record
    (``chi2``: the gas readings' misfit; ``wind``: the best flow's relative wind misfit;
    ``corr1``: :func:`residual_statistics`; the last two only in journals written since
    2026-11-28 h, and a journal without them scores their rules as no flattening)."""
    out: dict[str, Callable[[dict[str, float]], float]] = {
        "none": lambda fit: 1.0,
        "every estimate, tau 1.25": lambda fit: 1.25,
    }
    for c in (1.5, 2.0, 3.0):
        for t in (1.5, 2.0, 3.0):
            out[f"misfit > {c:g}: tau {t:g}"] = lambda fit, c=c, t=t: t if fit["chi2"] > c else 1.0
    for c in CORRELATIONS:
        for t in (1.5, 2.0, 3.0):
            out[f"correlation > {c:g}: tau {t:g}"] = lambda fit, c=c, t=t: (
                t if fit.get("corr1", 0.0) > c else 1.0
            )
    for c in WIND_MISFITS:
        for t in (1.5, 2.0, 3.0):
            out[f"wind misfit > {c:g}: tau {t:g}"] = lambda fit, c=c, t=t: (
                t if fit.get("wind", 0.0) > c else 1.0
            )
    return out


def write_summary(out: Path) -> None:
    rows = [json.loads(x) for x in (out / "journal.jsonl").read_text().splitlines()]
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["variant"], r["n"]), []).append(r)
    summary: dict[str, Any] = {"estimates": len(rows), "taus": list(TAUS), "cells": []}
    lines = [
        "# Flattening dgse-phys's source posterior (validation scenarios)",
        "",
        "`python benchmarks/tune_phys_calibration.py` (module doc). Per variant and count: "
        "calibration error / mean SL error (m) / mean CE (nats) of `p**(1/tau)`.",
        "",
        "| variant | n | estimates | " + " | ".join(f"tau {t:g}" for t in TAUS) + " | chi2 median |",
        "|---|---|---|" + "---|" * len(TAUS) + "---|",
    ]
    for (variant, n), rr in sorted(groups.items()):
        cell: dict[str, Any] = {"variant": variant, "n": n, "estimates": len(rr), "by_tau": {}}
        texts = []
        for t in TAUS:
            cell["by_tau"][f"{t:g}"], text = pooled([r["tau"][f"{t:g}"] for r in rr])
            texts.append(text)
        chi2 = float(np.median([r["fit"]["chi2"] for r in rr]))
        cell["chi2_median"] = chi2
        for key, name in (("wind", "wind_misfit"), ("corr1", "correlation_1m")):
            got = [r["fit"][key] for r in rr if key in r["fit"]]
            if got:
                cell[f"{name}_quartiles"] = [float(q) for q in np.percentile(got, [25, 50, 75])]
        cell["chance_calibration_error"] = chance_calibration_error(len(rr))
        summary["cells"].append(cell)
        lines.append(f"| {variant} | {n} | {len(rr)} | " + " | ".join(texts) + f" | {chi2:.2f} |")
    lines += [
        "",
        "Rules: calibration error / mean SL error (m) / mean CE (nats) per variant and count "
        "(tau from the grid's nearest value).",
        "",
        "| rule | " + " | ".join(f"{v} {n}" for v, n in sorted(groups)) + " |",
        "|---|" + "---|" * len(groups) + "",
    ]
    summary["rules"] = {}
    grid = np.array(TAUS)
    for name, rule in rules().items():
        texts, cells = [], {}
        for (variant, n), rr in sorted(groups.items()):
            got = [r["tau"][f"{grid[np.argmin(abs(grid - rule(r['fit'])))]:g}"] for r in rr]
            cells[f"{variant} {n}"], text = pooled(got)
            texts.append(text)
        summary["rules"][name] = cells
        lines.append(f"| {name} | " + " | ".join(texts) + " |")
    write_text(out / "summary.json", json.dumps(summary, indent=1) + "\n")
    write_text(out / "summary.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


def main() -> None:
    ap = tuning_parser(__doc__, "benchmarks/results/phys_calibration_tuning", [50, 150])
    args = ap.parse_args()
    # the estimator's posterior (it flattens nothing): the rules are applied afterwards
    options = checked_options(ap, args, {})
    args.out.mkdir(parents=True, exist_ok=True)
    if args.summary_only:
        write_summary(args.out)
        return
    journal = args.out / "journal.jsonl"
    est = get_estimator("dgse-phys", **options)
    with journal.open("a") as jf:
        for case, key, obs in validation_readings(
            args, journal, lambda c: est.set_knowledge(Knowledge.from_case(c, args.knowledge))
        ):
            b = est.estimate(case.occupancy, case.resolution, obs)
            rec = {
                **key,
                "options": options,
                "temperature": b.info["temperature"],
                "fit": {
                    "chi2": b.info["gas_misfit"],
                    "wind": b.info["wind_misfit"],
                    **residual_statistics(b, obs, case.resolution),
                },
                "tau": {f"{t:g}": scores(flattened(b.source_probs, t), case) for t in TAUS},
                "seconds": b.info["seconds"],
            }
            jf.write(json.dumps(rec) + "\n")
            jf.flush()
            print(json.dumps({k: rec[k] for k in ("variant", "case", "n", "trial", "fit")}), flush=True)
    write_summary(args.out)


if __name__ == "__main__":
    main()
