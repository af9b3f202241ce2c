"""Suite ``field``: closed-loop search with filament readings on paper-size, building-scale and
GADEN-format scenarios, beside the paper's DGSE-S table.

Every episode is :func:`dgse.search.campaign.run_trials`' (the search suite's runner,
:mod:`dgse.bench.search`): the simulated robot (0.5 m/s, 3 s per measurement, Table I sensor
noise) reads the time-varying frames of the filament model (:func:`dgse.bench.scenarios.variant_case`,
``dgse plume``'s simulator), never the steady field.  Trial ``r`` on scenario ``<stem>`` is seeded
by ``(seed, stem, r)``, so every method starts from the same cells with the same noise draws.

Scenario groups (:data:`GROUPS`):

* ``test``: the paper-size test scenarios, seeds 2000-2019
  (:func:`dgse.bench.scenarios.search_cases`, set ``test``);
* ``building``: the office floors of 20-30 m at 0.2 m cells
  (:func:`dgse.bench.scenarios.office_floor_cases`);
* ``gaden``: generated layouts written as GADEN scenario folders (ROS map, outlet models,
  simulation with the source, wind CSV) and imported back through ``dgse
  import-gaden-scenario``'s library function (:func:`dgse.bench.scenarios.gaden_cases`).

Methods: those of the search suite (:data:`dgse.bench.search.METHODS`, named methods of
:data:`dgse.presets.PRESETS`), each at the run's knowledge level (``--knowledge``; methods that
do not work there are left out and named), the slow ones (registry tag ``"slow"``: PMFS) with
the search suite's shorter time limit.

Per group and method the table gives the success rate (an episode succeeds when the method
stopped the search itself within the time limit with its estimate within 2 m of the source,
:func:`dgse.search.metrics.is_success`), the mean error, the mean and median search time ST,
the mean travelled distance TD, the median path efficiency ratio PER (TD / shortest path),
the median one-step computation time, and as a reference the shortest-path time: the
shortest obstacle-free path from the start to the source at the robot's speed plus one
dwell (the least time any search needs to stand at the source and read), averaged over the
same episodes.  The paper's DGSE-S numbers of its six GADEN environments
(:data:`PAPER_DGSE_S`) are a table of their own, set beside ours in ``summary.md``.

Sizes (full / quick): 20 / 1 test scenarios, 10 / 1 office floors, 3 / 1 GADEN-format
scenarios, 2 / 1 trials each, time limit 2000 s / 20 s (slow methods 300 s / 10 s), every
method / the cheap ones (:data:`QUICK_METHODS`), filament frames of the simulator's defaults
(120 s recorded, looped) / 20 s.

Resuming: every finished episode is kept in a journal per method and group
(``journals/<method>_<group>-<key>.jsonl``, :func:`run_trials`' ``journal``; the key is a hash
of the settings, so a run with other settings starts its own), and a rerun skips the kept
episodes; ``run_<method>_<group>.json`` holds each combined result and ``field_results.json``
the summaries.
"""

from __future__ import annotations

import hashlib
import json
import math
import statistics
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from dgse.bench.core import BenchContext
from dgse.bench.plots import plt
from dgse.bench.search import METHODS, SLOW_TIME_LIMIT, is_slow, progress_lines
from dgse.presets import PROTOCOL, Preset

__all__ = [
    "GROUPS",
    "PAPER_DGSE_S",
    "QUICK_METHODS",
    "TABLE_COLUMNS",
    "FieldPlan",
    "make_plan",
    "run",
    "shortest_path_time",
]

#: The scenario groups: name and how the report names them.
GROUPS: tuple[tuple[str, str], ...] = (
    ("test", "paper-size test scenarios"),
    ("building", "office floors"),
    ("gaden", "GADEN-format scenarios"),
)

#: The methods of a quick run: those whose one step takes well under a second on a small map.
QUICK_METHODS = ("dgse-s", "dualmode", "pf-infotaxis")

