"""dgse-phys in active search: the searches, their step cost, and the proposals at ``map``.

One command per measurement (``python benchmarks/search.py COMMAND --help``); results go to
``benchmarks/results/phys_search/`` (``-o``):

* ``run``: a method's searches on a scenario set (``dgse.bench.scenarios.SEARCH_SETS``: seeds
  900-907 ``validation``, 908-923 ``validation2``, 924-963 ``validation3``, 2000-2019
  ``test``; made once into ignored ``_cases_<set>/`` folders, ``cases`` makes them alone) at a
  knowledge level, as ``dgse search`` runs them: the method's preset (:mod:`dgse.presets`:
  estimator options, planner and planner options at the level; ``--planner`` another
  registered planner with its own defaults), ``-E`` over an estimator option, ``-P`` over a
  planner option; writes the search metrics and how the searches ended (``stops``: stops of
  the stop test and how many lie within 2 m of the source, deadline stops and what each point
  estimate of their final beliefs would have declared).  Every finished episode is journaled
  beside the JSON, so an interrupted run resumes; ``--steps`` keeps every step's readings in
  the journal (what ``misfit`` rebuilds proposals from).  Output names:
  ``<set>_<method>_<level>_<planner>[_<tag>].json``::

      python benchmarks/search.py run --set validation --knowledge openings
      python benchmarks/search.py run --set validation3 --knowledge map --seed 1 --tag s1-steps --steps
      python benchmarks/search.py run --set test --knowledge wind --told-wind wind_smoothed --tag smoothed-s0

  The result files named ``<set>_<method>_<level>_<rule>[_<tag>].json`` (``paper``,
  ``mass1m90``, ``...-revisit0.5m-gas1m``) are searches with the utility planner and one of
  the stop rules it had then (the mass stop, its confirmation, the disk source term, the
  revisit discount, the held stop on the wind misfit, a deadline); this script at commit
  41797cb runs them (``run --rule``), with its ``deadline`` and ``stops`` commands that
  rebuilt their final beliefs.  Of the noise-weight comparisons of ``docs/decisions.md``,
  ``seed0-mix`` ran the mixture as dgse-phys runs it now; ``seed0``, ``seed0-cand`` and
  ``seed0-larger`` ran one weighting alone through a dgse-phys option that is removed
  (``-E 'noise_weights="plug-in"'``, ``"candidate"``, ``"larger"``; this script at commit
  7ba21b2 takes it).
* ``merge``: one result from the JSON files of runs made apart (one ``--files`` case per
  process): ``python benchmarks/search.py merge OUT.json RESULT.json...``.
* ``step-time``: the computation seconds of every search step of dgse-phys with its preset
  (the first estimate, which solves the flows, and the median and 90th percentile of the
  rest) on the first test scenarios; writes ``step_time.json`` (``step_time_map.json`` at
  ``map``)::

      python benchmarks/search.py step-time --cases 20
      python benchmarks/search.py step-time --cases 1 --knowledge map

* ``speed``: the wall-clock cost of dgse-phys at each knowledge level
  (:func:`dgse.bench.speed.speed_table`): one search per validation scenario with the preset
  (first step, median step) and one random-readings estimate per count with nothing cached;
  writes ``benchmarks/results/speed/<tag>.json`` (``-o`` a folder)::

      python benchmarks/search.py speed --cases 2 --counts 20 50 --tag before

* ``misfit``: were the true openings among dgse-phys's proposals at ``map`` (from an
  episode's first 64 wind readings), and what was the best proposal's wind misfit, for
  searches at ``map`` journaled with ``--steps``::

      python benchmarks/search.py run --set validation3 --knowledge map --tag s0-steps --steps
      python benchmarks/search.py misfit \\
          benchmarks/results/phys_search/validation3_dgse-phys_map_info_s0-steps.journal.jsonl \\
          -o benchmarks/results/phys_search/map_proposal_misfit_validation3_info.json

  (``map_proposal_misfit_validation3*.json`` are of the utility planner's searches, journals
  of ``run --rule`` at commit 41797cb.)

``misfit`` reads journals as written or gzipped; the case files they name are the set's
(``python benchmarks/search.py cases --set validation3``).  A setting is only ever chosen on
validation episodes; the test split's are for reporting.
"""

from __future__ import annotations

