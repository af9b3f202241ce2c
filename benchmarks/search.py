"""dgse-phys in active search: the searches, their step cost, and what their stops knew.

One command per measurement (``python benchmarks/search.py COMMAND --help``); results go to
``benchmarks/results/phys_search/`` (``-o``):

* ``run``: the utility planner on a scenario set (``dgse.bench.scenarios.SEARCH_SETS``: seeds
  900-907 ``validation``, 908-923 ``validation2``, 924-963 ``validation3``, 2000-2019
  ``test``; made once into ignored ``_cases_<set>/`` folders, ``cases`` makes them alone) with
  a method at a knowledge level and a stop rule (:data:`RULES`); writes the search metrics and
  how the searches ended (``stops``: mass stops and how many lie within 2 m of the source,
  deadline stops, the stops a confirmation held).  Every finished episode is journaled beside
  the JSON, so an interrupted run resumes; ``--steps`` keeps every step's readings in the
  journal (what ``deadline``, ``misfit`` and ``stops`` rebuild beliefs from).  ``dgse-phys``
  runs with its search preset at the level (:mod:`dgse.presets`); ``-E`` overrides an
  estimator option, ``-P`` a planner option of the rule.  Output names:
  ``<set>_<method>_<level>_<rule>[_<tag>].json``::

      python benchmarks/search.py run --set validation --rule mass1m90 --knowledge openings
      python benchmarks/search.py run --set validation3 --knowledge map \\
          --rule mass1m90-disk1m-deadline60s-revisit0.5m-gas1m --seed 0 --tag base-s0
      python benchmarks/search.py run --set validation3 --knowledge map \\
          --rule mass1m90-disk1m-deadline60s-revisit0.5m-gas1m --seed S -P stop.max_wind_misfit=0.7 \\
          -P deadline.estimate_radius_m=1.0 --tag fit0.7-disk1-sS-steps --steps
      python benchmarks/search.py run --set test --knowledge wind --told-wind wind_smoothed \\
          --rule mass1m90-disk1m-deadline60s-revisit0.5m-gas1m --seed 0 --tag smoothed-s0

  Of the noise-weight comparisons of ``docs/decisions.md``, ``seed0-mix`` is this command as
  it runs now (the mixture is dgse-phys's only gas evidence); ``seed0``, ``seed0-cand`` and
  ``seed0-larger`` ran one weighting alone through a dgse-phys option that is removed
  (``-E 'noise_weights="plug-in"'``, ``"candidate"``, ``"larger"``; this script at commit
  7ba21b2 takes it).
* ``merge``: one result from the JSON files of runs made apart (one ``--files`` case per
  process): ``python benchmarks/search.py merge OUT.json RESULT.json...``.
* ``step-time``: the computation seconds of every search step of dgse-phys (the first
  estimate, which solves the flows, and the median and 90th percentile of the rest) on the
  first test scenarios; writes ``step_time.json`` (``step_time_map.json`` at ``map``)::

      python benchmarks/search.py step-time --cases 20
      python benchmarks/search.py step-time --cases 1 --knowledge map

* ``speed``: the wall-clock cost of dgse-phys at each knowledge level
  (:func:`dgse.bench.speed.speed_table`): one search per validation scenario with the preset
  (first step, median step) and one random-readings estimate per count with nothing cached;
  writes ``benchmarks/results/speed/<tag>.json`` (``-o`` a folder)::

      python benchmarks/search.py speed --cases 2 --counts 20 50 --tag before

* ``deadline``: for every episode of ``map`` searches journaled with ``--steps`` that ended
  at its deadline, the final belief rebuilt from the recorded readings and scored by several
  point estimates (the posterior mean, the mode, the centre of the heaviest 0.5, 1 or 2 m
  disk, :meth:`dgse.planning.planners.UtilityPlanner.declare`)::

      python benchmarks/search.py deadline \\
          benchmarks/results/phys_search/validation3*_map_*-gas1m_base-s0.journal.jsonl \\
          benchmarks/results/phys_search/validation3-files3_*-gas1m_fit0.7-s0.journal.jsonl \\
          -o benchmarks/results/phys_search/deadline_estimate_validation3.json

* ``misfit``: were the true openings among dgse-phys's proposals at ``map`` (from an
  episode's first 64 wind readings), and what was the best proposal's wind misfit::

      python benchmarks/search.py misfit \\
          benchmarks/results/phys_search/validation3*_map_*-gas1m_base-s0.journal.jsonl \\
          -o benchmarks/results/phys_search/map_proposal_misfit_validation3.json

* ``stops``: what a mass stop at ``map`` knew when it fired: the belief the stop saw rebuilt
  and the statistics a stop rule could hold on (readings, the flow hypotheses' weights and
  agreement, wind and gas misfit, DGSE-S's own mass near the mode)::

      python benchmarks/search.py stops \\
          benchmarks/results/phys_search/validation3_*_map_*-gas1m_fit0.7-disk1-s1-steps.journal.jsonl.gz \\
          -o benchmarks/results/phys_search/map_stop_diagnostics_validation3_s1.json

``deadline``, ``misfit`` and ``stops`` read journals as written or gzipped; the case files
they name are the set's (``python benchmarks/search.py cases --set validation3``).  A rule is
only ever chosen on validation episodes; the test split's are for reporting.
"""

