"""dgse-phys from random readings: the knowledge-level tables, its robustness, and its tuning.

One command per measurement (``python benchmarks/phys.py COMMAND --help``), each writing under
``benchmarks/results/``.  Seeds 900-963 are validation scenarios (every tuning command reads
only these), 2000-2019 test scenarios (never tuned on); ``../shared/reference-cases`` (or
``$DGSE_REFERENCE_CASES``) are OpenFOAM's, a flow the built-in solver did not make.

* ``gsl``: mean and median source-localization error and source cross-entropy from 5 to 300
  random readings (Table I noise) per method at its knowledge level (DGSE-S and dgse-phys at
  ``map``, ``adjoint`` and dgse-phys at ``openings``, dgse-phys and ``adjoint-oracle`` at
  ``wind``), on the reference cases and generated test scenarios 2000-2007 (``test``), and
  on a fresh draw of test scenarios 2008-2015 with readings of seed 11 (``fresh``); every
  estimate journaled; ``--workers N`` runs one process per case and count
  (:func:`dgse.bench.parallel.evaluate_parallel`).  ``OUT/<set>_<method>_<level>.json`` and
  ``OUT/summary.{json,md}``::

      python benchmarks/phys.py gsl --sets test reference --methods dgse-phys@openings \\
          adjoint-oracle@wind dgse-s@map --trials 20 --workers 2 --rounds 20 \\
          -o benchmarks/results/phys_gsl_20_mixture
      python benchmarks/phys.py gsl --sets test reference --methods dgse-phys@openings \\
          --trials 20 --workers 2 --rounds 5 -o benchmarks/results/phys_gsl_20_tilt  # and _floor_openings
      python benchmarks/phys.py gsl --sets test reference --methods dgse-phys@wind \\
          --trials 20 --workers 2 --rounds 5 -o benchmarks/results/phys_gsl_20_given
      python benchmarks/phys.py gsl --sets fresh --methods dgse-s@map dgse-phys@map \
          --trials 20 -o benchmarks/results/phys_gsl_fresh

  ``phys_gsl_20_map_sqrt`` is ``dgse evaluate`` on the same cases: ``dgse evaluate
  benchmarks/results/phys_gsl_20_tilt/_test_cases -m dgse-phys --knowledge map -n N --trials 20
  --seed 0 --threads 1 --json benchmarks/results/phys_gsl_20_map_sqrt/test_dgse-phys_map_N.json``
  (and ``../shared/reference-cases`` for ``reference_...``).  The folders with a
  ``summary.json`` keep their gzipped journals, not the per-row JSONs: ``gunzip`` them and
  run the folder's command again, which finds every estimate in the journals and writes
  the JSONs and the summary without estimating again.
* ``robustness``: dgse-phys where its physics is wrong, the same random readings with the
  physics off in one way at a time (:data:`dgse.bench.scenarios.VARIANTS`: filament readings;
  the wind told at ``wind`` rotated, smoothed or twice too fast); mean and median SL error,
  mean CE and the credible sets' calibration error per variant, method and count; every
  estimate journaled (``OUT/journal[-TAG].jsonl``), ``--paired DIR`` compares two runs on the
  estimates both made (``OUT/paired.md``).  ``benchmarks/results/phys_robustness/`` is its
  default folder (``--seeds 2000-2005 --trials 1``), whose ``_cases`` the other runs share::

      python benchmarks/phys.py robustness --seeds 2000-2019 --counts 50 --trials 5 \\
          --variants steady filament --methods METHOD --tag TAG \\
          --cache benchmarks/results/phys_robustness/_cases -o benchmarks/results/phys_calibration50_mixture
      python benchmarks/phys.py robustness --seeds 2000-2009 --counts 50 --trials 10 \\
          --variants steady filament --methods dgse-phys@openings --tag a \\
          -o benchmarks/results/phys_calibration50_floor_openings   # and --seeds 2010-2019 --tag b
      python benchmarks/phys.py robustness --seeds 2000-2019 --counts 50 --trials 2 \\
          --variants steady filament --methods dgse-phys@map --tag map -E fusion.floor=0.05 \\
          -o benchmarks/results/phys_calibration50_floor
      python benchmarks/phys.py robustness --seeds 2000-2019 --counts 20 50 150 --trials 2 \\
          --variants wind_smoothed steady wind_rotated wind_x2 filament --methods dgse-phys@wind \\
          -o benchmarks/results/phys_robustness_wind_given   # -E flows.given_wind_prior=1.0: ..._given1.0
      python benchmarks/phys.py robustness --seeds 900-923 --counts 50 150 --trials 2 \\
          --variants steady wind_smoothed wind_x2 wind_rotated filament --methods dgse-phys@wind \\
          -E flows.given_wind_prior=P -o benchmarks/results/phys_given_wind_validation/givenP
      python benchmarks/phys.py robustness --seeds 900-923 --counts 50 150 --trials 5 \\
          --variants steady filament --methods dgse-phys@openings \\
          -o benchmarks/results/phys_noise_weights_validation/openings_mixture

  The last is ``phys_noise_weights_validation/openings_mixture`` (``map_mixture`` and
  ``wind_mixture``: ``--methods dgse-phys@map`` / ``@wind`` with the counts and trials their
  ``summary.md`` names).  Two kinds of recorded folder ran dgse-phys options that are removed
  with the experiments they served (``docs/decisions.md``; this script at commit 7ba21b2 takes
  them): ``phys_calibration50_misfit`` flattened the posterior where the gas readings misfit
  (``-E misfit_threshold=2.0``), and ``phys_noise_weights_validation/*_plug-in`` weighed the
  noise by the plug-in alone (``-E 'noise_weights="plug-in"'``; the mixture is dgse-phys's only
  gas evidence now).

* ``calibration``: how well calibrated dgse-phys's source posterior is, and how much a
  flattening would change that: every estimate of the validation scenarios with its
  posterior flattened by a grid of powers (the estimator flattens nothing: the rules,
  not adopted, are scored here from the journal) and the statistics of how well the best
  flow explains the readings, so that any rule is scored without estimating again
  (``OUT/journal.jsonl``, ``OUT/summary.{json,md}``)::

      python benchmarks/phys.py calibration --seeds 900-923 --counts 50 150 --trials 5 \\
          -o benchmarks/results/phys_calibration_tuning      # --knowledge map/wind: _map, _wind
      python benchmarks/phys.py calibration --seeds 900-923 --counts 150 300 --trials 2 \\
          --variants steady --knowledge map -E evidence.effective_readings=E \\
          -E evidence.effective_growth=0 -o benchmarks/results/phys_map_tempering_validation/effE
      python benchmarks/phys.py calibration --seeds 900-923 --counts 150 300 --trials 2 \\
          --variants steady --knowledge map [-E evidence.censored_tilt=false] \\
          -o benchmarks/results/phys_tilt_map_validation[/notilt]

  (``phys_map_tempering_validation/sqrt18`` is the first of those without ``-E``: ``T =
  sqrt(m / 18)`` is the default at ``map``.)

* ``fusion``: how much of DGSE-S's source belief to keep in dgse-phys's: the physics'
  posterior and the network's for every validation estimate, the mixture scored for a grid of
  weights (``OUT/journal-LEVEL.jsonl``, ``OUT/summary.{json,md}``)::

      python benchmarks/phys.py fusion --knowledge openings --counts 20 50 150 --trials 5 \\
          -o benchmarks/results/phys_fusion_tuning_openings_tilt
      python benchmarks/phys.py fusion --knowledge map --counts 50 150 --trials 1 \\
          -o benchmarks/results/phys_fusion_tuning
      python benchmarks/phys.py fusion --knowledge wind --counts 50 150 --trials 2 --variants steady \\
          filament wind_rotated wind_smoothed wind_x2 -o benchmarks/results/phys_fusion_tuning_wind_given
      # the same with the given field alone (-E flows.given_wind_prior=1.0): ..._wind_perturbed

* ``fields``: dgse-phys's field model error per knowledge level, chosen by the Gaussian log
  likelihood of the true fields on validation scenarios 900-911::

      python benchmarks/phys.py fields -o benchmarks/results/phys_field_tuning.json

* ``sweep NAME``: settings of dgse-phys compared on the same readings of generated validation
  scenarios, by SL error and CE (:data:`SWEEPS`; every other option at its default):
  ``temperature`` (the tempering at ``openings``, ``evidence.effective_readings``), ``map``
  (how many readings the gas evidence counts at ``map``), ``learned`` (DGSE-S's weight at
  ``map``, ``fusion.weight`` and ``fusion.readings``).  Writes ``phys_temperature.json``,
  ``phys_map_tuning.json``, ``phys_learned_tuning.json``::

      python benchmarks/phys.py sweep temperature

  Two sweeps ran settings whose options are removed (``docs/decisions.md``) and run only what
  remains: ``temperature`` compared constant temperatures ``T = 2, 4, 8`` too, and ``map`` a
  tempering of the flow hypotheses' weights (``hypothesis_readings``); the recorded
  ``phys_temperature.json`` and ``phys_map_tuning.json`` hold their rows, and this script at
  commit 7ba21b2 runs them.

* ``projection``: the settings of :mod:`dgse.physics.projection` (a given wind made
  mass-conserving and given an eddy viscosity): the plume on that flow against the
  scenario's own, validation seeds 900-907::

      python benchmarks/phys.py projection -o benchmarks/results/projection_tuning.json

* ``turbulence``: k-epsilon on a frozen flow against the coupled solve's, per residual
  criterion (why ``dgse-phys --knowledge wind`` missed test scenario 2005)::

      python benchmarks/phys.py turbulence --seeds 900-911,2005 -o benchmarks/results/frozen_turbulence.json

* ``closed``: closed slices, what an imported GADEN scenario is: OpenFOAM reference cases
  with walls drawn at the map's edge and no openings (:func:`dgse.bench.scenarios.walled_case`),
  from random readings, dgse-phys at ``wind`` and ``map`` against DGSE-S; ``--slice-smoothing``
  smooths dgse-phys's exchange through the slice::

      python benchmarks/phys.py closed -o benchmarks/results/phys_closed
      python benchmarks/phys.py closed --methods dgse-phys@wind --trials 4 --slice-smoothing L \\
          -o benchmarks/results/phys_closed_smoothingL   # L = 0 (no option), 0.2, 0.5

* ``diagnostics``: three diagnoses of the physics posterior on one test scenario: how
  negative the raw adjoint rows are (``undershoot``), how far the estimate moves with the
  given inlet speed (``speed``), and warm- against cold-started speed flows
  (``warm_start``)::

      python benchmarks/phys.py diagnostics --case test2005 --speeds 1.0 1.331 1.38
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from dgse.belief.knowledge import Knowledge
from dgse.bench.commands import command_parser, run_command
from dgse.bench.scenarios import VARIANTS, parse_seeds, perturbed_wind, search_cases, variant_case
from dgse.cli.common import parse_params
from dgse.errors import InputDataError
from dgse.estimators.phys import PhysicsGuidedEstimator
from dgse.estimators.registry import get_estimator
from dgse.evaluation.calibration import (
    calibration_error,
    chance_calibration_error,
    coverage_curve,
    credible_level,
)
from dgse.evaluation.evaluate import draw_observations, evaluate, summarize, write_json
from dgse.evaluation.metrics import PROB_FLOOR, source_cross_entropy, source_localization_error
from dgse.files import write_text
from dgse.journal import journal_path
from dgse.physics.projection import ProjectedFlow, project_wind
from dgse.sensing.sensors import Observations
from dgse.world.case import Case

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
REFERENCE = Path(
    os.environ.get("DGSE_REFERENCE_CASES", Path(__file__).resolve().parents[2] / "shared" / "reference-cases")
)


def _seeds(text: str) -> list[int]:
    """:func:`dgse.bench.scenarios.parse_seeds` as an argparse type."""
    try:
        return parse_seeds(text)
    except InputDataError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


_parser = partial(command_parser, "phys.py")


def phys_option_args(
    ap: argparse.ArgumentParser, items: Sequence[str], base: dict[str, Any] | None = None
) -> dict[str, Any]:
    """``base`` updated with the ``-E KEY=VALUE`` items: dgse-phys options (dotted keys of its
    settings), checked by building the estimator once, so that a wrong key or value is a usage
    error before anything is estimated."""
    try:
        options = {**(base or {}), **parse_params(items, "-E")}
        get_estimator("dgse-phys", **options)
    except InputDataError as exc:
        ap.error(str(exc))
    return options


# ------------------------------------------------------------------------------------------ gsl
#: The reading counts and rows of ``gsl``.
GSL_COUNTS = [5, 20, 50, 150, 300]
GSL_METHODS = [
    ("dgse-s", "map"),
    ("dgse-phys", "map"),
    ("adjoint", "openings"),
    ("dgse-phys", "openings"),
    ("dgse-phys", "wind"),
    ("adjoint-oracle", "wind"),
]
GSL_TEST_SEEDS = range(2000, 2008)
#: the generated scenarios of each set but ``reference`` (OpenFOAM's cases), and each set's seed
#: of the readings: ``fresh`` is a second draw of test scenarios and readings
GSL_SCENARIOS = {"test": GSL_TEST_SEEDS, "fresh": range(2008, 2016)}
GSL_READING_SEEDS = {"reference": 0, "test": 0, "fresh": 11}


def _gsl_test_cases(out: Path, name: str = "test") -> Path:
    """The generated scenarios of set ``name`` as case files (made once)."""
    from dgse.physics.scenario import random_cases

    d = out / f"_{name}_cases"
    d.mkdir(parents=True, exist_ok=True)
    for seed in GSL_SCENARIOS[name]:
        path = d / f"test{seed}_src0.npz"
        if not path.exists():
            random_cases(seed, n_sources=1)[0].save(path)
    return d


#: (row, against it, the goal): paired on the same case, count and trial
GSL_PAIRS = [
    ("dgse-phys@openings", "adjoint-oracle@wind", "within 10 % of the oracle from 50 readings on"),
    ("dgse-phys@openings", "dgse-s@map", "better than DGSE-S at every count"),
    ("dgse-phys@map", "dgse-s@map", "better than DGSE-S at every count"),
    ("dgse-phys@map", "adjoint-oracle@wind", "goal: within 1.5x of the oracle at 150 and 300"),
]


def _gsl_comparisons(per_estimate: dict[str, dict[str, dict[tuple, float]]]) -> list[str]:
    """Mean SL error ratios of :data:`GSL_PAIRS` on the estimates both rows have, with the paired
    difference's mean and standard error (m).  ``per_estimate``: ``{set: {row: {(case, n_obs,
    trial): SL error}}}``."""
    lines: list[str] = []
    for name, errors in per_estimate.items():
        rows = [(a, b, goal) for a, b, goal in GSL_PAIRS if a in errors and b in errors]
        if not rows:
            continue
        lines += [
            f"## {name}: paired comparisons",
            "",
            "mean SL error ratio A / B (paired difference A - B, m, mean +- standard error; estimates)",
            "",
            "| A | B | " + " | ".join(str(n) for n in GSL_COUNTS) + " | asked |",
            "|---|---|" + "---|" * len(GSL_COUNTS) + "---|",
        ]
        for a, b, goal in rows:
            cells = []
            for n in GSL_COUNTS:
                keys = sorted(k for k in errors[a] if k[1] == n and k in errors[b])
                x = np.array([errors[a][k] for k in keys])
                y = np.array([errors[b][k] for k in keys])
                if len(keys) < 2:
                    cells.append("-")
                    continue
                d = x - y
                se = d.std(ddof=1) / np.sqrt(len(d))
                cells.append(f"{x.mean() / y.mean():.2f} ({d.mean():+.2f} +- {se:.2f}; {len(d)})")
            lines.append(f"| {a} | {b} | " + " | ".join(cells) + f" | {goal} |")
        lines.append("")
    return lines


def gsl(argv: list[str]) -> None:
    """``gsl``: source localization from random readings per knowledge level (module doc)."""
    from dgse.bench.parallel import evaluate_parallel

    ap = _parser("gsl", "source localization from random readings per knowledge level")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "phys_gsl")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument(
        "--sets", nargs="+", default=["reference", "test"], choices=["reference", "test", "fresh"]
    )
    ap.add_argument(
        "--methods",
        nargs="+",
        default=None,
        metavar="METHOD@LEVEL",
        help="only these rows, e.g. dgse-phys@openings adjoint-oracle@wind (default: all)",
    )
    ap.add_argument("--reference", type=Path, default=REFERENCE)
    ap.add_argument("--summary-only", action="store_true", help="summarize the folder's results, run nothing")
    ap.add_argument(
        "--workers", type=int, default=1, help="processes, one case and count of a row each (module doc)"
    )
    ap.add_argument("--rounds", type=int, default=None, help="with --workers: trials per round (default all)")
    ap.add_argument("--time-limit", type=float, default=None, help="with --workers: stop after this many s")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = GSL_METHODS
    if args.methods:
        known = {f"{m}@{lv}": (m, lv) for m, lv in GSL_METHODS}
        bad = [x for x in args.methods if x not in known]
        if bad:
            ap.error(f"unknown rows {bad}; choose from {sorted(known)}")
        rows = [known[x] for x in args.methods]
    table: dict = {}
    sets = [] if args.summary_only else args.sets
    sources = {
        name: args.reference if name == "reference" else _gsl_test_cases(args.out, name) for name in sets
    }
    if args.workers < 1 or (args.rounds is not None and args.rounds < 1):
        ap.error("--workers and --rounds must be at least 1")
    if args.workers > 1 and "fresh" in sets:
        ap.error("--sets fresh runs with one worker (its readings have their own seed)")
    if sets and args.workers > 1:
        try:
            done = evaluate_parallel(
                rows,
                sources,
                args.out,
                GSL_COUNTS,
                args.trials,
                args.workers,
                args.rounds or args.trials,
                args.time_limit,
            )
        except KeyboardInterrupt:
            raise SystemExit(
                "interrupted: the finished estimates are kept; the same command resumes"
            ) from None
        if not done:
            print("stopped by --time-limit; the finished estimates are kept and the same command resumes")
            return
    for name in sets:
        for method, level in rows:
            out = args.out / f"{name}_{method}_{level}.json"
            res = evaluate(
                sources[name], method, GSL_COUNTS, trials=args.trials, seed=GSL_READING_SEEDS[name],
                knowledge=level,
                journal=journal_path(out), progress=True,
            )  # fmt: skip
            write_json(res, out)
    # the summary covers every row in the folder, this run's and earlier runs' (one method per
    # process is the way to use both cores)
    per_estimate: dict[str, dict[str, dict[tuple, float]]] = {}
    for name in ("reference", "test", "fresh"):
        for method, level in GSL_METHODS:
            path = args.out / f"{name}_{method}_{level}.json"
            if not path.exists():
                continue
            res = json.loads(path.read_text())
            per_estimate.setdefault(name, {})[f"{method}@{level}"] = {
                (r["case"], r["n_obs"], r["trial"]): r["sl_error_m"] for r in res["per_case"]
            }
            seconds = [r["seconds"] for r in res["per_case"] if r.get("seconds") is not None]
            table.setdefault(name, {})[f"{method}@{level}"] = {
                "trials": res["trials"],
                "median_seconds": float(np.median(seconds)) if seconds else None,
                **{
                    n: {
                        k: res["aggregate"][str(n)].get(k)
                        for k in ("sl_error_m_mean", "sl_error_m_median", "ce_mean")
                    }
                    for n in GSL_COUNTS
                },
            }
    lines = []
    for name, rows in table.items():
        lines += [
            f"## {name}",
            "",
            "SL error mean / median (m), CE mean (nats); trials per case; the median seconds an estimate "
            "took (as the run was made: with --workers N, N estimates at a time)",
            "",
        ]
        lines.append(
            "| method@knowledge | trials | " + " | ".join(str(n) for n in GSL_COUNTS) + " | median s |"
        )
        lines.append("|---|---|" + "---|" * (len(GSL_COUNTS) + 1))
        for key, by_n in rows.items():
            cells = [
                f"{v['sl_error_m_mean']:.2f} / {v['sl_error_m_median']:.2f} / {v['ce_mean']:.1f}"
                for n, v in by_n.items()
                if n in GSL_COUNTS
            ]
            secs = by_n["median_seconds"]
            cells.append("-" if secs is None else f"{secs:.2f}")
            lines.append(f"| {key} | {by_n['trials']} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += _gsl_comparisons(per_estimate)
    write_text(args.out / "summary.md", "\n".join(lines))
    write_text(args.out / "summary.json", json.dumps(table, indent=1))
    print("\n".join(lines))


# ---------------------------------------------------------------------------- robustness
#: The default scenarios, counts and rows of ``robustness``.
ROBUSTNESS_SEEDS = range(2000, 2008)
ROBUSTNESS_COUNTS = (20, 50, 150)
ROBUSTNESS_METHODS = (
    ("dgse-s", "map"),
    ("dgse-phys", "map"),
    ("dgse-phys", "openings"),
    ("dgse-phys", "wind"),
)


def robustness_summary(out: Path, trials: int) -> None:
    """``summary.md`` / ``summary.json`` from the journals (what they hold so far of the first ``trials``)."""
    rows = [r for r in journal_rows(out).values() if r["trial"] < trials]  # the trials the summary covers
    if not rows:
        raise SystemExit(f"no estimates of trials below {trials} in the journals of {out}")
    cases = sorted({r["case"] for r in rows})
    # journals name a generated scenario test<seed>, a case file by its stem (--cases)
    seeds = sorted(int(c.removeprefix("test")) for c in cases if c.removeprefix("test").isdigit())
    where = (
        f"{len(cases)} scenarios, seeds {seeds[0]}-{seeds[-1]}"
        if len(seeds) == len(cases)
        else f"{len(cases)} case files ({', '.join(cases)})"
    )
    counts = sorted({r["n"] for r in rows})
    summary: dict[str, Any] = {}
    sizes: set[int] = set()
    lines = [
        "# dgse-phys where the physics is wrong",
        "",
        f"`python benchmarks/phys.py robustness` ({where}, "
        f"up to {trials} trials each; the counts in brackets say how many estimates): "
        "SL error mean / median (m), source CE mean (nats), and the "
        "calibration error of the source posterior's highest-density credible sets "
        "(mean |coverage - level|, `dgse.evaluation.calibration`).",
        "",
    ]
    for variant in VARIANTS:
        vr = [r for r in rows if r["variant"] == variant]
        if not vr:
            continue
        lines += [f"## {variant}", "", "| method@knowledge | " + " | ".join(map(str, counts)) + " |"]
        lines.append("|---" * (len(counts) + 1) + "|")
        for method, level in ROBUSTNESS_METHODS:
            cells = []
            for n in counts:
                rr = [r for r in vr if r["method"] == method and r["knowledge"] == level and r["n"] == n]
                if not rr:
                    cells.append("-")
                    continue
                sl, ce = summarize(r["sl_m"] for r in rr), summarize(r["ce"] for r in rr)
                levels = [r["credible_level"] for r in rr]
                ece = calibration_error(coverage_curve(levels))
                sizes.add(len(rr))
                summary.setdefault(variant, {}).setdefault(f"{method}@{level}", {})[str(n)] = {
                    "sl_m": sl,
                    "ce": ce,
                    "credible_set_calibration_error": ece,
                    # 0.5 when calibrated; above: the truth sits in the tails (overconfident)
                    "mean_credible_level_of_truth": float(np.mean(levels)),
                }
                cell = f"{sl['mean']:.2f} / {sl['median']:.2f} / {ce['mean']:.1f} / {ece:.2f}"
                cells.append(f"{cell} ({len(rr)})")
            if any(c != "-" for c in cells):
                lines.append(f"| {method}@{level} | " + " | ".join(cells) + " |")
        lines.append("")
    chance = {str(k): round(chance_calibration_error(k), 3) for k in sorted(sizes)}
    summary["chance_calibration_error"] = chance
    lines.append(
        "A perfectly calibrated posterior would show a calibration error of about "
        + ", ".join(f"{v:.2f} on {k}" for k, v in chance.items())
        + " estimates (sampling noise alone, `chance_calibration_error`)."
    )
    write_text(out / "summary.json", json.dumps(summary, indent=1))
    write_text(out / "summary.md", "\n".join(lines))
    print("\n".join(lines))


def journal_rows(out: Path) -> dict[tuple, dict[str, Any]]:
    """Every estimate of a run's journals by (variant, method, level, case, n, trial)."""
    journals = sorted(out.glob("journal*.jsonl"))
    rows = (json.loads(line) for j in journals for line in j.read_text().splitlines())
    return {(r["variant"], r["method"], r["knowledge"], r["case"], r["n"], r["trial"]): r for r in rows}


