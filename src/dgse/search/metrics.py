"""Active-search metrics of the paper (Sec. V-D, App. D) and their aggregation over trials.

Per episode (:func:`episode_metrics`):

* ``success``: the final estimate lies within ``2 m`` of the true source
  *and* the method ended the search itself within the time limit (a timeout
  is a failure whatever its estimate);
* ``error_m``: distance from the final estimate (probability-weighted mean;
  at the timeout for failed searches) to the true source;
* ``search_time_s`` (ST), ``distance_m`` (TD);
* ``step_seconds``: one-step computation time, the mean over the episode's
  steps of preprocessing + inference + planning (also split:
  ``preprocessing_s``, ``inference_s``, ``planning_s``);
* ``per``: path efficiency ratio ``TD / d_shortest``, with ``d_shortest`` the
  shortest obstacle-free path from the start to the source cell (NaN when
  that is 0 or not finite);
* ``n_steps``: number of search steps: measurement locations (goals), each one estimate
  and one decision, so ``step_seconds`` is the time of one estimate and decision;
* ``n_readings``: the readings the estimates used (``n_steps`` unless the robot read on
  the way to the goals, :mod:`dgse.search.episode`).

:func:`aggregate` gives, over a set of episodes, ``n_trials``,
``success_rate`` (a fraction in [0, 1]; the paper prints percent) and for
each metric of :data:`METRICS` its ``<metric>_mean``, ``<metric>_std``
(sample standard deviation, ``ddof=1``; 0 for one trial) and
``<metric>_median``, ignoring NaN values (a metric that is NaN everywhere
gives None).  ``step_seconds_mean`` is the mean over episodes of each
episode's mean step time.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from dgse.search.episode import EpisodeResult

__all__ = [
    "METRICS",
    "SUCCESS_RADIUS_M",
    "aggregate",
    "episode_metrics",
    "format_mean_std",
    "is_success",
    "path_efficiency_ratio",
]

#: Success radius of the paper, m.
SUCCESS_RADIUS_M = 2.0
#: The per-episode metrics that :func:`aggregate` summarizes.
METRICS = (
    "error_m",
    "search_time_s",
    "distance_m",
    "step_seconds",
    "preprocessing_s",
    "inference_s",
    "planning_s",
    "per",
    "n_steps",
    "n_readings",
)


def is_success(result: EpisodeResult, radius_m: float = SUCCESS_RADIUS_M) -> bool:
    """Error ``<= radius_m`` and the search ended by the method within the time limit."""
    return (
        result.terminated
        and result.search_time_s <= result.time_limit_s
        and math.isfinite(result.error_m)
        and result.error_m <= radius_m
    )


def path_efficiency_ratio(distance_m: float, shortest_path_m: float) -> float:
    """``distance_m / shortest_path_m``; NaN when the shortest path is 0 or not finite."""
    d = float(shortest_path_m)
    if not (math.isfinite(d) and d > 0):
        return math.nan
    return float(distance_m) / d


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else math.nan


def episode_metrics(result: EpisodeResult, radius_m: float = SUCCESS_RADIUS_M) -> dict[str, Any]:
    """The paper's metrics of one episode (see the module docstring)."""
    return {
        "success": is_success(result, radius_m),
        "terminated": result.terminated,
        "error_m": float(result.error_m),
        "search_time_s": float(result.search_time_s),
        "distance_m": float(result.distance_m),
        "step_seconds": _mean([s.compute_s for s in result.steps]),
        "preprocessing_s": _mean([s.preprocessing_s for s in result.steps]),
        "inference_s": _mean([s.inference_s for s in result.steps]),
        "planning_s": _mean([s.planning_s for s in result.steps]),
        "per": path_efficiency_ratio(result.distance_m, result.shortest_path_m),
        "n_steps": result.n_steps,
        "n_readings": result.n_readings,
    }


def _stats(values: list[float]) -> tuple[float | None, float | None, float | None]:
    a = np.asarray(values, dtype=np.float64)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return None, None, None
    std = float(a.std(ddof=1)) if a.size > 1 else 0.0
    return float(a.mean()), std, float(np.median(a))


def aggregate(
    results: Iterable[EpisodeResult | Mapping[str, Any]], radius_m: float = SUCCESS_RADIUS_M
) -> dict[str, Any]:
    """Summary over episodes: ``n_trials``, ``success_rate`` and mean/std/median per metric.

    Args:
        results: :class:`EpisodeResult` objects or dicts of :func:`episode_metrics`.
        radius_m: success radius for :class:`EpisodeResult` inputs.

    Returns:
        A JSON-able dict (None for undefined statistics, e.g. of no trials).
    """
    rows = [episode_metrics(r, radius_m) if isinstance(r, EpisodeResult) else dict(r) for r in results]
    out: dict[str, Any] = {
        "n_trials": len(rows),
        "success_rate": float(np.mean([bool(r["success"]) for r in rows])) if rows else None,
    }
    for m in METRICS:
        mean, std, median = _stats([float(r[m]) for r in rows if r.get(m) is not None])
        out[f"{m}_mean"], out[f"{m}_std"], out[f"{m}_median"] = mean, std, median
    return out


def format_mean_std(agg: Mapping[str, Any], key: str, spec: str, missing: str = "-") -> str:
    """``"mean (std)"`` of metric ``key`` of an :func:`aggregate` (format ``spec``), else ``missing``."""
    mean, std = agg.get(f"{key}_mean"), agg.get(f"{key}_std")
    if mean is None:
        return missing
    return f"{mean:{spec}} ({std:{spec}})" if std is not None else f"{mean:{spec}}"