from __future__ import annotations

import gzip
import json
import math
import os
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from dgse.bench.commands import command_parser, run_command
from dgse.bench.scenarios import SEARCH_SETS, WIND_VARIANTS, ToldWind, search_cases
from dgse.files import write_text
from dgse.presets import PRESETS
from dgse.search.campaign import json_safe, run_trials
from dgse.world.case import Case

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "phys_search"
#: A stop within this distance of the source means something.
SUCCESS_M = 2.0

#: The stop rules of ``run`` (the utility planner's settings, :mod:`dgse.planning.planners`):
#:
#: * ``paper``: the entropy test from the 5th reading (``stop.min_observations=5``);
#: * ``paper-eta0.78``: the same with the shipped DGSE-S's threshold (``stop.eta=0.78``,
#:   ``dgse demo``'s, tuned on the validation split by ``python benchmarks/training.py eta``);
#: * ``confirm``: the same, and a stop needs 2 readings within 1 m of the posterior's mode
#:   (``stop.confirm_radius_m=1``, ``stop.confirm_readings=2``);
#: * ``mass1m90`` / ``mass2m95``: instead of the entropy test, stop once the posterior holds
#:   90 % within 1 m (95 % within 2 m) of its mode (``stop.mass_radius_m``, ``stop.mass_level``);
#: * ``mass1m90-disk1m`` / ``mass1m90-disk0.5m``: ``mass1m90``, and the utility's source term
#:   is the posterior mass within 1 m (0.5 m) of a cell (``weights.source_radius_m``), not the
#:   cell's own;
#: * ``mass1m90-disk1m-deadline60s``: and the search stops with its estimate once less than
#:   60 s of the time limit is left (``deadline.margin_s``); such stops are counted apart
#:   (``deadline_stops``);
#: * ``mass1m90-disk1m-deadline60s-revisit0.5m``: and the variance terms of a cell are divided
#:   by one plus the cells measured within 0.5 m of it (``weights.revisit_radius_m``);
#: * ``...-revisit0.5m-confirm1m``: and a stop needs 2 readings within 1 m of the mode;
#: * ``...-revisit0.5m-gas1m``: and a stop needs 1 reading within 1 m of the mode above twice
#:   the estimator's noise floor (``stop.confirm_readings=1``, ``stop.confirm_sigmas=2``): gas
#:   smelt there.  Every trial records the stops the confirmation held (``held_stops``) and the
#:   error of the first (``first_held_error_m``).  This rule is dgse-phys's search preset
#:   (:data:`dgse.presets.PRESETS`); at knowledge ``map`` the preset adds
#:   ``stop.max_wind_misfit=0.7`` and ``deadline.estimate_radius_m=1``: ``run`` takes them as
#:   ``-P stop.max_wind_misfit=0.7 -P deadline.estimate_radius_m=1.0`` (files tagged
#:   ``fit0.7-disk1``) and notes what of the preset a run leaves out.
#:
#: The rule ``...-revisit0.5m-twice`` (the mass test at two readings in a row, not adopted:
#: ``docs/decisions.md``) is removed with its planner option; its result file stays in
#: ``benchmarks/results/phys_search/``, and this script at commit 7ba21b2 runs it.
RULES: dict[str, dict[str, Any]] = {
    "paper": {"stop.min_observations": 5},
    "paper-eta0.78": {"stop.min_observations": 5, "stop.eta": 0.78},
    "confirm": {"stop.min_observations": 5, "stop.confirm_radius_m": 1.0, "stop.confirm_readings": 2},
    "mass1m90": {"stop.min_observations": 5, "stop.mass_radius_m": 1.0, "stop.mass_level": 0.9},
    "mass2m95": {"stop.min_observations": 5, "stop.mass_radius_m": 2.0, "stop.mass_level": 0.95},
    "mass1m90-disk1m": {
        "stop.min_observations": 5,
        "stop.mass_radius_m": 1.0,
        "stop.mass_level": 0.9,
        "weights.source_radius_m": 1.0,
    },
    "mass1m90-disk1m-deadline60s": {
        "stop.min_observations": 5,
        "stop.mass_radius_m": 1.0,
        "stop.mass_level": 0.9,
        "weights.source_radius_m": 1.0,
        "deadline.margin_s": 60.0,
    },
    "mass1m90-disk1m-deadline60s-revisit0.5m": {
        "stop.min_observations": 5,
        "stop.mass_radius_m": 1.0,
        "stop.mass_level": 0.9,
        "weights.source_radius_m": 1.0,
        "deadline.margin_s": 60.0,
        "weights.revisit_radius_m": 0.5,
    },
    "mass1m90-disk0.5m": {
        "stop.min_observations": 5,
        "stop.mass_radius_m": 1.0,
        "stop.mass_level": 0.9,
        "weights.source_radius_m": 0.5,
    },
}
RULES["mass1m90-disk1m-deadline60s-revisit0.5m-confirm1m"] = {
    **RULES["mass1m90-disk1m-deadline60s-revisit0.5m"],
    "stop.confirm_radius_m": 1.0,
    "stop.confirm_readings": 2,
}
RULES["mass1m90-disk1m-deadline60s-revisit0.5m-gas1m"] = {
    **RULES["mass1m90-disk1m-deadline60s-revisit0.5m"],
    "stop.confirm_radius_m": 1.0,
    "stop.confirm_readings": 1,
    "stop.confirm_sigmas": 2.0,
}