def paired_summary(out: Path, against: Path) -> str:
    """The run in ``out`` against the one in ``against``, over the estimates both made (the
    same readings): per variant, method and count, each run's mean SL error (m), mean CE
    (nats), calibration error and the truth's mean credible level, and the paired differences
    of the SL error and CE (``out`` minus ``against``, mean +- standard error).  Written to
    ``out/paired.md``."""
    new, old = journal_rows(out), journal_rows(against)
    cells: dict[tuple, list[tuple]] = {}
    for key in sorted(set(new) & set(old)):
        cells.setdefault((key[0], f"{key[1]}@{key[2]}", key[4]), []).append(key)
    if not cells:
        raise SystemExit(f"{out} and {against} have no estimate in common")

    def stats(rows: dict[tuple, dict[str, Any]], keys: list[tuple]) -> tuple[np.ndarray, np.ndarray, str]:
        sl = np.array([rows[k]["sl_m"] for k in keys])
        ce = np.array([rows[k]["ce"] for k in keys])
        levels = [rows[k]["credible_level"] for k in keys]
        text = f"{sl.mean():.2f} / {ce.mean():.2f} / {calibration_error(coverage_curve(levels)):.3f} / "
        return sl, ce, text + f"{np.mean(levels):.2f}"

    lines = [
        f"# {out} against {against}",
        "",
        "`python benchmarks/phys.py robustness -o OUT --paired AGAINST` over the estimates both runs "
        "made (the same readings). Each run: mean SL error (m) / mean CE (nats) / calibration error / "
        "the truth's mean credible level (0.5 when calibrated); then the paired differences "
        "(this run minus the other, mean +- standard error).",
        "",
        "| variant | method@knowledge | n | estimates | this run | the other | SL difference (m) "
        "| CE difference |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (variant, method, n), keys in sorted(cells.items()):
        (sl_a, ce_a, text_a), (sl_b, ce_b, text_b) = stats(new, keys), stats(old, keys)
        root = math.sqrt(len(keys))
        d_sl, d_ce = sl_a - sl_b, ce_a - ce_b
        se_sl, se_ce = (float(d.std(ddof=1)) / root if d.size > 1 else math.nan for d in (d_sl, d_ce))
        lines.append(
            f"| {variant} | {method} | {n} | {len(keys)} | {text_a} | {text_b} | "
            f"{d_sl.mean():+.3f} +- {se_sl:.3f} | {d_ce.mean():+.2f} +- {se_ce:.2f} |"
        )
    text = "\n".join(lines) + "\n"
    write_text(out / "paired.md", text)
    return text


def robustness(argv: list[str]) -> None:
    """``robustness``: dgse-phys where its physics is wrong (module doc)."""
    ap = _parser("robustness", "dgse-phys where its physics is wrong: filament readings and perturbed winds")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    names = [f"{m}@{k}" for m, k in ROBUSTNESS_METHODS]
    ap.add_argument("--methods", nargs="+", default=names, choices=names, help="method@knowledge")
    ap.add_argument(
        "--seeds",
        type=_seeds,
        default=list(ROBUSTNESS_SEEDS),
        help="scenario seeds, e.g. 2000-2019 (test) or 900-923 (validation)",
    )
    ap.add_argument(
        "--cases",
        type=Path,
        nargs="+",
        default=None,
        help="case files to use instead of the generated scenarios (e.g. ../shared/reference-cases/*.npz)",
    )
    ap.add_argument(
        "--counts", type=int, nargs="+", default=list(ROBUSTNESS_COUNTS), help="numbers of readings"
    )
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "phys_robustness")
    ap.add_argument(
        "--cache", type=Path, default=None, help="where scenario files are kept (default: OUT/_cases)"
    )
    ap.add_argument(
        "--tag", default="", help="this process's journal is journal-TAG.jsonl (the summary reads all)"
    )
    ap.add_argument(
        "-E",
        "--estimator-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a dgse-phys option, e.g. -E evidence.effective_readings=50 (repeatable; its own -o)",
    )
    ap.add_argument("--summary-only", action="store_true", help="summarize the journal, estimate nothing")
    ap.add_argument(
        "--paired",
        type=Path,
        default=None,
        metavar="DIR",
        help="compare OUT's estimates with another run's on the same readings (writes OUT/paired.md)",
    )
    args = ap.parse_args(argv)
    if any(n < 1 for n in args.counts):
        ap.error("--counts must be positive")
    phys_options = phys_option_args(ap, args.estimator_option)
    if args.paired is not None:
        print(paired_summary(args.out, args.paired))
        return
    if args.summary_only:
        robustness_summary(args.out, args.trials)
        return
    from dgse.physics.scenario import random_cases

    args.out.mkdir(parents=True, exist_ok=True)
    cache = args.cache or args.out / "_cases"
    cache.mkdir(parents=True, exist_ok=True)
    journal = args.out / (f"journal-{args.tag}.jsonl" if args.tag else "journal.jsonl")
    done = set()
    if journal.exists():
        for line in journal.read_text().splitlines():
            r = json.loads(line)
            done.add((r["variant"], r["method"], r["knowledge"], r["case"], r["n"], r["trial"]))
    estimators: dict[tuple[str, str], Any] = {}
    with journal.open("a") as jf:
        if args.cases is not None:
            items = [(path.stem, path) for path in args.cases]
        else:
            items = [(f"test{seed}", cache / f"test{seed}.npz") for seed in args.seeds]
        for case_id, path in items:
            if args.cases is None and not path.exists():
                random_cases(int(case_id.removeprefix("test")), n_sources=1)[0].save(path)
            base = Case.load(path)
            for variant in args.variants:
                truth = variant_case(base, variant, cache, case_id)
                told = replace(base, wind=perturbed_wind(base, variant))
                for n in args.counts:
                    for trial in range(args.trials):
                        obs = draw_observations(truth, n, seed=0, case_id=case_id, trial=trial)
                        for method, level in ROBUSTNESS_METHODS:
                            if f"{method}@{level}" not in args.methods:
                                continue
                            if variant.startswith("wind_") and level != "wind":
                                continue  # only the wind level reads the perturbed field
                            key = (variant, method, level, case_id, n, trial)
                            if key in done:
                                continue
                            est = estimators.get((method, level))
                            if est is None:
                                kw = (
                                    {"dtype": "bf16", "channels_last": True}
                                    if method == "dgse-s"
                                    else dict(phys_options)
                                )
                                est = estimators[(method, level)] = get_estimator(method, **kw)
                            est.set_knowledge(Knowledge.from_case(told, level))
                            t0 = time.perf_counter()
                            b = est.estimate(base.occupancy, base.resolution, obs)
                            seconds = time.perf_counter() - t0  # with the flows it solves for this map
                            rec = {
                                "variant": variant,
                                "method": method,
                                "knowledge": level,
                                "case": case_id,
                                "n": n,
                                "trial": trial,
                                "sl_m": source_localization_error(b, base.source),
                                "ce": source_cross_entropy(b, base.source_cell),
                                "credible_level": credible_level(b.source_probs, base.source_cell),
                                "seconds": seconds,
                            }
                            if method == "dgse-phys" and phys_options:
                                rec["options"] = phys_options
                            jf.write(json.dumps(rec) + "\n")
                            jf.flush()
                            print(json.dumps(rec), flush=True)
    robustness_summary(args.out, args.trials)


