"""The wall-clock cost of ``dgse-phys`` at each knowledge level, as a user meets it.

* :func:`search_times`: one search with the method's preset at a level (:mod:`dgse.presets`):
  the first step's seconds (the flows are solved there), the median and 90th percentile of
  the others, and the search's error;
* :func:`estimate_times`: random-readings estimates (Table I noise, :mod:`dgse.evaluation`'s
  draw) by a fresh estimator with no flow cached: the seconds and the SL error of each;
* :func:`speed_table`: both over cases and levels, with the medians a target compares to.

Every timing starts with an empty flow cache (:func:`dgse.posterior.adjoint.clear_flow_cache`),
so a first estimate pays for its flows as in a new process; the network DGSE-S and the
compiled kernels are loaded once beforehand (:func:`warm_up`), as a long-running process has them.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dgse.belief.knowledge import Knowledge
from dgse.presets import PHYSICS_METHOD, PRESETS
from dgse.world.case import Case

__all__ = ["estimate_times", "search_times", "speed_table", "warm_up"]

METHOD = PHYSICS_METHOD


def warm_up(case: Case) -> None:
    """Load what every process loads once (DGSE-S's weights, the numba kernels' caches) with one
    small estimate at ``map``, so the timings after it are the method's own."""
    from dgse.estimators.registry import get_estimator
    from dgse.evaluation.evaluate import draw_observations

    est = get_estimator(METHOD, **PRESETS[METHOD].estimator_options_at("map", search=False))
    est.set_knowledge(Knowledge.from_case(case, "map"))
    est.estimate(case.occupancy, case.resolution, draw_observations(case, 5, 0))


def search_times(path: Path, level: str, seed: int = 0) -> dict[str, Any]:
    """One search of ``dgse-phys`` (its preset at ``level``) on the case file ``path``: its steps'
    computation seconds (``first_s``, ``median_s`` and ``p90_s`` of the steps after the first,
    every step's in ``step_s``), the steps, how it ended and its error, m."""
    from dgse.posterior.adjoint import clear_flow_cache
    from dgse.search.campaign import run_trials

    p = PRESETS[METHOD]
    clear_flow_cache()
    res = run_trials(
        path,
        METHOD,
        p.planner,
        trials=1,
        seed=seed,
        planner_options=p.planner_options_at(level),
        estimator_options=p.estimator_options_at(level, search=True),
        knowledge=level,
        steps=True,
    )
    trial = res["per_case"][0]["trials"][0]
    s = np.array([st["compute_s"] for st in trial["steps"]])
    rest = s[1:] if s.size > 1 else s
    return {
        "case": path.stem,
        "level": level,
        "steps": int(s.size),
        "first_s": float(s[0]),
        "median_s": float(np.median(rest)),
        "p90_s": float(np.percentile(rest, 90)),
        "reason": trial["reason"],
        "error_m": trial["error_m"],
        "step_s": [round(float(x), 4) for x in s],
    }


def estimate_times(case: Case, level: str, counts: Sequence[int], seed: int = 0) -> list[dict[str, Any]]:
    """One random-readings estimate of ``dgse-phys`` (its preset at ``level``, outside a search)
    per count of readings, each by a fresh estimator with no flow cached: seconds, SL error."""
    from dgse.estimators.registry import get_estimator
    from dgse.evaluation.evaluate import draw_observations
    from dgse.posterior.adjoint import clear_flow_cache

    rows = []
    for n in counts:
        obs = draw_observations(case, int(n), seed)
        clear_flow_cache()
        est = get_estimator(METHOD, **PRESETS[METHOD].estimator_options_at(level, search=False))
        est.set_knowledge(Knowledge.from_case(case, level))
        t0 = time.perf_counter()
        belief = est.estimate(case.occupancy, case.resolution, obs)
        rows.append(
            {
                "case": case.name,
                "level": level,
                "readings": int(n),
                "seconds": time.perf_counter() - t0,
                "sl_error_m": belief.localization_error(case.source),
            }
        )
    return rows


def speed_table(
    paths: Sequence[Path],
    levels: Sequence[str],
    counts: Sequence[int],
    seed: int = 0,
    searches: bool = True,
    progress: Any = None,
) -> dict[str, Any]:
    """:func:`search_times` and :func:`estimate_times` on every case file of ``paths`` at every
    level, and per level the median step, the median first step and the median estimate seconds
    (pooled over the cases).  ``progress(row)`` sees every row as it is made."""
    cases = [Case.load(p) for p in paths]
    warm_up(cases[0])
    searched: list[dict[str, Any]] = []
    estimated: list[dict[str, Any]] = []
    for level in levels:
        for path, case in zip(paths, cases, strict=True):
            rows = [search_times(Path(path), level, seed)] if searches else []
            rows += [{**r, "case": Path(path).stem} for r in estimate_times(case, level, counts, seed)]
            for row in rows:
                (searched if "steps" in row else estimated).append(row)
                if progress is not None:
                    progress(row)
    summary: dict[str, Any] = {}
    for level in levels:
        s = [r for r in searched if r["level"] == level]
        e = [r for r in estimated if r["level"] == level]
        summary[level] = {
            "median_step_s": float(np.median(np.concatenate([r["step_s"][1:] for r in s]))) if s else None,
            "median_first_s": float(np.median([r["first_s"] for r in s])) if s else None,
            "median_estimate_s": float(np.median([r["seconds"] for r in e])) if e else None,
            "mean_estimate_sl_error_m": float(np.mean([r["sl_error_m"] for r in e])) if e else None,
        }
    return {
        "cores": os.cpu_count(),
        "load_average_at_end": os.getloadavg(),
        "summary": summary,
        "searches": searched,
        "estimates": estimated,
    }