def journal_episodes(journals: list[Path]) -> dict[str, tuple[Any, dict[str, Any]]]:
    """``{case stem: (Case, journal row)}`` of searches journaled with ``--steps`` (a later
    journal's episode replaces an earlier one's of the same case)."""
    out: dict[str, tuple[Any, dict[str, Any]]] = {}
    for journal in journals:
        text = (
            gzip.decompress(journal.read_bytes()).decode() if journal.suffix == ".gz" else journal.read_text()
        )
        for line in text.splitlines()[1:]:
            entry = json.loads(line)
            if "steps" not in entry["row"]:
                raise SystemExit(f"{journal}: no steps recorded; run the search with --steps")
            found = sorted(journal.parent.glob(f"_cases_*/{entry['case']}.npz"))
            if not found:
                raise SystemExit(
                    f"no case file {entry['case']}.npz in a _cases_* folder beside {journal}: "
                    "make the set's cases with `python benchmarks/search.py cases --set SET`"
                )
            out[entry["case"]] = (Case.load(found[0]), entry["row"])
    return out


def step_observations(steps: list[dict[str, Any]]) -> Any:
    """The readings of a journaled episode's steps as :class:`~dgse.sensing.sensors.Observations`."""
    from dgse.sensing.sensors import Observations

    cells = np.array([s["cell"] for s in steps], dtype=np.int64)
    gas = np.array([s["gas"] for s in steps], dtype=np.float64)
    wind = np.array([s["wind"] for s in steps], dtype=np.float64)
    return Observations(cells, gas, wind)


def map_estimator_at_end(case: Any, obs: Any, **options: Any) -> Any:
    """dgse-phys at ``map`` holding the opening proposals a search held after the readings ``obs``:
    those made from the last power of two of them (a search estimates after every reading, and
    ``PhysicsGuidedEstimator`` proposes anew when the readings have doubled)."""
    from dgse.belief.knowledge import Knowledge
    from dgse.estimators.registry import get_estimator

    est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "map"), **options)
    held = 1 << (len(obs).bit_length() - 1)
    est.hypotheses(obs.take(slice(0, held)))
    return est


def stop_quality(result: dict[str, Any]) -> dict[str, Any]:
    """Entropy stops (episodes that terminated) and the share of them within 2 m of the source."""
    rows = [t for c in result["per_case"] for t in c["trials"]]
    ended = [t for t in rows if t.get("terminated")]
    late = [t for t in ended if t.get("reason") == "deadline"]
    stops = [t for t in ended if t.get("reason") != "deadline"]
    near = [t for t in stops if t["error_m"] <= SUCCESS_M]
    out: dict[str, Any] = {
        "episodes": len(rows),
        "entropy_stops": len(stops),
        "stops_within_2m": len(near),
        "stops_within_2m_share": (len(near) / len(stops)) if stops else None,
        "deadline_stops": len(late),
        "deadline_stops_within_2m": sum(t["error_m"] <= SUCCESS_M for t in late),
    }
    held = [t for t in rows if t.get("held_stops")]
    if held:
        # the same run read as the rule without the confirmation: an episode with a held stop
        # would have ended there (as a mass stop) with that step's error; the others the same
        def without(t: dict[str, Any]) -> tuple[float, bool]:
            if t.get("held_stops"):
                return float(t["first_held_error_m"]), True
            return float(t["error_m"]), bool(t.get("terminated")) and t.get("reason") != "deadline"

        w = [without(t) for t in rows]
        w_stops = [e for e, stop in w if stop]
        out["held"] = {
            "episodes_with_held_stops": len(held),
            "held_stop_errors_m": [round(float(t["first_held_error_m"]), 3) for t in held],
            "final_errors_m": [round(float(t["error_m"]), 3) for t in held],
            "without_confirmation": {
                "found": sum(e <= SUCCESS_M for e, _ in w),
                "error_m_mean": sum(e for e, _ in w) / len(w),
                "mass_stops": len(w_stops),
                "mass_stops_within_2m": sum(e <= SUCCESS_M for e in w_stops),
            },
        }
    # the deadline stops read every way (``end_errors_m``: what each point estimate of the final
    # belief would have declared), so that ``deadline.estimate_radius_m`` is chosen from one run
    recorded = [t for t in late if t.get("end_errors_m")]
    if recorded:
        ways = sorted(recorded[0]["end_errors_m"])
        out["deadline_estimates"] = {
            w: {
                "error_m_mean": sum(t["end_errors_m"][w] for t in recorded) / len(recorded),
                "within_2m": sum(t["end_errors_m"][w] <= SUCCESS_M for t in recorded),
            }
            for w in ways
        }
    return out