# ---------------------------------------------------------------- calibration and fusion
def tuning_parser(command: str, what: str, out: Path, counts: list[int]) -> argparse.ArgumentParser:
    """The arguments ``calibration`` and ``fusion`` take (validation seeds, counts, trials,
    variants, knowledge level, output, case cache, ``-E`` estimator options, ``--summary-only``);
    their readings are ``robustness``'s (same scenarios, same draws), validation only."""
    ap = _parser(command, what)
    ap.add_argument("--seeds", type=_seeds, default=parse_seeds("900-923"))
    ap.add_argument("--counts", type=int, nargs="+", default=counts)
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument(
        "--variants",
        nargs="+",
        default=["steady", "filament"],
        choices=VARIANTS,
        help="as robustness: the wind_* ones change the wind told at --knowledge wind",
    )
    ap.add_argument("--knowledge", default="openings", choices=["map", "openings", "wind"])
    ap.add_argument("-o", "--out", type=Path, default=out)
    ap.add_argument(
        "--cache",
        type=Path,
        default=RESULTS / "phys_robustness" / "_cases_validation",
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
    return phys_option_args(ap, args.estimator_option, base)


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


def posterior_scores(p: np.ndarray, case: Case) -> dict[str, float]:
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
    """The calibration error, mean SL error and mean CE of estimates' :func:`posterior_scores`, as a
    record (with the truth's mean credible level: 0.5 when calibrated, below when too flat)
    and as the summaries' ``"cal / sl / ce"`` text."""
    levels = [g["credible_level"] for g in got]
    ce = calibration_error(coverage_curve(levels))
    sl = float(np.mean([g["sl_m"] for g in got]))
    xe = float(np.mean([g["ce"] for g in got]))
    mean_level = float(np.mean(levels))
    record = {"calibration_error": ce, "sl_mean_m": sl, "ce_mean": xe, "mean_credible_level": mean_level}
    return record, f"{ce:.3f} / {sl:.2f} / {xe:.2f}"


#: The flattening powers ``calibration`` scores.
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
    """The neighbour correlation (:func:`neighbour_correlation`) of the gas readings'
    standardized residuals about the belief's most probable source, per radius of
    :data:`CORRELATION_RADII` (``"corr1"``: 1 m)."""
    from dgse.posterior.mixture import standardized_residuals
    from dgse.world.grid import Grid

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
    ``corr1``: :func:`residual_statistics`; a journal that lacks the last two, as the earliest
    recorded ones do, scores their rules as no flattening)."""
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


def calibration_summary(out: Path) -> None:
    """``OUT/summary.{json,md}`` of a ``calibration`` run's journal."""
    rows = [json.loads(x) for x in (out / "journal.jsonl").read_text().splitlines()]
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["variant"], r["n"]), []).append(r)
    summary: dict[str, Any] = {"estimates": len(rows), "taus": list(TAUS), "cells": []}
    lines = [
        "# Flattening dgse-phys's source posterior (validation scenarios)",
        "",
        "`python benchmarks/phys.py calibration` (module doc). Per variant and count: "
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


def calibration(argv: list[str]) -> None:
    """``calibration``: how much to flatten dgse-phys's source posterior, and when (module doc)."""
    ap = tuning_parser(
        "calibration",
        "how much to flatten dgse-phys's source posterior, and when (validation scenarios)",
        RESULTS / "phys_calibration_tuning",
        [50, 150],
    )
    args = ap.parse_args(argv)
    # the estimator's posterior (it flattens nothing): the rules are applied afterwards
    options = checked_options(ap, args, {})
    args.out.mkdir(parents=True, exist_ok=True)
    if args.summary_only:
        calibration_summary(args.out)
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
                "tau": {f"{t:g}": posterior_scores(flattened(b.source_probs, t), case) for t in TAUS},
                "seconds": b.info["seconds"],
            }
            jf.write(json.dumps(rec) + "\n")
            jf.flush()
            print(json.dumps({k: rec[k] for k in ("variant", "case", "n", "trial", "fit")}), flush=True)
    calibration_summary(args.out)