#: DGSE-S in the paper's six GADEN environments, mean (std) over 20 trials each, from the
#: paper's active-search table (label ``tab:active_search_results``): inlet velocity m/s,
#: release rate g/s, SR %, error m, ST s, TD m, one-step computation time s; PER from the
#: out-of-domain appendix (label ``app:shift``), which lists the in-domain PER per environment.
PAPER_DGSE_S: tuple[dict[str, Any], ...] = (
    {"environment": 1, "inlet_m_s": 0.5, "rate_g_s": 0.06, "sr_pct": 100, "error_m": (0.197, 0.076),
     "st_s": (65.69, 7.12), "td_m": (11.42, 0.54), "step_s": (0.108, 0.0105), "per": 1.18},
    {"environment": 2, "inlet_m_s": 1.0, "rate_g_s": 0.03, "sr_pct": 100, "error_m": (0.769, 0.368),
     "st_s": (158.94, 29.26), "td_m": (23.73, 2.57), "step_s": (0.125, 0.0386), "per": 1.51},
    {"environment": 3, "inlet_m_s": 1.5, "rate_g_s": 0.045, "sr_pct": 100, "error_m": (0.430, 0.118),
     "st_s": (107.52, 20.47), "td_m": (15.17, 1.89), "step_s": (0.117, 0.00871), "per": 1.77},
    {"environment": 4, "inlet_m_s": 2.0, "rate_g_s": 0.06, "sr_pct": 100, "error_m": (0.456, 0.428),
     "st_s": (136.27, 22.36), "td_m": (28.13, 2.54), "step_s": (0.114, 0.00688), "per": 1.82},
    {"environment": 5, "inlet_m_s": 2.0, "rate_g_s": 0.06, "sr_pct": 100, "error_m": (0.319, 0.161),
     "st_s": (54.14, 21.96), "td_m": (9.78, 1.78), "step_s": (0.0929, 0.00604), "per": 2.89},
    {"environment": 6, "inlet_m_s": 3.0, "rate_g_s": 0.09, "sr_pct": 100, "error_m": (0.376, 0.145),
     "st_s": (52.31, 13.08), "td_m": (14.98, 0.93), "step_s": (0.102, 0.00676), "per": 2.17},
)  # fmt: skip

#: The columns of the per-group table (``field_search.csv``), in order.
TABLE_COLUMNS = [
    "group",
    "method",
    "scenarios",
    "episodes",
    "SR [%]",
    "error [m]",
    "ST mean [s]",
    "ST median [s]",
    "TD [m]",
    "PER median",
    "step median [s]",
    "shortest-path time [s]",
]


@dataclass(frozen=True)
class FieldPlan:
    """The sizes of a run (full or quick)."""

    #: scenarios per group
    scenarios: Mapping[str, int]
    trials: int
    time_limit: float
    #: the methods run (before the knowledge level leaves any out)
    methods: tuple[str, ...]
    #: per method: ``time_limit`` where it differs (methods tagged ``"slow"``)
    overrides: Mapping[str, Mapping[str, Any]]
    #: per method: extra estimator options (a quick run: the preset's ``quick_options``)
    extra_options: Mapping[str, Mapping[str, Any]]
    #: the filament simulation's settings (:class:`~dgse.physics.filament.FilamentSettings`)
    filament: Any
    #: the filament frames' cache (a folder of ``OUT/_scenarios/``): one per setting
    filament_cache: str


def make_plan(ctx: BenchContext) -> FieldPlan:
    """The run's sizes (module docstring)."""
    from dgse.physics.filament import FilamentSettings

    methods = tuple(m.name for m in METHODS if not ctx.quick or m.name in QUICK_METHODS)
    chosen = [m for m in METHODS if m.name in methods]
    return FieldPlan(
        scenarios={"test": ctx.pick(20, 1), "building": ctx.pick(10, 1), "gaden": ctx.pick(3, 1)},
        trials=ctx.pick(2, 1),
        time_limit=ctx.pick(PROTOCOL.time_limit, 20.0),
        methods=methods,
        overrides={m.name: {"time_limit": ctx.pick(*SLOW_TIME_LIMIT)} for m in chosen if is_slow(m)},
        extra_options={m.name: dict(m.quick_options) for m in chosen if ctx.quick and m.quick_options},
        filament=ctx.pick(FilamentSettings(), FilamentSettings(duration=20.0, warmup=10.0)),
        filament_cache=ctx.pick("field-filament", "field-filament-quick"),
    )