def write_result(path: Path, result: dict[str, Any], label: str, extra: str = "") -> None:
    """Write ``result`` as JSON and print its one-line summary (success, error, ST, TD, step)."""
    write_text(path, json.dumps(json_safe(result), indent=1))
    agg = result["aggregate"]
    print(
        f"{label} ({agg['n_trials']} episodes): success {agg['success_rate']:.2f}, error mean "
        f"{agg['error_m_mean']:.2f} m (median {agg['error_m_median']:.2f}), ST "
        f"{agg['search_time_s_mean']:.0f} s, TD {agg['distance_m_mean']:.0f} m, step median "
        f"{agg['step_seconds_median']:.3f} s{extra}"
    )
    print(f"wrote {path}")


#: Planner options a run without them answers for some episodes (``--fill``), and which:
#: ``stop.max_wind_misfit`` only holds stops (a stop test that passed returns False instead), so
#: an episode that ended at its deadline is the same with it; ``deadline.estimate_radius_m``
#: only changes what a deadline stop declares, so an episode that stopped before is the same.
FILL_OPTIONS = {"stop.max_wind_misfit": "deadline", "deadline.estimate_radius_m": "converged"}
#: The names the result files recorded before the settings objects give those options.
RECORDED_NAMES = {
    "stop.max_wind_misfit": "max_wind_misfit",
    "deadline.estimate_radius_m": "deadline_estimate_radius_m",
}


def _without(settings: dict[str, Any], option: str | None) -> dict[str, Any]:
    """``settings`` without the planner option ``option`` (by its name and its recorded one)."""
    names = {option, RECORDED_NAMES.get(option or "")}
    planner = {k: v for k, v in settings.get("planner_options", {}).items() if k not in names}
    return {**settings, "planner_options": planner}


def merged(paths: list[Path], fill: Path | None = None, fill_option: str | None = None) -> dict[str, Any]:
    """One result of several runs' JSON files (their cases in the given order, their settings
    checked equal but for ``set``; the aggregate and the stops recomputed).

    ``fill``: a run without the planner option ``fill_option`` (a key of :data:`FILL_OPTIONS`)
    whose other settings equal the runs'; its episodes of the cases the runs lack are added,
    each checked to have ended as the option cannot change (``FILL_OPTIONS[fill_option]``).
    The runs then need only the other episodes."""
    from dgse.search.metrics import aggregate

    results = [json.loads(p.read_text()) for p in paths]
    settings = dict(results[0]["settings"])
    for p, r in zip(paths, results, strict=True):
        if {**r["settings"], "set": settings["set"]} != settings:
            raise SystemExit(f"{p}: its settings differ from {paths[0]}'s")
    per_case = [c for r in results for c in r["per_case"]]
    filled: list[str] = []
    if fill is not None:
        if fill_option not in FILL_OPTIONS:
            raise SystemExit(f"--fill needs --fill-option, one of {sorted(FILL_OPTIONS)}")
        unchanged = FILL_OPTIONS[fill_option]
        base = json.loads(fill.read_text())
        base_settings = {**base["settings"], "set": settings["set"]}
        if _without(base_settings, fill_option) != _without(settings, fill_option):
            raise SystemExit(f"{fill}: its settings differ from the runs' in more than {fill_option}")
        have = {Path(c["file"]).name for c in per_case}  # case names repeat; files do not
        for c in base["per_case"]:
            name = Path(c["file"]).name
            if name in have:
                continue
            if any(t["reason"] != unchanged for t in c["trials"]):
                raise SystemExit(f"{fill}: {name} did not end {unchanged!r}: run it with {fill_option}")
            per_case.append(c)
            filled.append(name)
    out = {
        "settings": settings,
        "aggregate": aggregate([t["metrics"] for c in per_case for t in c["trials"]]),
        "per_case": per_case,
        "merged_from": [str(p) for p in paths],
    }
    if fill is not None:
        out["filled_from"] = {"file": str(fill), "option": fill_option, "cases": filled}
    out["stops"] = stop_quality(out)
    return out