#: The network's weights in the mixture ``(1 - w) physics + w network`` that ``fusion`` scores.
FUSION_WEIGHTS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)


def fusion_summary(out: Path) -> None:
    """``OUT/summary.{json,md}`` of a ``fusion`` run's journals."""
    groups: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
    for path in sorted(out.glob("journal-*.jsonl")):
        for line in path.read_text().splitlines():
            r = json.loads(line)
            groups.setdefault((r["knowledge"], r["variant"], r["n"]), []).append(r)
    summary: dict[str, Any] = {"weights": list(FUSION_WEIGHTS), "cells": []}
    lines = [
        "# DGSE-S's weight in dgse-phys's source posterior (validation scenarios)",
        "",
        "`python benchmarks/phys.py fusion` (module doc): calibration error / mean SL error (m) / "
        "mean CE (nats) of `(1 - w) physics + w network`; the last column is the chance calibration error.",
        "",
        "| level | variant | n | estimates | "
        + " | ".join(f"w {w:g}" for w in FUSION_WEIGHTS)
        + " | chance |",
        "|---|---|---|---|" + "---|" * len(FUSION_WEIGHTS) + "---|",
    ]
    for (level, variant, n), rr in sorted(groups.items()):
        cell: dict[str, Any] = {"knowledge": level, "variant": variant, "n": n, "estimates": len(rr)}
        texts = []
        for w in FUSION_WEIGHTS:
            cell[f"w {w:g}"], text = pooled([r["by_weight"][f"{w:g}"] for r in rr])
            texts.append(text)
        chance = chance_calibration_error(len(rr))
        cell["chance_calibration_error"] = chance
        summary["cells"].append(cell)
        lines.append(f"| {level} | {variant} | {n} | {len(rr)} | " + " | ".join(texts) + f" | {chance:.3f} |")
    write_text(out / "summary.json", json.dumps(summary, indent=1) + "\n")
    write_text(out / "summary.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


def fusion(argv: list[str]) -> None:
    """``fusion``: how much of DGSE-S's source belief to keep in dgse-phys's (module doc)."""
    ap = tuning_parser(
        "fusion",
        "how much of DGSE-S's source belief to keep in dgse-phys's, by level and count (validation)",
        RESULTS / "phys_fusion_tuning",
        [20, 50, 150],
    )
    args = ap.parse_args(argv)
    # the physics alone: the mixtures are formed here
    options = checked_options(ap, args, {"fusion.weight": 0.0, "fusion.floor": 0.0})
    args.out.mkdir(parents=True, exist_ok=True)
    if args.summary_only:
        fusion_summary(args.out)
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
            mixed = {f"{w:g}": posterior_scores((1 - w) * p_phys + w * p_net, case) for w in FUSION_WEIGHTS}
            jf.write(json.dumps({**key, "options": recorded, "by_weight": mixed}) + "\n")
            jf.flush()
            print(f"{key['variant']} {key['case']} n={key['n']} trial {key['trial']}", flush=True)
    fusion_summary(args.out)


# -------------------------------------------------------------------------------- fields
#: The grids of ``fields``: wind ``(a, b)``, log-concentration ``(c, d)`` (``field_error_variance``).
A_GRID = (0.0, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0)
B_GRID = (0.0, 0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0)
C_GRID = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0)
D_GRID = (0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0)
#: Free cells ``fields`` samples per estimate.
FIELD_CELLS = 3000