def shortest_path_time(
    shortest_path_m: float | None, speed: float = PROTOCOL.speed, dwell: float = PROTOCOL.dwell
) -> float | None:
    """The least time a search from a start needs: its shortest path to the source at ``speed``
    plus one reading (``dwell``), s; None without a finite path."""
    if shortest_path_m is None or not math.isfinite(float(shortest_path_m)):
        return None
    return float(shortest_path_m) / float(speed) + float(dwell)


# -- scenarios ----------------------------------------------------------------------------------
def group_cases(ctx: BenchContext, plan: FieldPlan, group: str) -> list[tuple[Path, Any]]:
    """``(steady case file, case with filament frames)`` of the first scenarios of ``group``.

    The steady files are made once under ``OUT/_scenarios/`` (shared with the benchmark
    scripts' makers), the frames once into ``OUT/_scenarios/<plan.filament_cache>/``.
    """
    from dgse.bench.scenarios import SEARCH_SETS, gaden_cases, office_floor_cases, search_cases, variant_case
    from dgse.search.campaign import load_cases

    base = ctx.root / "_scenarios"
    n = int(plan.scenarios[group])
    if group == "test":
        folder = search_cases(base, "test", None if n >= len(SEARCH_SETS["test"]) else n)
    elif group == "building":
        folder = office_floor_cases(base, n)
    elif group == "gaden":
        folder = gaden_cases(base, n)
    else:
        raise ValueError(f"unknown group {group!r}")
    cache = ctx.scenario_dir(plan.filament_cache)
    steady = load_cases(folder)[:n]
    if len(steady) < n:
        ctx.note(f"{group}: {n - len(steady)} scenario(s) left out (their flow did not converge)")
    return [(p, variant_case(c, "filament", cache, p.stem, settings=plan.filament)) for p, c in steady]


# -- running ------------------------------------------------------------------------------------
def _key(settings: Mapping[str, Any]) -> str:
    """A short hash of a run's settings (its journal's name)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def _run_method(
    ctx: BenchContext,
    plan: FieldPlan,
    method: Preset,
    group: str,
    cases: list[tuple[Path, Any]],
) -> dict[str, Any]:
    """:func:`run_trials` of ``method`` on the group's cases, episodes kept in a journal."""
    from dgse.bench.core import jsonable
    from dgse.search.campaign import estimator_options, run_trials

    est_kw = estimator_options(
        method.estimator,
        seed=ctx.seed,
        options={
            **method.estimator_options_at(ctx.knowledge, search=True),
            **plan.extra_options.get(method.name, {}),
        },
    )
    plan_kw = method.planner_options_at(ctx.knowledge)
    time_limit = float(plan.overrides.get(method.name, {}).get("time_limit", plan.time_limit))
    key = _key(
        {
            "method": method.name,
            "estimator": method.estimator,
            "planner": method.planner,
            "estimator_options": est_kw,
            "planner_options": plan_kw,
            "time_limit": time_limit,
            "seed": ctx.seed,
            "knowledge": ctx.knowledge,
            "filament": asdict(plan.filament),
        }
    )
    journal = ctx.out / "journals" / f"{method.name}_{group}-{key}.jsonl"
    journal.parent.mkdir(parents=True, exist_ok=True)
    what = f"{method.display} {group}"
    name = f"run_{method.name}_{group}"
    counts: dict[str, int] = {}
    show = progress_lines(ctx, what)
    clock: dict[str, float] = {}

    def progress(desc: str, done: int, total: int) -> None:
        clock["start"] = time.perf_counter()  # called before every episode run (not the kept ones)
        if show is not None:
            show(desc, done, total)

    def finished(path: Path, case: Any, trial: int, result: Any) -> None:
        # each episode's cost, kept as it finishes: a resumed run's compute time includes it
        if "start" in clock:
            ctx.add_seconds(name, time.perf_counter() - clock.pop("start"))

    def started(kept: int, total: int) -> None:
        counts.update(kept=kept, total=total)
        if ctx.progress and kept:
            print(f"  {what}: {kept} of {total} episodes kept from an earlier run", flush=True)

    result = run_trials(
        cases,
        method.estimator,
        method.planner,
        plan.trials,
        ctx.seed,
        estimator_options=est_kw,
        planner_options=plan_kw,
        method=method.name,
        time_limit=time_limit,
        use_frames=True,
        progress=progress,
        on_episode=finished,
        on_start=started,
        journal=journal,
        knowledge=ctx.knowledge,
    )
    result["journal"] = str(journal.relative_to(ctx.out))
    result["episodes_kept"] = counts.get("kept", 0)
    ctx.save_json(name, result)
    return jsonable(result)