import gzip
import json
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
from dgse.presets import resolve
from dgse.search.campaign import json_safe, run_trials
from dgse.world.case import Case

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "phys_search"
#: A stop within this distance of the source means something.
SUCCESS_M = 2.0


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
    """The stop test's stops (reason ``converged``) and the share of them within 2 m of the
    source; the deadline stops and what each point estimate would have declared at them."""
    rows = [t for c in result["per_case"] for t in c["trials"]]
    ended = [t for t in rows if t.get("terminated")]
    late = [t for t in ended if t.get("reason") == "deadline"]
    stops = [t for t in ended if t.get("reason") != "deadline"]
    near = [t for t in stops if t["error_m"] <= SUCCESS_M]
    out: dict[str, Any] = {
        "episodes": len(rows),
        "converged_stops": len(stops),
        "stops_within_2m": len(near),
        "stops_within_2m_share": (len(near) / len(stops)) if stops else None,
        "deadline_stops": len(late),
        "deadline_stops_within_2m": sum(t["error_m"] <= SUCCESS_M for t in late),
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
#: ``deadline.estimate_radius_m`` only changes what a deadline stop declares, so an episode that
#: stopped before is the same.
FILL_OPTIONS = {"deadline.estimate_radius_m": "converged"}
#: The names the result files recorded before the settings objects give those options.
RECORDED_NAMES = {"deadline.estimate_radius_m": "deadline_estimate_radius_m"}


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
    """``run``: a method's searches of a scenario set at a knowledge level (module doc)."""
    ap = _parser("run", "active search on a scenario set with a method (its preset) at a knowledge level")
    ap.add_argument("--set", choices=sorted(SEARCH_SETS), default="validation")
    ap.add_argument("--method", default="dgse-phys")
    ap.add_argument(
        "--planner",
        default=None,
        help="another registered planner than the method's (its own defaults then apply, as "
        "`dgse search --planner`)",
    )
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
        help="a planner option over the preset's, e.g. -P stop.min_observations=60 (repeatable)",
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
    user: dict[str, dict[str, Any]] = {}
    for flag, items in (("-E", args.estimator_option), ("-P", args.planner_option)):
        user[flag] = {}
        for item in items:
            key, sep, value = item.partition("=")
            if not sep:
                ap.error(f"{flag} takes KEY=JSON, got {item!r}")
            user[flag][key] = json.loads(value)
    # the method as dgse search runs it (its preset at the level), the user's options on top
    method = resolve(
        args.method,
        args.knowledge,
        search=True,
        planner=args.planner,
        estimator_options=user["-E"],
        planner_options=user["-P"],
    )
    est_opts = method.estimator_options
    tag = f"_{args.tag}" if args.tag else ""
    stem = f"{set_name}_{args.method}_{args.knowledge}_{method.planner}{tag}"
    if args.told_wind is not None and args.knowledge != "wind":
        ap.error("--told-wind changes only what --knowledge wind is told")
    estimator: Any = method.estimator
    if args.told_wind is not None:
        from dgse.estimators.registry import get_estimator

        estimator = ToldWind(get_estimator(method.estimator, **est_opts), args.told_wind)
    result = run_trials(
        cases,
        estimator,
        method.planner,
        method=args.method,
        trials=args.trials,
        seed=args.seed,
        planner_options=method.planner_options,
        estimator_options=est_opts,
        knowledge=args.knowledge,
        steps=args.steps,
        journal=args.out / f"{stem}.journal.jsonl",
    )
    for case in result["per_case"]:  # steps stay in the journal: the JSON keeps the summaries
        for trial in case["trials"]:
            trial.pop("steps", None)
    result["stops"] = stop_quality(result)
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
    method = resolve("dgse-phys", args.knowledge, search=True)
    rows = []
    for path in sorted(d.glob("*.npz")):
        res = run_trials(
            path,
            method.estimator,
            method.planner,
            trials=1,
            planner_options=method.planner_options,
            estimator_options=method.estimator_options,
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
        "estimator_options": method.estimator_options,
        "planner": method.planner,
        "planner_options": method.planner_options,
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


_parser = partial(command_parser, "search.py")


COMMANDS: dict[str, Callable[[list[str]], None]] = {
    "run": run,
    "merge": merge,
    "cases": cases,
    "step-time": step_time,
    "speed": speed,
    "misfit": misfit,
}


def main(argv: list[str] | None = None) -> None:
    run_command(__doc__, COMMANDS, sys.argv[1:] if argv is None else argv)


if __name__ == "__main__":
    main()