def run(argv: list[str]) -> None:
    """``run``: searches of a scenario set with a method, knowledge level and stop rule (module doc)."""
    ap = _parser("run", "active search on a scenario set with a method, knowledge level and stop rule")
    ap.add_argument("--set", choices=sorted(SEARCH_SETS), default="validation")
    ap.add_argument("--rule", choices=sorted(RULES), default="confirm")
    ap.add_argument("--method", default="dgse-phys")
    ap.add_argument("--knowledge", default="openings", choices=["map", "openings", "wind"])
    ap.add_argument("--trials", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cases", type=int, default=None, help="only the first N scenarios of the set")
    ap.add_argument(
        "--files",
        type=Path,
        nargs="+",
        default=None,
        metavar="CASE",
        help="search these case files instead of a set (e.g. the filament cases of "
        "benchmarks/results/phys_robustness/_cases/*_filament.npz); --set then only names the output",
    )
    ap.add_argument(
        "-E",
        "--estimator-option",
        action="append",
        default=[],
        metavar="KEY=JSON",
        help="an estimator option, e.g. -E flows.refine_speeds=0 (repeatable)",
    )
    ap.add_argument(
        "-P",
        "--planner-option",
        action="append",
        default=[],
        metavar="KEY=JSON",
        help="a planner option over the rule's, e.g. -P stop.min_observations=60 (repeatable)",
    )
    ap.add_argument(
        "--steps",
        action="store_true",
        help="keep every step's record (cell, readings, estimate) in the journal (not in the JSON)",
    )
    ap.add_argument(
        "--told-wind",
        default=None,
        choices=WIND_VARIANTS,
        help="at --knowledge wind, tell the estimator the case's wind perturbed as in "
        "`benchmarks/phys.py robustness` (a user's CFD that is off); the robot still reads the true wind",
    )
    ap.add_argument("--tag", default="", help="appended to the output names (a variant's own files)")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    if args.cases is not None and args.cases < 1:
        ap.error(f"--cases must be at least 1, got {args.cases}")
    args.out.mkdir(parents=True, exist_ok=True)
    set_name = args.set if args.cases is None else f"{args.set}{args.cases}"
    if args.files:
        cases: Any = [(f, Case.load(f)) for f in args.files]
        set_name = f"{args.set}-files{len(cases)}"
    else:
        cases = search_cases(args.out, args.set, args.cases)
    stem = f"{set_name}_{args.method}_{args.knowledge}_{args.rule}" + (f"_{args.tag}" if args.tag else "")
    # dgse-phys searches as dgse demo runs them, unless -E says otherwise
    est_opts = (
        PRESETS["dgse-phys"].estimator_options_at(args.knowledge, search=True)
        if args.method == "dgse-phys"
        else {}
    )
    for item in args.estimator_option:
        key, sep, value = item.partition("=")
        if not sep:
            ap.error(f"-E takes KEY=JSON, got {item!r}")
        est_opts[key] = json.loads(value)
    planner_opts = dict(RULES[args.rule])
    for item in args.planner_option:
        key, sep, value = item.partition("=")
        if not sep:
            ap.error(f"-P takes KEY=JSON, got {item!r}")
        planner_opts[key] = json.loads(value)
    missing = {
        k: v
        for k, v in PRESETS["dgse-phys"].at_level.get(args.knowledge, {}).get("planner", {}).items()
        if args.method == "dgse-phys" and k not in planner_opts
    }
    if missing:  # kept out of the defaults: the recorded runs' commands must mean what they meant
        opts = " ".join(f"-P {k}={json.dumps(v)}" for k, v in missing.items())
        print(f"note: dgse demo's search at {args.knowledge} also sets {opts}; this run does not", flush=True)
    if args.told_wind is not None and args.knowledge != "wind":
        ap.error("--told-wind changes only what --knowledge wind is told")
    estimator: Any = args.method
    if args.told_wind is not None:
        from dgse.estimators.registry import get_estimator

        estimator = ToldWind(get_estimator(args.method, **est_opts), args.told_wind)
    result = run_trials(
        cases,
        estimator,
        "utility",
        method=args.method,
        trials=args.trials,
        seed=args.seed,
        planner_options=planner_opts,
        estimator_options=est_opts,
        knowledge=args.knowledge,
        steps=args.steps,
        journal=args.out / f"{stem}.journal.jsonl",
    )
    for case in result["per_case"]:  # steps stay in the journal: the JSON keeps the summaries
        for trial in case["trials"]:
            trial.pop("steps", None)
    result["stops"] = stop_quality(result)
    result["settings"]["rule"] = args.rule
    result["settings"]["set"] = args.set
    result["settings"]["estimator_options"] = est_opts
    result["settings"]["told_wind"] = args.told_wind
    write_result(args.out / f"{stem}.json", result, stem, f", stops {result['stops']}")


def merge(argv: list[str]) -> None:
    """``merge``: one result from the JSON files of runs made apart (module doc)."""
    ap = _parser("merge", "one search result from the JSON files of runs made apart")
    ap.add_argument("out", type=Path, metavar="OUT", help="the merged result (JSON)")
    ap.add_argument("results", type=Path, nargs="+", metavar="RESULT", help="the runs' JSON files")
    ap.add_argument(
        "--fill",
        type=Path,
        default=None,
        metavar="BASE",
        help="the episodes of BASE, a run without --fill-option, for the cases the runs lack "
        "(each checked to have ended as the option cannot change; see merged)",
    )
    ap.add_argument("--fill-option", default=None, choices=sorted(FILL_OPTIONS))
    args = ap.parse_args(argv)
    result = merged(args.results, args.fill, args.fill_option)
    write_result(args.out, result, args.out.stem, f", stops {result['stops']}")


def cases(argv: list[str]) -> None:
    """``cases``: make a scenario set's case files (what ``run`` makes on first use)."""
    ap = _parser("cases", "make a scenario set's case files")
    ap.add_argument("--set", choices=sorted(SEARCH_SETS), required=True)
    ap.add_argument("--cases", type=int, default=None, help="only the first N scenarios of the set")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    d = search_cases(args.out, args.set, args.cases)
    left = sorted(p.stem for p in d.glob("*.unconverged"))
    print(
        f"{d}: {len(list(d.glob('*.npz')))} cases"
        + (f"; left out (no converged flow): {left}" if left else "")
    )


def step_time(argv: list[str]) -> None:
    """``step-time``: the computation seconds of every step of dgse-phys's searches (module doc)."""
    ap = _parser("step-time", "search step cost of dgse-phys: the first estimate and the median step")
    ap.add_argument("--cases", type=int, default=2)
    ap.add_argument("-o", "--out", type=Path, default=RESULTS)
    ap.add_argument("--knowledge", choices=("openings", "map"), default="openings")
    args = ap.parse_args(argv)
    d = search_cases(args.out, "test", args.cases)
    rows = []
    for path in sorted(d.glob("*.npz")):
        res = run_trials(
            path,
            "dgse-phys",
            "utility",
            trials=1,
            planner_options={
                "stop.min_observations": 5,
                **PRESETS["dgse-phys"].planner_options_at(args.knowledge),
            },
            estimator_options=PRESETS["dgse-phys"].estimator_options_at(args.knowledge, search=True),
            knowledge=args.knowledge,
            steps=True,
        )
        trial = res["per_case"][0]["trials"][0]
        s = np.array([st["compute_s"] for st in trial["steps"]])
        rows.append(
            {
                "case": path.stem,
                "steps": int(s.size),
                "first_s": float(s[0]),
                "median_s": float(np.median(s[1:])),
                "p90_s": float(np.percentile(s[1:], 90)),
                "error_m": trial["error_m"],
                "step_s": [round(float(x), 4) for x in s],
            }
        )
        print(json.dumps({k: v for k, v in rows[-1].items() if k != "step_s"}), flush=True)
    out = {
        "cores": os.cpu_count(),
        "load_average_at_end": os.getloadavg(),
        "estimator_options": PRESETS["dgse-phys"].estimator_options_at(args.knowledge, search=True),
        "knowledge": args.knowledge,
        "episodes": rows,
        # every step after each episode's first, pooled over the episodes
        "median_all_s": float(np.median(np.concatenate([r["step_s"][1:] for r in rows]))),
    }
    name = "step_time.json" if args.knowledge == "openings" else f"step_time_{args.knowledge}.json"
    path = args.out / name
    write_text(path, json.dumps(out, indent=1))
    print(f"wrote {path}")


def speed(argv: list[str]) -> None:
    """``speed``: dgse-phys's search steps and estimates timed per knowledge level (module doc)."""
    from dgse.bench.speed import speed_table

    ap = _parser("speed", "dgse-phys's step, first-estimate and random-readings estimate seconds")
    ap.add_argument("--set", default="validation", choices=[k for k in SEARCH_SETS if k != "test"])
    ap.add_argument("--cases", type=int, default=2)
    ap.add_argument("--levels", nargs="+", default=["openings", "wind", "map"])
    ap.add_argument("--counts", type=int, nargs="+", default=[20, 50])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-search", action="store_true", help="the random-readings estimates only")
    ap.add_argument("--tag", default="speed")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS.parent / "speed")
    args = ap.parse_args(argv)
    d = search_cases(RESULTS, args.set, args.cases)
    paths = sorted(d.glob("*.npz"))

    def show(row: dict) -> None:
        print(json.dumps({k: v for k, v in row.items() if k != "step_s"}), flush=True)

    out = speed_table(paths, args.levels, args.counts, args.seed, not args.no_search, show)
    path = args.out / f"{args.tag}.json"
    write_text(path, json.dumps(out, indent=1) + "\n")
    print(json.dumps(out["summary"]))
    print(f"wrote {path}")