def fields_collect(level: str, seeds: list[int], counts: list[int]) -> dict[int, dict[str, np.ndarray]]:
    """Per count: pooled truth, mean and hypotheses' spread of both fields on sampled free cells."""
    from dgse.physics.scenario import random_cases

    out: dict[int, dict[str, list]] = {n: {} for n in counts}
    for seed in seeds:
        t0 = time.perf_counter()
        case = random_cases(seed, n_sources=1)[0]
        k = Knowledge.from_case(case, level)
        est = get_estimator("dgse-phys", knowledge=k, **{"fields.model_error": (0, 0, 0, 0)})
        free = np.argwhere(case.occupancy == 0)
        rng = np.random.default_rng(seed)
        pick = free[rng.choice(len(free), size=min(FIELD_CELLS, len(free)), replace=False)]
        i, j = pick[:, 0], pick[:, 1]
        logc = np.log1p(np.maximum(case.concentration, 0.0))
        for n in counts:
            b = est.estimate(case.occupancy, case.resolution, draw_observations(case, n, seed=0))
            assert b.wind_mean is not None and b.wind_var is not None
            assert b.log_conc_mean is not None and b.log_conc_var is not None
            rows = {
                "wind_true": case.wind[:, i, j],
                "wind_mean": b.wind_mean[:, i, j],
                "wind_spread": b.wind_var[:, i, j],
                "conc_true": logc[i, j],
                "conc_mean": b.log_conc_mean[i, j],
                "conc_spread": b.log_conc_var[i, j],
            }
            for k, v in rows.items():
                out[n].setdefault(k, []).append(v)
        print(f"{level} scenario {seed}: {time.perf_counter() - t0:.0f} s", flush=True)
    return {n: {k: np.concatenate(v, axis=-1) for k, v in d.items()} for n, d in out.items()}


