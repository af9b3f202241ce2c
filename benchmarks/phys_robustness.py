"""dgse-phys where its physics is wrong: filament readings and perturbed winds (issue 12).

The same random readings (Table I noise) on the generated test scenarios
(seeds 2000-2007, as ``benchmarks/phys_gsl.py``), with the physics off in
one way at a time:

* ``steady``: the scenario as generated (the reference row);
* ``filament``: readings from a filament simulation of the same scenario
  (``dgse plume``'s simulator: an intermittent plume, readings at random times);
* ``wind_rotated``: the wind told at knowledge ``wind`` is rotated by 20 degrees;
* ``wind_smoothed``: ... smoothed with a Gaussian of 3 cells (0.3 m);
* ``wind_x2``: ... twice as fast, as from a CFD run at a wrong inlet speed.

The wind perturbations change only what the estimator is told, never the
readings.  Methods: DGSE-S at ``map`` and ``dgse-phys`` at ``map``,
``openings`` and ``wind`` (the perturbations touch only the last).  Mean and
median SL error (m), mean source CE (nats) and the credible sets' calibration
error per variant, method and count;
every estimate is journaled, so an interrupted run resumes::

    python benchmarks/phys_robustness.py --trials 2

The calibration at 50 readings on all 20 test scenarios, two processes (one
journal each, one summary over both)::

    python benchmarks/phys_robustness.py --seeds 2000-2019 --counts 50 --trials 5 \
        --variants steady filament --methods dgse-phys@openings --tag phys \
        --cache benchmarks/results/phys_robustness/_cases -o benchmarks/results/phys_calibration50
    # the same with --methods dgse-s@map --tag dgse-s

``--cases FILE...`` takes case files instead of generated scenarios (the OpenFOAM reference
cases: a flow the built-in solver did not make), each named by its stem.  ``--paired DIR``
compares the run in ``-o`` with another on the estimates both made (``OUT/paired.md``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from dgse.belief.knowledge import Knowledge
from dgse.cli.common import parse_params
from dgse.errors import InputDataError
from dgse.estimators.registry import get_estimator
from dgse.evaluation.calibration import (
    calibration_error,
    chance_calibration_error,
    coverage_curve,
    credible_level,
)
from dgse.evaluation.evaluate import draw_observations, summarize
from dgse.evaluation.metrics import source_cross_entropy, source_localization_error
from dgse.files import write_text
from dgse.world.case import Case

SEEDS = range(2000, 2008)
COUNTS = (20, 50, 150)
VARIANTS = ("steady", "filament", "wind_rotated", "wind_smoothed", "wind_x2")
METHODS = (("dgse-s", "map"), ("dgse-phys", "map"), ("dgse-phys", "openings"), ("dgse-phys", "wind"))


def perturbed_wind(case: Case, variant: str) -> np.ndarray:
    """The wind told at knowledge ``wind`` in a perturbed variant (walls stay still)."""
    u = np.asarray(case.wind, dtype=np.float64)
    free = case.occupancy == 0
    if variant == "wind_rotated":
        a = math.radians(20.0)
        out = np.stack([math.cos(a) * u[0] - math.sin(a) * u[1], math.sin(a) * u[0] + math.cos(a) * u[1]])
    elif variant == "wind_smoothed":
        w = ndimage.gaussian_filter(free.astype(float), 3.0)
        out = np.stack([ndimage.gaussian_filter(c * free, 3.0) / np.maximum(w, 1e-6) for c in u])
    elif variant == "wind_x2":
        out = 2.0 * u
    else:
        return u
    return np.where(free[None], out, 0.0)


def variant_case(case: Case, variant: str, cache: Path, tag: str) -> Case:
    """The scenario the readings come from (filament frames made once, cached as ``<tag>_filament``)."""
    if variant != "filament":
        return case
    path = cache / f"{tag}_filament.npz"
    if not path.exists():
        from dgse.physics.filament import FilamentSettings, make_filament_case

        # FilamentSettings' default caps the prefill at RECOMMENDED_MAX_FILAMENTS since
        # 2026-11-27; the recorded summary's filament cases were made without a cap
        make_filament_case(case, FilamentSettings(), seed=0).save(path)
    return Case.load(path)


def parse_seeds(text: str) -> list[int]:
    """``"2000-2019"`` or ``"2000,2003"`` -> the scenario seeds."""
    seeds: list[int] = []
    try:
        for part in text.split(","):
            lo, _, hi = part.partition("-")
            seeds += list(range(int(lo), int(hi or lo) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"seeds must look like 2000-2019 or 2000,2003, got {text!r}"
        ) from None
    if not seeds:
        raise argparse.ArgumentTypeError(f"no seeds in {text!r}")
    return seeds


def write_summary(out: Path, trials: int) -> None:
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
        f"`python benchmarks/phys_robustness.py` ({where}, "
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
        for method, level in METHODS:
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
        "`python benchmarks/phys_robustness.py -o OUT --paired AGAINST` over the estimates both runs "
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    names = [f"{m}@{k}" for m, k in METHODS]
    ap.add_argument("--methods", nargs="+", default=names, choices=names, help="method@knowledge")
    ap.add_argument(
        "--seeds",
        type=parse_seeds,
        default=list(SEEDS),
        help="scenario seeds, e.g. 2000-2019 (test) or 900-923 (validation)",
    )
    ap.add_argument(
        "--cases",
        type=Path,
        nargs="+",
        default=None,
        help="case files to use instead of the generated scenarios (e.g. ../shared/reference-cases/*.npz)",
    )
    ap.add_argument("--counts", type=int, nargs="+", default=list(COUNTS), help="numbers of readings")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_robustness"))
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
    args = ap.parse_args()
    if any(n < 1 for n in args.counts):
        ap.error("--counts must be positive")
    try:
        phys_options = parse_params(args.estimator_option, "-E")
    except InputDataError as exc:
        ap.error(str(exc))
    if args.paired is not None:
        print(paired_summary(args.out, args.paired))
        return
    if args.summary_only:
        write_summary(args.out, args.trials)
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
                        for method, level in METHODS:
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
    write_summary(args.out, args.trials)


if __name__ == "__main__":
    main()
