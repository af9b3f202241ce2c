"""What the dgse-phys tuning scripts share: one sweep over settings on generated scenarios, its table.

Used by ``tune_phys_temperature.py``, ``tune_phys_map.py`` and ``tune_phys_learned.py``
(run from the repository root as ``python benchmarks/<script>.py``).
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dgse.belief.knowledge import Knowledge
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.files import write_text
from dgse.physics.scenario import random_cases


def sweep(
    level: str,
    settings: Sequence[Any],
    options: Callable[[Any], dict[str, Any]],
    seeds: Iterable[int],
    counts: Sequence[int],
    trials: int = 1,
    prepare: Callable[[Any], None] | None = None,
) -> tuple[dict, dict]:
    """``(errors, cross-entropies)`` per ``(setting, count)`` of ``dgse-phys`` at knowledge ``level``.

    For every generated scenario (one source), count and trial the same readings go to an
    estimator per setting (``options(setting)`` are its keyword arguments); the flows (and
    at ``map`` the opening proposals) of the first are handed to the others, so that the
    settings differ in nothing else.  ``prepare(estimator)`` runs on each before it estimates.
    """
    err: dict = defaultdict(list)
    ce: dict = defaultdict(list)
    for seed in seeds:
        case = random_cases(seed, n_sources=1)[0]
        k = Knowledge.from_case(case, level)
        cell = case.layout.grid.cell_of(*case.source)
        for n in counts:
            for trial in range(trials):
                obs = draw_observations(case, n, seed=trial)
                shared = None
                for s in settings:
                    est = get_estimator("dgse-phys", knowledge=k, **options(s))
                    if prepare is not None:
                        prepare(est)
                    if shared is not None:
                        est._hypotheses, est._proposed_at, est._proposed_from = shared
                    b = est.estimate(case.occupancy, case.resolution, obs)
                    shared = (est._hypotheses, est._proposed_at, est._proposed_from)
                    err[s, n].append(b.localization_error(tuple(case.source)))
                    ce[s, n].append(-float(np.log(max(b.source_probs[cell], 1e-12))))
        print(f"scenario {seed} done", flush=True)
    return err, ce


def write_rows(
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