def field_scores(truth: np.ndarray, mean: np.ndarray, var: np.ndarray) -> dict[str, float]:
    """Mean Gaussian NLL and the coverage of the 1 and 2 sigma intervals."""
    v = np.maximum(var, 1e-12)
    z = np.abs(truth - mean) / np.sqrt(v)
    nll = 0.5 * (np.log(2 * math.pi * v) + (truth - mean) ** 2 / v)
    cov = {f"cov_{k}sigma": float((z <= k).mean()) for k in (1, 2)}
    return {"nll": float(nll.mean()), **cov}


def fields_fit(data: dict[int, dict[str, np.ndarray]]) -> tuple[float, float, float, float]:
    """``(a, b, c, d)`` of the best pooled log likelihood over every count."""
    from dgse.posterior.mixture import field_error_variance

    pooled = {k: np.concatenate([d[k] for d in data.values()], axis=-1) for k in next(iter(data.values()))}
    best_w, best_c = (math.inf, 0.0, 0.0), (math.inf, 0.0, 0.0)
    for a, b in itertools.product(A_GRID, B_GRID):
        w_err, _ = field_error_variance(pooled["wind_mean"], pooled["conc_mean"], (a, b, 0, 0))
        s = field_scores(pooled["wind_true"], pooled["wind_mean"], pooled["wind_spread"] + w_err)["nll"]
        best_w = min(best_w, (s, a, b))
    for c, d in itertools.product(C_GRID, D_GRID):
        _, c_err = field_error_variance(pooled["wind_mean"], pooled["conc_mean"], (0, 0, c, d))
        s = field_scores(pooled["conc_true"], pooled["conc_mean"], pooled["conc_spread"] + c_err)["nll"]
        best_c = min(best_c, (s, c, d))
    return best_w[1], best_w[2], best_c[1], best_c[2]


def fields_report(data: dict[int, dict[str, np.ndarray]], params: tuple[float, float, float, float]) -> dict:
    """Coverage and NLL per count with the spread alone and with the model error ``params``."""
    from dgse.posterior.mixture import field_error_variance

    rows = {}
    for n, d in data.items():
        w_err, c_err = field_error_variance(d["wind_mean"], d["conc_mean"], params)
        rows[str(n)] = {
            "wind_spread_only": field_scores(d["wind_true"], d["wind_mean"], d["wind_spread"]),
            "wind_with_error": field_scores(d["wind_true"], d["wind_mean"], d["wind_spread"] + w_err),
            "conc_spread_only": field_scores(d["conc_true"], d["conc_mean"], d["conc_spread"]),
            "conc_with_error": field_scores(d["conc_true"], d["conc_mean"], d["conc_spread"] + c_err),
        }
    return rows


def fields(argv: list[str]) -> None:
    """``fields``: dgse-phys's field model error per knowledge level (module doc)."""
    ap = _parser("fields", "choose dgse-phys's field model error on generated validation scenarios")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "phys_field_tuning.json")
    ap.add_argument("--levels", nargs="*", default=["openings", "wind", "map"])
    ap.add_argument("--seeds", type=int, nargs="*", default=list(range(900, 912)))
    ap.add_argument("--counts", type=int, nargs="*", default=[25, 100, 300])
    args = ap.parse_args(argv)
    result = json.loads(args.out.read_text()) if args.out.exists() else {}
    result.update({"seeds": args.seeds, "counts": args.counts, "cells_per_estimate": FIELD_CELLS})
    result.setdefault("levels", {})
    for level in args.levels:
        data = fields_collect(level, args.seeds, args.counts)
        params = fields_fit(data)
        rows = fields_report(data, params)
        result["levels"][level] = {"field_error": list(params), "by_count": rows}
        print(f"{level}: fields.model_error (a, b, c, d) = {params}")
        for n, r in rows.items():
            cov = {k: f"{v['cov_1sigma']:.2f}/{v['cov_2sigma']:.2f}" for k, v in r.items()}
            print(
                f"  {n:>4} readings, 1/2 sigma coverage: wind {cov['wind_spread_only']} -> "
                f"{cov['wind_with_error']}; log-conc {cov['conc_spread_only']} -> {cov['conc_with_error']}"
            )
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_text(args.out, json.dumps(result, indent=1))  # after each level: nothing lost
    print(f"wrote {args.out}")


# --------------------------------------------------------------------------------- sweep
def sweep(
    level: str,
    settings: Sequence[Any],
    options: Callable[[Any], dict[str, Any]],
    seeds: Iterable[int],
    counts: Sequence[int],
    trials: int = 1,
) -> tuple[dict, dict]:
    """``(errors, cross-entropies)`` per ``(setting, count)`` of ``dgse-phys`` at knowledge ``level``.

    For every generated scenario (one source), count and trial the same readings go to a
    fresh estimator per setting (``options(setting)`` are its keyword arguments), which solves
    its own flows (and at ``map`` proposes its own openings, from the same readings): the
    settings differ in nothing else.
    """
    from dgse.physics.scenario import random_cases

    err: dict = defaultdict(list)
    ce: dict = defaultdict(list)
    for seed in seeds:
        case = random_cases(seed, n_sources=1)[0]
        k = Knowledge.from_case(case, level)
        cell = case.layout.grid.cell_of(*case.source)
        for n in counts:
            for trial in range(trials):
                obs = draw_observations(case, n, seed=trial)
                for s in settings:
                    est = get_estimator("dgse-phys", knowledge=k, **options(s))
                    b = est.estimate(case.occupancy, case.resolution, obs)
                    err[s, n].append(b.localization_error(tuple(case.source)))
                    ce[s, n].append(-float(np.log(max(b.source_probs[cell], 1e-12))))
        print(f"scenario {seed} done", flush=True)
    return err, ce


