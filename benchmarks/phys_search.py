"""Active search with dgse-phys: success, error, stops that mean something.

Runs the utility planner on generated scenarios with a method at a knowledge
level and a stop rule, and writes the search metrics plus the share of
entropy stops within 2 m of the source (``stops_within_2m``: a stop must mean
something).  Case sets (made once, into ignored ``_cases_<set>/`` folders):

* ``validation``: seeds 900-907 (the range the dgse-phys parameters were tuned on);
* ``validation2``: seeds 908-923, more validation scenarios (to see rare failures such as
  wrong stops before choosing a rule against them);
* ``validation3``: seeds 924-963, 40 more (rare failures of the stop rule show on 40 that
  hide on 24); a seed whose flow does not converge is left out (a ``.unconverged`` note);
* ``test``: seeds 2000-2019 (never used for tuning).

Stop rules (``--rule``; the utility planner's settings, :mod:`dgse.planning.planners`):

* ``paper``: the entropy test from the 5th reading (``stop.min_observations=5``);
* ``paper-eta0.78``: the same with the shipped DGSE-S's threshold (``dgse demo``'s, tuned on
  the validation split by ``benchmarks/tune_eta.py``);
* ``confirm``: the same, and a stop needs 2 readings within 1 m of the posterior's
  mode (``stop.confirm_radius_m=1``, ``stop.confirm_readings=2``);
* ``mass1m90`` / ``mass2m95``: instead of the entropy test, stop once the posterior
  holds 90 % within 1 m (95 % within 2 m) of its mode (``stop.mass_radius_m``, ``stop.mass_level``);
* ``mass1m90-disk1m`` / ``mass1m90-disk0.5m``: ``mass1m90``, and the utility's source term
  is the posterior mass within 1 m (0.5 m) of a cell (``weights.source_radius_m``), not the cell's own;
* ``mass1m90-disk1m-deadline60s``: and the search stops with its estimate once less than 60 s
  of the time limit is left (``deadline.margin_s``); such stops are counted apart
  (``deadline_stops``);
* ``mass1m90-disk1m-deadline60s-revisit0.5m``: and the variance terms of a cell are divided by
  one plus the cells measured within 0.5 m of it (``weights.revisit_radius_m``);
* ``...-revisit0.5m-confirm1m``: and a stop needs 2 readings within 1 m of the mode (as ``confirm``);
* ``...-revisit0.5m-gas1m``: and a stop needs 1 reading within 1 m of the mode above twice the
  estimator's noise floor (``stop.confirm_readings=1``, ``stop.confirm_sigmas=2``): gas smelt there.
  Every trial records the stops the confirmation held (``held_stops``) and the error of the
  first (``first_held_error_m``): what the rule without it would have reported, in the same run.
  This rule is the dgse-phys preset's planner (:data:`dgse.presets.PRESETS`); at knowledge
  ``map`` the preset adds ``stop.max_wind_misfit=0.7`` and ``deadline.estimate_radius_m=1``:
  run it with ``-P stop.max_wind_misfit=0.7 -P deadline.estimate_radius_m=1.0`` (files tagged
  ``fit0.7-disk1``).

``dgse-phys`` runs with the preset's search options (what ``dgse demo`` uses); ``-E``
overrides them, and ``-P`` a planner option of the rule (``-P stop.min_observations=60``: no
entropy or mass stop before 60 readings).

Every finished episode is journaled beside the JSON, so an interrupted run resumes::

    python benchmarks/phys_search.py --set validation --rule confirm --knowledge openings

Episodes run apart (one ``--files`` case per process, on several machines or cores) are
summed up into one result by ``--merge OUT.json EPISODE.json...``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from phys_robustness import VARIANTS as ROBUSTNESS_VARIANTS  # this folder's
from phys_robustness import perturbed_wind

from dgse.files import write_text
from dgse.presets import PRESETS
from dgse.search.campaign import json_safe, run_trials

SETS = {
    "validation": range(900, 908),
    "validation2": range(908, 924),
    "validation3": range(924, 964),
    "test": range(2000, 2020),
}
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
    from dgse.world.case import Case

    out: dict[str, tuple[Any, dict[str, Any]]] = {}
    for journal in journals:
        for line in journal.read_text().splitlines()[1:]:
            entry = json.loads(line)
            if "steps" not in entry["row"]:
                raise SystemExit(f"{journal}: no steps recorded; run the search with --steps")
            found = sorted(journal.parent.glob(f"_cases_*/{entry['case']}.npz"))
            if not found:
                raise SystemExit(f"no case file {entry['case']}.npz beside {journal}")
            out[entry["case"]] = (Case.load(found[0]), entry["row"])
    return out


def step_observations(steps: list[dict[str, Any]]) -> Any:
    """The readings of a journaled episode's steps as :class:`~dgse.sensing.sensors.Observations`."""
    import numpy as np

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