#: The disk radii (m) of the deadline estimates ``deadline`` scores.
DEADLINE_RADII = (0.5, 1.0, 2.0)


def deadline_row(case: Case, row: dict) -> dict:
    """Every point estimate's error of one deadline episode's rebuilt final belief."""
    from dgse.planning.planners import Deadline, UtilityPlanner

    obs = step_observations(row["steps"])
    est = map_estimator_at_end(case, obs, **PRESETS["dgse-phys"].estimator_options_at("map", search=True))
    belief = est.estimate(case.occupancy, case.resolution, obs)
    sx, sy = (float(v) for v in case.source)

    def error(xy: tuple[float, float]) -> float:
        return math.hypot(xy[0] - sx, xy[1] - sy)

    i, j = belief.most_likely_cell()
    out = {
        "journal_error_m": row["error_m"],
        "mean": error(belief.source_estimate()),
        "mode": error(((j + 0.5) * case.resolution, (i + 0.5) * case.resolution)),
        "wind_misfit": belief.info["wind_misfit"],
    }
    for r in DEADLINE_RADII:
        planner = UtilityPlanner(deadline=Deadline(estimate_radius_m=r))
        out[f"disk{r:g}m"] = error(planner.declare(belief, True))
    # the search's own posterior mean: what it declared, unless it declared a disk's centre
    # (deadline.estimate_radius_m), when its journal row records the mean beside
    searched = row.get("end_errors_m", {}).get("mean", row["error_m"])
    if abs(out["mean"] - searched) > 1e-6:
        raise SystemExit(f"rebuilt mean {out['mean']:.3f} m off, the search's {searched:.3f} m")
    return out