def write_sweep(
    out: Path, err: dict, ce: dict, settings: Sequence[Any], counts: Sequence[int], header: dict
) -> dict[str, dict]:
    """Mean/median SL error and mean CE per (setting, count): printed, and written to ``out`` as JSON."""
    rows = {
        str(s): {
            str(n): {
                "sl_error_m_mean": float(np.mean(err[s, n])),
                "sl_error_m_median": float(np.median(err[s, n])),
                "ce_mean": float(np.mean(ce[s, n])),
            }
            for n in counts
        }
        for s in settings
    }
    for name, by_n in rows.items():
        print(
            f"{name:14s} "
            + " | ".join(
                f"{n}: SL {v['sl_error_m_mean']:.2f}/{v['sl_error_m_median']:.2f} CE {v['ce_mean']:.2f}"
                for n, v in by_n.items()
            )
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text(out, json.dumps({**header, "rows": rows}, indent=1))
    print(f"wrote {out}")
    return rows


#: The sweeps of ``sweep NAME``: ``(level, settings by name, scenario seeds, counts, trials,
#: default output)``; a setting is the dgse-phys options it runs with.
SWEEPS: dict[str, tuple[str, dict[str, dict[str, Any]], range, tuple[int, ...], int, str]] = {
    # the tempering at ``openings``: the gas evidence divided by T = max(1, m / effective_readings)
    # (``T=1``: never tempered); the constant temperatures of the recorded file are removed
    "temperature": (
        "openings",
        {
            "T=1" if math.isinf(m) else f"m_eff={m:g}": {
                "evidence.effective_readings": m,
                "evidence.effective_growth": 0.0,
            }
            for m in (math.inf, 50.0, 100.0)
        },
        range(900, 912),
        (20, 50, 150, 300),
        2,
        "phys_temperature.json",
    ),
    # how much the physics is trusted at ``map``: the readings the gas evidence counts
    # (T = m / effective_readings; the recorded file's rows ``(None, E)``); the tempering of the
    # flow hypotheses' weights it also compared (``(5.0, 100.0)``) is removed
    "map": (
        "map",
        {
            f"m_eff={m:g}": {"evidence.effective_readings": m, "evidence.effective_growth": 0.0}
            for m in (100.0, 30.0, 10.0, 3.0)
        },
        range(900, 908),
        (20, 50, 150),
        1,
        "phys_map_tuning.json",
    ),
    # DGSE-S's weight in the source posterior at ``map``: weight * max(0, 1 - m / readings)
    # (``fusion.weight``, ``fusion.readings``; no floor at weight 0, as this was measured)
    "learned": (
        "map",
        {
            str((w, m)): {
                "fusion.weight.map": w,
                "fusion.readings": m,
                **({"fusion.floor": 0.0} if w == 0 else {}),
            }
            for w, m in ((0.0, 20.0), (0.5, 20.0), (0.9, 20.0), (0.5, 50.0), (0.9, 50.0), (1.0, 1e9))
        },
        range(900, 908),
        (5, 10, 20, 40),
        1,
        "phys_learned_tuning.json",
    ),
}


def sweep_cmd(argv: list[str]) -> None:
    """``sweep NAME``: settings of dgse-phys compared on the same validation readings (module doc)."""
    ap = _parser("sweep", "settings of dgse-phys compared on the same readings of validation scenarios")
    ap.add_argument("name", choices=sorted(SWEEPS))
    ap.add_argument(
        "-o", "--out", type=Path, default=None, help="default: benchmarks/results/<the sweep's file>"
    )
    args = ap.parse_args(argv)
    level, settings, seeds, counts, trials, file = SWEEPS[args.name]
    names = list(settings)
    err, ce = sweep(level, names, settings.__getitem__, seeds, counts, trials=trials)
    write_sweep(args.out or RESULTS / file, err, ce, names, counts, {"seeds": list(seeds), "trials": trials})


# ------------------------------------------------------------- projection and turbulence
#: The validation scenarios of ``projection``.
PROJECTION_SEEDS = range(900, 908)


def projection_settings() -> list[tuple[bool, str, float | None, float | None]]:
    """``projection``'s settings: (openings known?, closure, open_fraction, frozen k-epsilon tolerance)."""
    from dgse.physics.projection import TURBULENCE_TOLERANCE

    return [
        (True, "k-epsilon", None, TURBULENCE_TOLERANCE),
        (True, "k-epsilon", None, 1e-4),
        (True, "mixing-length", None, None),
        *[(False, "k-epsilon", f, TURBULENCE_TOLERANCE) for f in (0.1, 0.3, 0.5, 0.75, 1.0, 1.5)],
        (False, "k-epsilon", 0.75, 1e-4),
        (False, "mixing-length", 0.75, None),
    ]


def log_rmse(c: np.ndarray, truth: np.ndarray, free: np.ndarray) -> float:
    d = np.log1p(np.maximum(c, 0.0)) - np.log1p(truth)
    return float(np.sqrt(np.mean(d[free] ** 2)))


def projection(argv: list[str]) -> None:
    """``projection``: the settings of dgse.physics.projection on validation scenarios (module doc)."""
    from dgse.physics.projection import project_wind, transport_from_wind
    from dgse.physics.scenario import random_cases

    ap = _parser(
        "projection", "choose the settings of dgse.physics.projection on generated validation scenarios"
    )
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "projection_tuning.json")
    args = ap.parse_args(argv)
    scenarios = [random_cases(seed, n_sources=2) for seed in PROJECTION_SEEDS]
    rows = []
    for known, closure, fraction, tol in projection_settings():
        errs, secs = [], []
        for cases in scenarios:
            c0 = cases[0]
            kw: dict = {"layout": c0.layout} if known else {"open_fraction": fraction}
            if tol is not None:
                kw["turbulence_tolerance"] = tol
            t0 = time.perf_counter()
            flow = project_wind(c0.occupancy, c0.resolution, c0.wind, closure=closure, **kw)
            ts = transport_from_wind(flow)
            cells = [c0.layout.grid.cell_of(*c.source) for c in cases]
            fields = ts.solve_cells(cells, [c.release_rate for c in cases])
            secs.append(time.perf_counter() - t0)
            for c, f in zip(cases, fields, strict=True):
                errs.append(log_rmse(f * ts.physics.ppm_per_gm3, c.concentration, c.free))
        row = {
            "openings": "known" if known else "unknown (map edges)",
            "closure": closure,
            "open_fraction": fraction,
            "turbulence_tolerance": tol,
            "log_rmse_mean": float(np.mean(errs)),
            "log_rmse_median": float(np.median(errs)),
            "log_rmse_max": float(np.max(errs)),
            "seconds_median": float(np.median(secs)),
        }
        rows.append(row)
        print(
            f"{row['openings']:20s} {closure:13s} open_fraction {fraction!s:5s} tol {tol!s:6s} "
            f"log RMSE mean {row['log_rmse_mean']:.3f} median {row['log_rmse_median']:.3f} "
            f"max {row['log_rmse_max']:.3f}; {row['seconds_median']:.2f} s per flow",
            flush=True,
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps({"seeds": list(PROJECTION_SEEDS), "rows": rows}, indent=1))
    print(f"wrote {args.out}")


#: The residual criteria of ``turbulence``.
TURBULENCE_TOLERANCES = (1e-4, 1e-6)


def turbulence_row(seed: int) -> dict:
    """The coupled solve against k-epsilon on its frozen flow, per criterion, for one scenario."""
    from dgse.physics.constants import DEFAULT_PHYSICS
    from dgse.physics.fv import build_mesh
    from dgse.physics.rans import FlowSettings, solve_flow, solve_turbulence
    from dgse.physics.scenario import random_cases
    from dgse.physics.transport import TransportSolver

    case = random_cases(seed, n_sources=1)[0]
    mesh = build_mesh(case.layout)
    st, info = solve_flow(case.layout, mesh, case.inlet_velocity)
    cells = [case.layout.grid.cell_of(*case.source)]
    phys = DEFAULT_PHYSICS

    def plume(nut: np.ndarray) -> np.ndarray:
        c = TransportSolver.build(mesh, st.F, nut, phys).solve_cells(cells, [case.release_rate])[0]
        return np.log1p(np.maximum(c * phys.ppm_per_gm3, 0.0))

    ref = plume(st.nut)
    row = {"seed": seed, "cells": int(mesh.n), "flow_iterations": info["iterations"]}
    row["nut_median"] = float(np.median(st.nut))
    for tol in TURBULENCE_TOLERANCES:
        settings = FlowSettings(tolerance=tol, max_iterations=5000)
        _, _, nut, t_info = solve_turbulence(mesh, st.ux, st.uy, st.F, phys, settings)
        d = plume(nut) - ref
        row[f"{tol:g}"] = {
            "iterations": t_info["iterations"],
            "converged": t_info["converged"],
            "nut_median_ratio": float(np.median(nut) / np.median(st.nut)),
            "plume_log_rmse": float(np.sqrt(np.mean(d[case.free] ** 2))),
        }
    return row


def turbulence(argv: list[str]) -> None:
    """``turbulence``: k-epsilon on a frozen flow against the coupled solve's (module doc)."""
    ap = _parser(
        "turbulence", "turbulence on a frozen flow against the coupled solve's, per residual criterion"
    )
    ap.add_argument("--seeds", type=_seeds, default=[*range(900, 912), 2005], help="e.g. 900-911,2005")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "frozen_turbulence.json")
    args = ap.parse_args(argv)
    rows = []
    for seed in args.seeds:
        rows.append(turbulence_row(seed))
        r = rows[-1]
        print(
            f"{seed}: median nu_t {r['nut_median']:.1e}; "
            + "; ".join(
                f"tol {t:g}: {r[f'{t:g}']['iterations']} it, nu_t x{r[f'{t:g}']['nut_median_ratio']:.2f}, "
                f"plume RMSE {r[f'{t:g}']['plume_log_rmse']:.3f}"
                for t in TURBULENCE_TOLERANCES
            ),
            flush=True,
        )
    write_text(args.out, json.dumps({"tolerances": TURBULENCE_TOLERANCES, "rows": rows}, indent=1))