def cases_dir(out: Path, name: str, limit: int | None = None) -> Path:
    """The generated scenarios of a set (the first ``limit``) as case files (made once)."""
    from dgse.errors import ConvergenceError
    from dgse.physics.scenario import random_cases

    seeds = list(SETS[name])[:limit]
    d = out / (f"_cases_{name}" if limit is None else f"_cases_{name}_{len(seeds)}")
    d.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        path = d / f"{name.rstrip('0123456789')}{seed}_src0.npz"
        skip = path.with_suffix(".unconverged")
        if path.exists() or skip.exists():
            continue
        try:
            random_cases(seed, n_sources=1)[0].save(path)
        except ConvergenceError as e:  # left out, as the dataset leaves such layouts out
            write_text(skip, f"{e}\n")
            print(f"seed {seed} left out: {e}", flush=True)
    return d


def told_wind_estimator(method: str, options: dict[str, Any], variant: str) -> Any:
    """``method`` built with ``options``, told at knowledge ``wind`` the case's wind perturbed as
    ``variant`` of ``benchmarks/phys_robustness.py`` (the readings stay the case's)."""
    from dataclasses import replace

    from dgse.estimators.registry import get_estimator

    est = get_estimator(method, **options)
    tell = est.set_knowledge

    def set_knowledge(knowledge: Any) -> None:
        if knowledge.wind is not None:
            knowledge = replace(knowledge, wind=perturbed_wind(knowledge, variant))
        tell(knowledge)

    est.set_knowledge = set_knowledge
    return est


def record_calls(
    owner: Any, name: str, path: Path, every: int, estimator_options: dict[str, Any] | None = None
) -> list[tuple[tuple, dict]]:
    """The arguments (arrays copied) of every ``every``-th call of ``owner.name`` during one
    dgse-phys search episode on ``path`` (knowledge ``openings``, ``SEARCH_PLANNER``; the
    estimator's defaults, or ``estimator_options``)."""
    original = getattr(owner, name)
    kept: list[tuple[tuple, dict]] = []
    n = [0]

    def copy(v: Any) -> Any:
        return v.copy() if hasattr(v, "copy") and hasattr(v, "shape") else v

    def keep(*a: Any, **kw: Any) -> Any:
        if n[0] % every == 0:
            kept.append((tuple(copy(v) for v in a), {k: copy(v) for k, v in kw.items()}))
        n[0] += 1
        return original(*a, **kw)

    setattr(owner, name, keep)
    try:
        run_trials(
            path, "dgse-phys", "utility", trials=1, knowledge="openings",
            planner_options={"stop.min_observations": 5, **PRESETS["dgse-phys"].planner_options},
            estimator_options=estimator_options,
        )  # fmt: skip
    finally:
        setattr(owner, name, original)
    return kept