# -- tables -------------------------------------------------------------------------------------
def _episodes(run: Mapping[str, Any]) -> list[dict[str, Any]]:
    return [t for c in run["per_case"] for t in c["trials"]]


def _median(values: Sequence[float | None]) -> float | None:
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return statistics.median(v) if v else None


def _mean(values: Sequence[float | None]) -> float | None:
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return statistics.fmean(v) if v else None


def _round(v: float | None, digits: int) -> float | None:
    return None if v is None else round(v, digits)


def table_row(group: str, method: Preset, run: Mapping[str, Any]) -> dict[str, Any]:
    """One row of the per-group table from a :func:`run_trials` result (numbers, not strings)."""
    eps = _episodes(run)
    agg = run["aggregate"]
    speed = float(run["settings"].get("speed", PROTOCOL.speed))
    dwell = float(run["settings"].get("dwell", PROTOCOL.dwell))
    sr = agg.get("success_rate")
    return {
        "group": group,
        "method": method.display,
        "scenarios": len(run["per_case"]),
        "episodes": len(eps),
        "SR [%]": None if sr is None else round(100.0 * sr, 1),
        "error [m]": _round(agg.get("error_m_mean"), 3),
        "ST mean [s]": _round(agg.get("search_time_s_mean"), 1),
        "ST median [s]": _round(agg.get("search_time_s_median"), 1),
        "TD [m]": _round(agg.get("distance_m_mean"), 2),
        "PER median": _round(agg.get("per_median"), 2),
        "step median [s]": _round(agg.get("step_seconds_median"), 4),
        "shortest-path time [s]": _round(
            _mean([shortest_path_time(t.get("shortest_path_m"), speed, dwell) for t in eps]), 1
        ),
    }


PAPER_COLUMNS = [
    "environment",
    "inlet [m/s]",
    "rate [g/s]",
    "SR [%]",
    "error [m]",
    "ST [s]",
    "TD [m]",
    "step [s]",
    "PER",
]


def paper_rows() -> list[dict[str, Any]]:
    """:data:`PAPER_DGSE_S` as table rows (means; the std in the text columns) and their mean."""
    rows = []
    for e in PAPER_DGSE_S:
        rows.append(
            {
                "environment": str(e["environment"]),
                "inlet [m/s]": e["inlet_m_s"],
                "rate [g/s]": e["rate_g_s"],
                "SR [%]": e["sr_pct"],
                "error [m]": e["error_m"][0],
                "ST [s]": e["st_s"][0],
                "TD [m]": e["td_m"][0],
                "step [s]": e["step_s"][0],
                "PER": e["per"],
            }
        )
    mean = {"environment": "mean"}
    for c in PAPER_COLUMNS[3:]:
        mean[c] = round(statistics.fmean(float(r[c]) for r in rows), 4)
    return [*rows, mean]