def deadline(argv: list[str]) -> None:
    """``deadline``: what a search should declare when it ends at its deadline (module doc)."""
    ap = _parser("deadline", "what a search at knowledge map should declare when it ends at its deadline")
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args(argv)
    rows = {}
    for name, (case, row) in sorted(journal_episodes(args.journals).items()):
        if row["reason"] != "deadline":
            continue
        rows[name] = deadline_row(case, row)
        print(name, {k: round(v, 2) for k, v in rows[name].items()}, flush=True)
    keys = ["mean", "mode", *(f"disk{r:g}m" for r in DEADLINE_RADII)]
    summary = {
        k: {
            "within_2m": sum(r[k] <= SUCCESS_M for r in rows.values()),
            "error_m_mean": float(np.mean([r[k] for r in rows.values()])) if rows else None,
        }
        for k in keys
    }
    summary["deadline_episodes"] = len(rows)
    write_text(args.out, json.dumps({"summary": summary, "episodes": rows}, indent=1))
    print(json.dumps(summary))


#: The wind readings of an episode's start ``misfit`` proposes openings from.
MISFIT_READINGS = 64


def _hits(opening: Any, truth: dict) -> bool:
    """The proposed opening lies on the true one's side and overlaps it."""
    return (
        opening.side == truth["side"]
        and opening.start_m < truth["end_m"]
        and opening.end_m > truth["start_m"]
    )


def _misfit(hyp, obs) -> float:
    """``dgse-phys``'s ``wind_misfit`` of one proposal: its flow scaled to fit the readings."""
    from dgse.posterior.mixture import fitted_wind_scale, relative_wind_misfit

    u = hyp.flow.wind[:, obs.cells[:, 0], obs.cells[:, 1]].T
    return relative_wind_misfit(fitted_wind_scale(u, obs.wind) * u, obs.wind)


def misfit_row(name: str, case: Case, row: dict) -> dict:
    """Whether one episode's proposals held the true openings, and their wind misfit."""
    from dgse.belief.knowledge import Knowledge
    from dgse.estimators.registry import get_estimator
    from dgse.physics.openings import potential_flow_proposals

    steps = row["steps"]
    n = min(MISFIT_READINGS, len(steps))
    obs = step_observations(steps[:n])
    est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "map"))
    hyps = est.hypotheses(obs)  # proposed from these readings
    # the same call the estimator makes, for the openings themselves (its hypotheses keep labels)
    props = potential_flow_proposals(
        case.occupancy, case.resolution, obs.cells, obs.wind, top=est.flows.map_proposals
    )
    if [p.label() for p in props] != [h.label for h in hyps]:
        raise SystemExit(f"{name}: the proposals differ from dgse-phys's hypotheses")
    misfits = [_misfit(h, obs) for h in hyps]
    # at the episode's end: the proposals dgse-phys held then against all its readings
    obs_m = step_observations(steps)
    end_hyps = map_estimator_at_end(case, obs_m).hypotheses(obs_m)
    inlet = [_hits(p.inlets[0], case.meta["inlet"]) for p in props]
    outlet = [_hits(p.outlets[0], case.meta["outlet"]) for p in props]
    return {
        "case": name,
        "success": bool(row["metrics"]["success"]),
        "error_m": row["error_m"],
        "reason": row["reason"],
        "n_steps": row["n_steps"],
        "readings_used": n,
        "best_misfit": min(misfits),
        "end_misfit": min(_misfit(h, obs_m) for h in end_hyps),
        "true_inlet_proposed": any(inlet),
        "true_pair_proposed": any(i and o for i, o in zip(inlet, outlet, strict=True)),
    }


def misfit(argv: list[str]) -> None:
    """``misfit``: the true openings among the proposals at ``map``, and the wind misfit (module doc)."""
    ap = _parser(
        "misfit", "were the true openings among dgse-phys's proposals at map, and did the wind say so"
    )
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args(argv)
    rows = []
    for name, (case, row) in journal_episodes(args.journals).items():
        rows.append(misfit_row(name, case, row))
        r = rows[-1]
        print(
            f"{r['case']}: {'found' if r['success'] else 'FAILED'} {r['error_m']:.2f} m ({r['reason']}), "
            f"misfit {r['best_misfit']:.2f} (end {r['end_misfit']:.2f}), "
            f"inlet proposed {r['true_inlet_proposed']}, pair {r['true_pair_proposed']}",
            flush=True,
        )
    summary = {}
    found_rows = [r for r in rows if r["success"]]
    failed_rows = [r for r in rows if not r["success"]]
    for label, group in (("found", found_rows), ("failed", failed_rows)):
        summary[label] = {
            "episodes": len(group),
            "true_inlet_proposed": sum(r["true_inlet_proposed"] for r in group),
            "true_pair_proposed": sum(r["true_pair_proposed"] for r in group),
            "best_misfit_median": float(np.median([r["best_misfit"] for r in group])) if group else None,
        }
    write_text(
        args.out, json.dumps({"readings": MISFIT_READINGS, "summary": summary, "episodes": rows}, indent=1)
    )
    print(json.dumps(summary))