def stop_quality(result: dict[str, Any]) -> dict[str, Any]:
    """Entropy stops (episodes that terminated) and the share of them within 2 m of the source."""
    rows = [t for c in result["per_case"] for t in c["trials"]]
    ended = [t for t in rows if t.get("terminated")]
    late = [t for t in ended if t.get("reason") == "deadline"]
    stops = [t for t in ended if t.get("reason") != "deadline"]
    near = [t for t in stops if t["error_m"] <= 2.0]
    out: dict[str, Any] = {
        "episodes": len(rows),
        "entropy_stops": len(stops),
        "stops_within_2m": len(near),
        "stops_within_2m_share": (len(near) / len(stops)) if stops else None,
        "deadline_stops": len(late),
        "deadline_stops_within_2m": sum(t["error_m"] <= 2.0 for t in late),
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
                "found": sum(e <= 2.0 for e, _ in w),
                "error_m_mean": sum(e for e, _ in w) / len(w),
                "mass_stops": len(w_stops),
                "mass_stops_within_2m": sum(e <= 2.0 for e in w_stops),
            },
        }
    # the deadline stops read every way (``end_errors_m``: what each point estimate of the final
    # belief would have declared), so that ``deadline_estimate_radius_m`` is chosen from one run
    recorded = [t for t in late if t.get("end_errors_m")]
    if recorded:
        ways = sorted(recorded[0]["end_errors_m"])
        out["deadline_estimates"] = {
            w: {
                "error_m_mean": sum(t["end_errors_m"][w] for t in recorded) / len(recorded),
                "within_2m": sum(t["end_errors_m"][w] <= 2.0 for t in recorded),
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
#: ``max_wind_misfit`` only holds stops (a stop test that passed returns False instead), so an
#: episode that ended at its deadline is the same with it; ``deadline_estimate_radius_m`` only
#: changes what a deadline stop declares, so an episode that stopped before is the same.
FILL_OPTIONS = {"stop.max_wind_misfit": "deadline", "deadline.estimate_radius_m": "converged"}


def _without(settings: dict[str, Any], option: str | None) -> dict[str, Any]:
    planner = {k: v for k, v in settings.get("planner_options", {}).items() if k != option}
    return {**settings, "planner_options": planner}


def merge(paths: list[Path], fill: Path | None = None, fill_option: str | None = None) -> dict[str, Any]:
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=sorted(SETS), default="validation")
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
        choices=[v for v in ROBUSTNESS_VARIANTS if v.startswith("wind_")],
        help="at --knowledge wind, tell the estimator the case's wind perturbed as in "
        "benchmarks/phys_robustness.py (a user's CFD that is off); the robot still reads the true wind",
    )
    ap.add_argument("--tag", default="", help="appended to the output names (a variant's own files)")
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_search"))
    ap.add_argument(
        "--merge",
        type=Path,
        nargs="+",
        metavar=("OUT", "RESULT"),
        help="write OUT.json from the RESULT JSON files of runs made apart; run nothing",
    )
    ap.add_argument(
        "--fill",
        type=Path,
        default=None,
        metavar="BASE",
        help="with --merge: the deadline episodes of BASE, a run without --fill-option, for the cases "
        "the runs lack (see merge)",
    )
    ap.add_argument("--fill-option", default=None, choices=sorted(FILL_OPTIONS))
    args = ap.parse_args()
    if args.cases is not None and args.cases < 1:
        ap.error(f"--cases must be at least 1, got {args.cases}")
    if args.merge:
        if len(args.merge) < 2:
            ap.error("--merge takes OUT and at least one RESULT")
        result = merge(args.merge[1:], args.fill, args.fill_option)
        write_result(args.merge[0], result, args.merge[0].stem, f", stops {result['stops']}")
        return
    args.out.mkdir(parents=True, exist_ok=True)
    set_name = args.set if args.cases is None else f"{args.set}{args.cases}"
    if args.files:
        from dgse.world.case import Case

        cases = [(f, Case.load(f)) for f in args.files]
        set_name = f"{args.set}-files{len(cases)}"
    else:
        cases = cases_dir(args.out, args.set, args.cases)
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
        estimator = told_wind_estimator(args.method, est_opts, args.told_wind)
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


if __name__ == "__main__":
    main()
