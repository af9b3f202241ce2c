"""Success, PER and aggregation on hand-made episode results."""

from __future__ import annotations

import math

import pytest

from dgse.search.episode import EpisodeResult, StepRecord
from dgse.search.metrics import (
    METRICS,
    aggregate,
    episode_metrics,
    format_mean_std,
    is_success,
    path_efficiency_ratio,
)


def _result(
    error: float, reason: str = "converged", time_s: float = 100.0, td: float = 10.0, d0: float = 4.0
):
    steps = [
        StepRecord(k, (0, k), 3.0 * k, 0.0, (0.0, 0.0), 1.0, 0.5, (0.0, 0.0), error, 0.01, 0.1 * k, 0.02)
        for k in (1, 2)
    ]
    return EpisodeResult(
        case_name="c",
        method="m",
        planner="p",
        source_xy=(1.0, 1.0),
        source_cell=(10, 10),
        start_cell=(0, 0),
        estimate_xy=(1.0 + error, 1.0),
        error_m=error,
        reason=reason,
        search_time_s=time_s,
        distance_m=td,
        shortest_path_m=d0,
        time_limit_s=2000.0,
        steps=steps,
    )


def test_success_needs_accuracy_and_own_termination_in_time():
    assert is_success(_result(1.9))
    assert is_success(_result(2.0))
    assert not is_success(_result(2.1))
    assert not is_success(_result(0.1, reason="time_limit", time_s=2000.0))  # a timeout fails
    assert not is_success(_result(0.1, time_s=2000.5))  # ended itself, but too late
    assert is_success(_result(0.1, reason="planner_stop"))
    assert is_success(_result(2.5), radius_m=3.0)


def test_episode_metrics_and_per():
    m = episode_metrics(_result(0.5, td=10.0, d0=4.0))
    assert m["success"] and m["terminated"] and m["n_steps"] == 2
    assert m["per"] == pytest.approx(2.5)
    assert m["step_seconds"] == pytest.approx(0.01 + 0.15 + 0.02)
    assert m["inference_s"] == pytest.approx(0.15)
    assert math.isnan(path_efficiency_ratio(3.0, 0.0)) and math.isnan(path_efficiency_ratio(3.0, math.inf))
    assert math.isnan(episode_metrics(_result(0.5, d0=0.0))["per"])


def test_aggregate():
    rs = [
        _result(0.5, td=8.0, time_s=50.0),
        _result(1.5, td=12.0, time_s=150.0),
        _result(3.0, reason="time_limit", time_s=2000.0, td=40.0, d0=0.0),
    ]
    a = aggregate(rs)
    assert a["n_trials"] == 3 and a["success_rate"] == pytest.approx(2 / 3)
    assert a["error_m_mean"] == pytest.approx(5 / 3) and a["error_m_median"] == pytest.approx(1.5)
    mean = 5 / 3
    assert a["error_m_std"] == pytest.approx(
        math.sqrt(((0.5 - mean) ** 2 + (1.5 - mean) ** 2 + (3 - mean) ** 2) / 2)
    )
    assert a["search_time_s_mean"] == pytest.approx(2200 / 3)
    assert a["distance_m_mean"] == pytest.approx(20.0)
    assert a["per_mean"] == pytest.approx((2.0 + 3.0) / 2)  # the NaN PER (start at the source) is left out
    required = ("success_rate", "error_m_mean", "search_time_s_mean", "distance_m_mean", "step_seconds_mean")
    assert all(k in a for k in (*required, "per_mean"))
    assert all(f"{m}_{s}" in a for m in METRICS for s in ("mean", "std", "median"))
    assert aggregate([episode_metrics(r) for r in rs]) == a  # dicts or results alike
    one = aggregate(rs[:1])
    assert one["error_m_std"] == 0.0
    empty = aggregate([])
    assert empty["n_trials"] == 0 and empty["success_rate"] is None and empty["error_m_mean"] is None


def test_format_mean_std():
    agg = {"error_m_mean": 1.23456, "error_m_std": 0.5, "per_mean": 2.0, "per_std": None}
    agg["n_steps_mean"] = None
    assert format_mean_std(agg, "error_m", ".2f") == "1.23 (0.50)"
    assert format_mean_std(agg, "per", ".1f") == "2.0"
    assert format_mean_std(agg, "n_steps", ".1f") == "-"
    assert format_mean_std(agg, "distance_m", ".1f", "n/a") == "n/a"