#: Radius (m) of ``stops``'s agreement and network-mass statistics.
RADIUS_M = 1.0
#: Hypotheses at least this heavy are counted as weighty.
WEIGHTY = 0.01


def stop_row(case: Case, row: dict[str, Any], network: Any) -> dict[str, Any]:
    """The statistics of the module doc for one episode's stop."""
    from dgse.planning.planners import mass_around, mass_within
    from dgse.world.grid import Grid

    obs = step_observations(row["steps"])
    est = map_estimator_at_end(case, obs, **PRESETS["dgse-phys"].estimator_options_at("map", search=True))
    belief = est.estimate(case.occupancy, case.resolution, obs)
    mx, my = belief.source_estimate()
    sx, sy = (float(v) for v in case.source)
    if abs(math.hypot(mx - sx, my - sy) - row["error_m"]) > 1e-6:
        raise SystemExit(
            f"{row['case']}: rebuilt mean {math.hypot(mx - sx, my - sy):.3f} m off, "
            f"the search's {row['error_m']:.3f} m"
        )
    grid = Grid(belief.shape, case.resolution)
    i, j = belief.most_likely_cell()
    mode = grid.center_of(i, j)
    hyps = belief.info["hypotheses"]
    weights = np.array([h["weight"] for h in hyps])
    agree = sum(
        h["weight"]
        for h in hyps
        if h["source_mode_xy"] is not None and math.dist(h["source_mode_xy"], mode) <= RADIUS_M
    )
    net = network.estimate(case.occupancy, case.resolution, obs)
    net_mode = grid.center_of(*net.most_likely_cell())
    net_disks = mass_within(net.source_probs, case.resolution, RADIUS_M)
    return {
        "error_m": row["error_m"],
        "within_2m": row["error_m"] <= SUCCESS_M,
        "readings": len(obs),
        "search_time_s": row["search_time_s"],
        "max_weight": float(weights.max()),
        "weighty_hypotheses": int((weights >= WEIGHTY).sum()),
        "agreement": float(agree),
        "wind_misfit": belief.info["wind_misfit"],
        "gas_misfit": belief.info["gas_misfit"],
        "network_mass_1m": mass_around(net.source_probs, case.resolution, (i, j), RADIUS_M),
        "network_peak_mass_1m": float(net_disks[case.occupancy == 0].max()),
        "network_mode_m": math.dist(net_mode, mode),
        "network_error_m": math.dist(net.source_estimate(), (sx, sy)),
    }


def stops(argv: list[str]) -> None:
    """``stops``: what a mass stop at ``map`` knew when it fired (module doc)."""
    from dgse.estimators.registry import get_estimator

    ap = _parser("stops", "what a mass stop at knowledge map knew when it fired")
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args(argv)
    network = get_estimator("dgse-s", model="default", seed=0, dtype="auto", channels_last=True)
    rows: dict[str, dict[str, Any]] = {}
    for name, (case, row) in sorted(journal_episodes(args.journals).items()):
        if row["reason"] != "converged":
            continue
        rows[name] = stop_row(case, row, network)
        print(
            name, {k: round(v, 3) if isinstance(v, float) else v for k, v in rows[name].items()}, flush=True
        )
    right = [r for r in rows.values() if r["within_2m"]]
    wrong = [r for r in rows.values() if not r["within_2m"]]
    keys = [
        "readings",
        "max_weight",
        "agreement",
        "wind_misfit",
        "gas_misfit",
        "network_mass_1m",
        "network_peak_mass_1m",
        "network_mode_m",
    ]
    summary: dict[str, Any] = {"mass_stops": len(rows), "within_2m": len(right)}
    for key in keys:
        summary[key] = {
            "right": [float(np.min([r[key] for r in right])), float(np.max([r[key] for r in right]))]
            if right
            else None,
            "wrong": sorted(float(r[key]) for r in wrong),
        }
    write_text(args.out, json.dumps({"summary": summary, "stops": rows}, indent=1) + "\n")
    print(json.dumps(summary))


_parser = partial(command_parser, "search.py")


COMMANDS: dict[str, Callable[[list[str]], None]] = {
    "run": run,
    "merge": merge,
    "cases": cases,
    "step-time": step_time,
    "speed": speed,
    "deadline": deadline,
    "misfit": misfit,
    "stops": stops,
}


def main(argv: list[str] | None = None) -> None:
    run_command(__doc__, COMMANDS, sys.argv[1:] if argv is None else argv)


if __name__ == "__main__":
    main()