# -- figures ------------------------------------------------------------------------------------
def _figure(
    methods: Sequence[Preset], runs: Mapping[str, Mapping[str, Mapping[str, Any]]], paper: Mapping[str, Any]
) -> Any:
    """Box plots of ST and PER per method, one column per group; ST beside the shortest-path
    times of the same episodes, the paper's DGSE-S mean over its six environments dotted."""
    groups = [g for g, _ in GROUPS if g in runs]
    fig, axes = plt.subplots(2, len(groups), figsize=(4.2 * len(groups), 6.4), squeeze=False)
    for c, group in enumerate(groups):
        names = [m for m in methods if m.name in runs[group]]
        for r, (metric, label) in enumerate((("search_time_s", "ST [s]"), ("per", "PER"))):
            ax = axes[r, c]
            data, labels, colours = [], [], []
            for m in names:
                eps = _episodes(runs[group][m.name])
                v = [t["metrics"].get(metric) for t in eps]
                data.append([float(x) for x in v if x is not None and math.isfinite(float(x))] or [math.nan])
                labels.append(m.display)
                colours.append(m.colour or "#777777")
            if metric == "search_time_s" and names:
                run0 = runs[group][names[0].name]
                sp = [shortest_path_time(t.get("shortest_path_m")) for t in _episodes(run0)]
                data.append([x for x in sp if x is not None] or [math.nan])
                labels.append("shortest path")
                colours.append("#bbbbbb")
            box = ax.boxplot(data, patch_artist=True, widths=0.6, showfliers=True)
            for patch, colour in zip(box["boxes"], colours, strict=True):
                patch.set_facecolor(colour)
                patch.set_alpha(0.75)
            ax.set_xticks(range(1, len(labels) + 1), labels, rotation=35, ha="right", fontsize=7)
            ref = paper.get("ST [s]" if metric == "search_time_s" else "PER")
            if ref is not None:
                ax.axhline(
                    float(ref),
                    ls=":",
                    color="k",
                    lw=1.0,
                    label="the paper's DGSE-S (mean of its 6 GADEN environments)",
                )
            if metric == "search_time_s":
                ax.set_yscale("log")
                plain = plt.matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
                ax.yaxis.set_major_formatter(plain)
                ax.yaxis.set_minor_formatter(plain)
                ax.tick_params(axis="y", which="minor", labelsize=6)
                ax.set_title(dict(GROUPS)[group], fontsize=9)
            else:
                ax.axhline(1.0, ls="--", color="#999999", lw=0.8, label="the shortest path (PER 1)")
            ax.set_ylabel(label)
            ax.grid(axis="y", alpha=0.3)
    seen: dict[str, Any] = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            seen.setdefault(lab, h)
    if seen:
        fig.legend(
            list(seen.values()), list(seen), loc="lower center", ncol=len(seen), frameon=False, fontsize=8
        )
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return fig


