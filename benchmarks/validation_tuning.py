"""What the posterior-tuning benchmarks share: their arguments, the validation readings they
estimate from (journaled, resumable) and the scores of a source posterior.

Used by ``benchmarks/tune_phys_calibration.py`` and ``benchmarks/tune_phys_fusion.py``; the
readings are those of ``benchmarks/phys_robustness.py`` (same scenarios, same draws), on the
validation split only.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from phys_robustness import VARIANTS, parse_seeds, perturbed_wind, variant_case

from dgse.cli.common import parse_params
from dgse.errors import InputDataError
from dgse.evaluation.calibration import calibration_error, coverage_curve, credible_level
from dgse.evaluation.evaluate import draw_observations
from dgse.evaluation.metrics import PROB_FLOOR
from dgse.sensing.sensors import Observations
from dgse.world.case import Case


def tuning_parser(doc: str, out: str, counts: list[int]) -> argparse.ArgumentParser:
    """The arguments every tuning benchmark takes (validation seeds, counts, trials, variants,
    knowledge level, output, case cache, ``-E`` estimator options, ``--summary-only``)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--seeds", type=parse_seeds, default=parse_seeds("900-923"))
    ap.add_argument("--counts", type=int, nargs="+", default=counts)
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument(
        "--variants",
        nargs="+",
        default=["steady", "filament"],
        choices=VARIANTS,
        help="as benchmarks/phys_robustness.py: the wind_* ones change the wind told at --knowledge wind",
    )
    ap.add_argument("--knowledge", default="openings", choices=["map", "openings", "wind"])
    ap.add_argument("-o", "--out", type=Path, default=Path(out))
    ap.add_argument(
        "--cache",
        type=Path,
        default=Path("benchmarks/results/phys_robustness/_cases_validation"),
        help="where the scenario files are kept",
    )
    ap.add_argument("-E", "--estimator-option", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--summary-only", action="store_true")
    return ap


def checked_options(
    ap: argparse.ArgumentParser, args: argparse.Namespace, base: dict[str, Any]
) -> dict[str, Any]:
    """``base`` updated with the ``-E`` options; refuses test seeds and bad counts."""
    if any(s >= 2000 for s in args.seeds):
        ap.error("tuning reads validation seeds only (the test split starts at 2000)")
    if any(n < 1 for n in args.counts):
        ap.error("--counts must be positive")
    if args.knowledge != "wind" and any(v.startswith("wind_") for v in args.variants):
        ap.error("the wind_* variants change only what --knowledge wind is told")
    try:
        return {**base, **parse_params(args.estimator_option, "-E")}
    except InputDataError as exc:
        ap.error(str(exc))


def validation_readings(
    args: argparse.Namespace, journal: Path, on_case: Callable[[Case], None]
) -> Iterator[tuple[Case, dict[str, Any], Observations]]:
    """``(case, key, readings)`` for every estimate ``journal`` lacks, in order: each scenario
    (made and cached on first use), variant (``on_case`` is called first with the scenario as
    the estimator is told it: its wind perturbed in the ``wind_*`` variants), count and trial;
    ``key`` (variant, case, n, trial) starts the estimate's journal line."""
    from dgse.physics.scenario import random_cases

    done = set()
    if journal.exists():
        for line in journal.read_text().splitlines():
            r = json.loads(line)
            done.add((r["variant"], r["case"], r["n"], r["trial"]))
    args.cache.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        path = args.cache / f"test{seed}.npz"
        if not path.exists():
            random_cases(seed, n_sources=1)[0].save(path)
        base = Case.load(path)
        for variant in args.variants:
            on_case(replace(base, wind=perturbed_wind(base, variant)))
            truth = variant_case(base, variant, args.cache, f"test{seed}")
            for n in args.counts:
                for trial in range(args.trials):
                    if (variant, f"test{seed}", n, trial) in done:
                        continue
                    obs = draw_observations(truth, n, seed=0, case_id=f"test{seed}", trial=trial)
                    key = {"variant": variant, "knowledge": args.knowledge, "case": f"test{seed}", "n": n}
                    yield base, {**key, "trial": trial}, obs


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


def pooled(got: list[dict[str, float]]) -> tuple[dict[str, float], str]:
    """The calibration error, mean SL error and mean CE of estimates' :func:`scores`, as a
    record (with the truth's mean credible level: 0.5 when calibrated, below when too flat)
    and as the summaries' ``"cal / sl / ce"`` text."""
    levels = [g["credible_level"] for g in got]
    ce = calibration_error(coverage_curve(levels))
    sl = float(np.mean([g["sl_m"] for g in got]))
    xe = float(np.mean([g["ce"] for g in got]))
    mean_level = float(np.mean(levels))
    record = {"calibration_error": ce, "sl_mean_m": sl, "ce_mean": xe, "mean_credible_level": mean_level}
    return record, f"{ce:.3f} / {sl:.2f} / {xe:.2f}"