# --------------------------------------------------------------------------- diagnostics
def undershoot(case: Case, sensors: int, seed: int) -> dict:
    """Raw adjoint rows at ``sensors`` random free cells: negative share and depth."""
    from dgse.posterior.adjoint import flow_model

    fm = flow_model(case.layout, case.inlet_velocity)
    free = np.argwhere(case.free)
    cells = free[np.random.default_rng(seed).choice(len(free), size=sensors, replace=False)]
    raw = fm.mesh.values(fm.transport.adjoint(cells))
    depth = raw.min(axis=1) / raw.max(axis=1)
    return {
        "sensors": sensors,
        "negative_share": float((raw < 0).mean()),
        "min_over_max_median": float(np.median(depth)),
        "min_over_max_worst": float(depth.min()),
    }


def speed_rows(case: Case, speeds: list[float], readings: int, seed: int) -> list[dict]:
    """dgse-phys's error from the same readings with one given inlet speed at a time."""
    obs = draw_observations(case, readings, seed=seed)
    knowledge = Knowledge.from_case(case, "openings")
    rows = []
    for v in speeds:
        est = get_estimator(
            "dgse-phys", knowledge=knowledge, **{"flows.speeds": (v,), "flows.refine_speeds": 0}
        )
        b = est.estimate(case.occupancy, case.resolution, obs)
        rows.append({"speed": v, "error_m": b.localization_error(case.source)})
        print(f"v_in {v:g} m/s: {rows[-1]['error_m']:.2f} m off")
    return rows


def warm_start_row(case: Case, readings: int, seed: int) -> dict:
    """Cold- against warm-started speed flows: the flows at 1 m/s and dgse-phys's errors."""
    obs = draw_observations(case, readings, seed=seed)
    knowledge = Knowledge.from_case(case, "openings")
    row: dict = {}
    flows = {}
    for warm in (False, True):
        opts = {"flows.refine_speeds": 0, "flows.warm_start": warm}
        est = get_estimator("dgse-phys", knowledge=knowledge, **opts)
        b = est.estimate(case.occupancy, case.resolution, obs)
        tag = "warm" if warm else "cold"
        row[f"{tag}_error_m"] = b.localization_error(case.source)
        row[f"{tag}_flow_seconds"] = sum(h.flow.info["seconds"] for h in est.hypotheses())
        flows[tag] = next(h.flow for h in est.hypotheses() if h.flow.inlet_velocity == 1.0)
        print(f"{tag} starts: {row[f'{tag}_error_m']:.2f} m off")
    free = case.free
    for name in ("wind", "nut"):
        a = np.asarray(getattr(flows["cold"].solved, name))
        b = np.asarray(getattr(flows["warm"].solved, name))
        row[f"{name}_rel_l2"] = float(np.linalg.norm(a - b) / np.linalg.norm(a))
        if name == "nut":
            rel = np.abs(a - b)[free] / np.maximum(np.abs(a)[free], 1e-30)
            row["nut_median_rel_diff"] = float(np.median(rel))
    return row


def diagnostics(argv: list[str]) -> None:
    """``diagnostics``: three diagnoses of the physics posterior on one test scenario (module doc)."""
    ap = _parser("diagnostics", "three diagnoses of dgse-phys's physics posterior")
    ap.add_argument("--case", default="test2005", help="a test scenario, testSEED (2000-2019)")
    ap.add_argument("--speeds", type=float, nargs="+", default=[1.0, 1.331, 1.38])
    ap.add_argument("--readings", type=int, default=150)
    ap.add_argument("--sensors", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "phys_diagnostics.json")
    args = ap.parse_args(argv)
    path = search_cases(RESULTS / "phys_search", "test") / f"{args.case}_src0.npz"
    if not path.exists():
        ap.error(f"{path} is not a test scenario")
    case = Case.load(path)
    row = {
        "case": args.case,
        "true_inlet_velocity": float(case.inlet_velocity),
        "readings": args.readings,
        "seed": args.seed,
        "undershoot": undershoot(case, args.sensors, args.seed),
        "speed": speed_rows(case, args.speeds, args.readings, args.seed),
        "warm_start": warm_start_row(case, args.readings, args.seed),
    }
    print(json.dumps(row["undershoot"]))
    print(json.dumps(row["warm_start"]))
    write_text(args.out, json.dumps(row, indent=1))
    print(f"wrote {args.out}")


# ---------------------------------------------------------------------------------- closed
#: The reference cases ``closed`` walls in by default (one source of each of three layouts).
CLOSED_CASES = ("s1_l000_src0", "s1_l001_src0", "s1_l002_src0")
CLOSED_METHODS = (("dgse-phys", "wind"), ("dgse-s", "map"), ("dgse-phys", "map"))


@dataclass(eq=False)
class SmoothedSliceEstimator(PhysicsGuidedEstimator):
    """dgse-phys with the given field's exchange through the slice smoothed over
    ``slice_smoothing`` m (:func:`dgse.physics.projection.smoothed_exchange`)."""

    slice_smoothing: float = 0.0

    def _project_given(self, k: Knowledge) -> ProjectedFlow:
        assert k.wind is not None
        layout = k.layout if k.has_openings else None
        return project_wind(
            k.occupancy,
            k.resolution,
            k.wind,
            layout,
            physics=self.physics,
            slice_smoothing=self.slice_smoothing,
        )


def closed(argv: list[str]) -> None:
    """``closed``: closed slices (walls drawn at the map's edge, no openings: what an imported
    GADEN scenario is) from random readings; ``OUT/<method>_<level>.json``, ``OUT/summary.md``."""
    from dgse.bench.scenarios import walled_case

    ap = _parser("closed", "closed slices from random readings")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "phys_closed")
    ap.add_argument("--cases", nargs="+", default=list(CLOSED_CASES), help="reference case names")
    ap.add_argument("--counts", nargs="+", type=int, default=[20, 50])
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--reference", type=Path, default=REFERENCE)
    ap.add_argument("--methods", nargs="+", default=[f"{m}@{lv}" for m, lv in CLOSED_METHODS])
    ap.add_argument("--slice-smoothing", type=float, default=0.0, help="dgse-phys's exchange smoothed, m")
    args = ap.parse_args(argv)
    cases = args.out / "_cases"
    cases.mkdir(parents=True, exist_ok=True)
    for name in args.cases:
        path = cases / f"{name}_walled.npz"
        if not path.exists():
            walled_case(Case.load(args.reference / f"{name}.npz")).save(path)
    lines = ["| method@knowledge | " + " | ".join(f"{n} readings" for n in args.counts) + " | median s |"]
    lines.append("|---|" + "---|" * (len(args.counts) + 1))
    for row in args.methods:
        method, level = row.split("@")
        out = args.out / f"{method}_{level}.json"
        smoothed = method == "dgse-phys" and args.slice_smoothing > 0
        chosen: Any = SmoothedSliceEstimator(slice_smoothing=args.slice_smoothing) if smoothed else method
        res = evaluate(
            cases, chosen, args.counts, trials=args.trials, seed=0, knowledge=level,
            journal=journal_path(out), progress=True,
        )  # fmt: skip
        write_json(res, out)
        agg = res["aggregate"]
        cells = [
            f"{agg[str(n)]['sl_error_m_mean']:.2f} / {agg[str(n)]['sl_error_m_median']:.2f}"
            for n in args.counts
        ]
        secs = float(np.median([r["seconds"] for r in res["per_case"]]))
        lines.append(f"| {row} | " + " | ".join(cells) + f" | {secs:.2f} |")
    text = "\n".join(
        [f"SL error mean / median (m), {len(args.cases)} closed cases x {args.trials} trials", "", *lines, ""]
    )
    write_text(args.out / "summary.md", text)
    print(text)


COMMANDS: dict[str, Callable[[list[str]], None]] = {
    "gsl": gsl,
    "robustness": robustness,
    "calibration": calibration,
    "fusion": fusion,
    "fields": fields,
    "sweep": sweep_cmd,
    "projection": projection,
    "turbulence": turbulence,
    "diagnostics": diagnostics,
    "closed": closed,
}


def main(argv: list[str] | None = None) -> None:
    run_command(__doc__, COMMANDS, sys.argv[1:] if argv is None else argv)


if __name__ == "__main__":
    main()