# -- the suite ----------------------------------------------------------------------------------
def run(ctx: BenchContext) -> None:
    """The field suite (module docstring): every method on every group, then the tables and
    the figure."""
    plan = make_plan(ctx)
    wanted = [m for m in METHODS if m.name in plan.methods]
    kept, _ = ctx.methods_at_level(list(dict.fromkeys(m.estimator for m in wanted)))
    methods = [m for m in wanted if m.estimator in kept]
    runs: dict[str, dict[str, dict[str, Any]]] = {}
    rows = []
    labels: dict[str, list[str]] = {}
    for group, _ in GROUPS:
        cases = group_cases(ctx, plan, group)
        labels[group] = [p.stem for p, _ in cases]
        runs[group] = {m.name: _run_method(ctx, plan, m, group, cases) for m in methods}
        rows += [table_row(group, m, runs[group][m.name]) for m in methods]
    paper = paper_rows()
    mine_rows = {(r["group"], r["method"]): r for r in rows}
    kept_eps = sum(int(r.get("episodes_kept", 0)) for g in runs.values() for r in g.values())
    total_eps = sum(len(_episodes(r)) for g in runs.values() for r in g.values())
    summary = {
        "plan": {
            "scenarios": dict(plan.scenarios),
            "trials": plan.trials,
            "time_limit_s": plan.time_limit,
            "methods": [m.name for m in methods],
            "overrides": plan.overrides,
            "extra_estimator_options": plan.extra_options,
            "filament": asdict(plan.filament),
            "speed": PROTOCOL.speed,
            "dwell": PROTOCOL.dwell,
        },
        "scenarios": labels,
        "aggregate": {g: {m: r["aggregate"] for m, r in rr.items()} for g, rr in runs.items()},
        "table": list(mine_rows.values()),
        "episodes": {"total": total_eps, "kept_from_earlier_runs": kept_eps},
    }
    ctx.save_json("field_results", summary)

    n = {g: len(labels[g]) for g, _ in GROUPS}
    slow = "".join(
        f" {m.display} ran with a time limit of {plan.overrides[m.name]['time_limit']:g} s "
        "(seconds per step)."
        for m in methods
        if m.name in plan.overrides
    )
    sec = ctx.section(
        "Search with filament readings: paper-size, building-scale and GADEN-format scenarios",
        f"Closed-loop search (the search suite's runner) where every reading comes from the "
        f"time-varying frames of the filament model ({plan.filament.duration:g} s recorded, looped), on "
        f"{n['test']} paper-size test scenario(s) (seeds from 2000), {n['building']} office floor(s) of "
        f"20-30 m at 0.2 m cells and {n['gaden']} GADEN-format scenario(s): generated layouts written "
        f"as GADEN scenario folders (ROS map, outlet models, simulation with the source, wind CSV) and "
        f"imported back through dgse's GADEN scenario import, solved again with the built-in solver. "
        f"{plan.trials} trial(s) per scenario, the same starts and sensor noise for every method; robot "
        f"{PROTOCOL.speed:g} m/s, {PROTOCOL.dwell:g} s per measurement, time limit {plan.time_limit:g} s, "
        f"start at least {PROTOCOL.min_start_distance:g} m (path) from the source. Every method at "
        f"knowledge {ctx.knowledge!r} with its preset's options.{slow} SR: the share of episodes the "
        f"method ended itself within the time limit with its estimate within 2 m of the source. "
        f"Shortest-path time: the shortest obstacle-free path from the start to the source at the "
        f"robot's speed plus one measurement, the least a search can take (mean over the episodes).",
    )
    sec.table(
        "field_search",
        rows,
        "Search with filament readings per scenario group and method: SR, mean error, mean and median "
        "search time ST, mean travelled distance TD, median path efficiency ratio PER (TD / shortest "
        "path), median one-step computation time, and the shortest-path time of the same episodes.",
        TABLE_COLUMNS,
    )
    per_rows = []
    for group, _ in GROUPS:
        for m in methods:
            run_ = runs[group][m.name]
            for c in run_["per_case"]:
                one = {**run_, "per_case": [c], "aggregate": c["metrics"]}
                per_rows.append({**table_row(group, m, one), "scenario": Path(c["file"]).stem})
    sec.table(
        "field_search_per_scenario",
        per_rows,
        "The same per scenario.",
        ["group", "scenario", *TABLE_COLUMNS[1:2], *TABLE_COLUMNS[3:]],
    )
    sec.figure(
        _figure(methods, runs, paper[-1]),
        "field_st_per",
        "Search time ST (log scale, beside the shortest-path times of the same episodes) and path "
        "efficiency ratio PER per method, one column per scenario group; dotted: the paper's DGSE-S "
        "mean over its six GADEN environments.",
    )
    psec = ctx.section(
        "The paper's DGSE-S in its GADEN environments (tab:active_search_results)",
        "DGSE-S as the paper reports it: six GADEN environments, 20 trials each, mean over trials; "
        "SR, error, ST, TD and one-step time from its active-search table, PER from its out-of-domain "
        "appendix (the in-domain values it lists); the last row is the mean over the environments.",
    )
    psec.table(
        "paper_dgse_s",
        paper,
        "DGSE-S in the paper's six GADEN environments (the paper's numbers; not run here).",
        PAPER_COLUMNS,
    )
    if kept_eps:
        ctx.note(
            f"{kept_eps} of {total_eps} episodes were kept from an earlier run (the journals in "
            f"journals/); the wall time covers this invocation only."
        )
