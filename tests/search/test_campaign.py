"""``run_trials``: the campaign loop behind ``dgse search`` (seeds, structure, callbacks)."""

from __future__ import annotations

import json

import pytest

from dgse.errors import InputDataError
from dgse.search.campaign import estimator_options, load_cases, run_trials, trial_seed
from dgse.search.planners import UtilityPlanner
from tests.search import PeakEstimator, corridor_case


def _cases(tmp_path):
    a, b = corridor_case(), corridor_case(source_cell=(5, 20))
    a.save(tmp_path / "a.npz")
    b.save(tmp_path / "b.npz")
    return tmp_path


def test_run_trials_structure_and_seeds(tmp_path):
    d = _cases(tmp_path)
    seen, ticks = [], []
    data = run_trials(
        d,
        PeakEstimator(adaptive=True),
        UtilityPlanner(eta=0.4),
        trials=2,
        seed=5,
        time_limit=120.0,
        min_start_distance=1.0,
        record_first=True,
        progress=lambda desc, done, total: ticks.append((done, total)),
        on_episode=lambda path, case, r, res: seen.append((path.stem, r, res.recorded)),
    )
    json.dumps(data, allow_nan=False)  # JSON-ready
    assert set(data) == {"settings", "aggregate", "per_case"}
    s = data["settings"]
    assert s["method"] == "peak" and s["planner"] == "utility" and s["trials"] == 2 and s["seed"] == 5
    assert s["time_limit_s"] == 120.0 and s["min_start_distance_m"] == 1.0 and s["model"] is None
    assert data["aggregate"]["n_trials"] == 4 and 0 <= data["aggregate"]["success_rate"] <= 1
    assert [c["file"] for c in data["per_case"]] == [str(d / "a.npz"), str(d / "b.npz")]
    assert all(c["metrics"]["n_trials"] == 2 for c in data["per_case"])
    # the belief maps of trial 0 only; every episode reported, the progress ends at the total
    assert seen == [("a", 0, True), ("a", 1, False), ("b", 0, True), ("b", 1, False)]
    assert ticks[0] == (0, 4) and ticks[-1] == (4, 4)
    # the starts depend on the seed, the file stem and the trial only (not on the method)
    again = run_trials(
        [(d / "a.npz", load_cases(d / "a.npz")[0][1])],
        PeakEstimator(sigma=0.05),
        UtilityPlanner(),
        trials=2,
        seed=5,
        time_limit=60.0,
        min_start_distance=1.0,
    )
    starts = [t["start_cell"] for t in data["per_case"][0]["trials"]]
    assert [t["start_cell"] for t in again["per_case"][0]["trials"]] == starts


def test_named_methods_and_checks(tmp_path):
    d = _cases(tmp_path)
    data = run_trials(
        d / "a.npz", "kdmv", "utility", trials=1, planner_options={"eta": 0.9}, time_limit=30.0, steps=True
    )
    assert data["settings"]["method"] == "kdmv" and data["settings"]["planner_options"] == {"eta": 0.9}
    assert "steps" in data["per_case"][0]["trials"][0]
    with pytest.raises(InputDataError, match="trials"):
        run_trials(d, "kdmv", "utility", trials=0)
    with pytest.raises(InputDataError, match="time limit"):
        run_trials(d, "kdmv", "utility", trials=1, time_limit=0.0)


def test_estimator_options_defaults():
    assert estimator_options("dgse-s", seed=3) == {"model": "default", "seed": 3}
    assert estimator_options("dgse-o", model="m.safetensors", options={"seed": 1}) == {
        "model": "m.safetensors",
        "seed": 1,
    }
    assert estimator_options("pmfs") == {}
    assert estimator_options("pmfs", model="x") == {"model": "x"}
    assert trial_seed(1, "a", 0).entropy == trial_seed(1, "a", 0).entropy
