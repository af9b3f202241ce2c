"""``run_trials``: the campaign loop behind ``dgse search`` (seeds, structure, callbacks)."""

from __future__ import annotations

import json

import pytest

from dgse.errors import InputDataError
from dgse.journal import count_records, journal_path
from dgse.planning.planners import StopRule, UtilityPlanner
from dgse.search.campaign import estimator_options, load_cases, run_trials, trial_seed
from tests.search import PeakEstimator, corridor_case


def _cases(tmp_path):
    tmp_path.mkdir(parents=True, exist_ok=True)
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
        UtilityPlanner(stop=StopRule(eta=0.4)),
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
        d / "a.npz",
        "kdmv",
        "utility",
        trials=1,
        planner_options={"stop.eta": 0.9},
        time_limit=30.0,
        steps=True,
    )
    assert data["settings"]["method"] == "kdmv" and data["settings"]["planner_options"] == {"stop.eta": 0.9}
    assert "steps" in data["per_case"][0]["trials"][0]
    with pytest.raises(InputDataError, match="trials"):
        run_trials(d, "kdmv", "utility", trials=0)
    with pytest.raises(InputDataError, match="time_limit must be a positive number"):
        run_trials(d, "kdmv", "utility", trials=1, time_limit=0.0)


def test_estimator_options_defaults():
    # the campaign's seed goes to every estimator that takes one (no name checks)
    assert estimator_options("dgse-s", seed=3) == {"seed": 3}
    assert estimator_options("dgse-o", model="m.safetensors", options={"seed": 1}) == {
        "model": "m.safetensors",
        "seed": 1,
    }
    assert estimator_options("pmfs", seed=2) == {"seed": 2}
    assert estimator_options("kdmv", seed=2) == {}
    assert estimator_options("kdmv", model="x") == {"model": "x"}  # rejected when it is built
    assert trial_seed(1, "a", 0).entropy == trial_seed(1, "a", 0).entropy


# -- keeping finished episodes and resuming ------------------------------------------------------
#: Metrics that are measured wall times (they differ from run to run).
TIMINGS = {"step_seconds", "preprocessing_s", "inference_s", "planning_s"}


def _trials(data):
    """Every trial's summary without its measured computation times, in campaign order."""
    return [
        {**{k: v for k, v in t.items() if k != "metrics"}, "metrics": _untimed(t["metrics"])}
        for c in data["per_case"]
        for t in c["trials"]
    ]


def _untimed(metrics):
    return {k: v for k, v in metrics.items() if not any(k.startswith(m) for m in TIMINGS)}


def _campaign(d, **kw):
    args = {"trials": 2, "seed": 5, "time_limit": 90.0, "min_start_distance": 1.0, **kw}
    return run_trials(d, PeakEstimator(adaptive=True), UtilityPlanner(stop=StopRule(eta=0.4)), **args)


def test_interrupted_campaign_keeps_finished_episodes_and_resumes(tmp_path):
    d = _cases(tmp_path / "cases")
    journal = tmp_path / "out" / "search.journal.jsonl"
    assert journal_path(tmp_path / "out" / "search.json") == journal
    whole = _campaign(d)

    def stop_after(n):
        calls = []

        def on_episode(path, case, r, result):
            calls.append((path.stem, r))
            if len(calls) == n:
                raise KeyboardInterrupt

        return on_episode, calls

    on_episode, calls = stop_after(3)
    with pytest.raises(KeyboardInterrupt):
        _campaign(d, journal=journal, on_episode=on_episode)
    assert count_records(journal) == 3
    # Ctrl-C within the 4th episode (from the per-step callback): still 3 kept
    steps = []

    def interrupt_in_episode(path, r, rec):
        steps.append((path.stem, r, rec.step, rec.time_s))
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _campaign(d, journal=journal, on_step=interrupt_in_episode)
    assert steps == [("b", 1, 1, steps[0][3])] and count_records(journal) == 3
    # the rerun runs only the missing episode and returns what the uninterrupted run returned
    on_episode, calls = stop_after(-1)
    ticks = []
    again = _campaign(
        d, journal=journal, on_episode=on_episode, progress=lambda desc, done, total: ticks.append(done)
    )
    assert calls == [("b", 1)] and ticks == [3, 4] and count_records(journal) == 4
    assert _trials(again) == _trials(whole)
    assert again["settings"] == whole["settings"]
    assert _untimed(again["aggregate"]) == _untimed(whole["aggregate"])
    # more trials: the kept ones are reused, only the new ones run
    on_episode, calls = stop_after(-1)
    more = _campaign(d, journal=journal, trials=3, on_episode=on_episode)
    assert calls == [("a", 2), ("b", 2)] and more["aggregate"]["n_trials"] == 6
    assert [t for t in _trials(more) if t["trial"] < 2] == _trials(whole)


def test_journal_of_other_settings_is_refused(tmp_path):
    d = _cases(tmp_path / "cases")
    journal = tmp_path / "search.journal.jsonl"
    _campaign(d, journal=journal, trials=1)
    with pytest.raises(InputDataError, match=r"seed was 5, now 6.*restart=True") as e:
        _campaign(d, journal=journal, trials=1, seed=6)
    assert str(journal) in str(e.value)
    with pytest.raises(InputDataError, match=r"time_limit_s was 90\.0, now 60\.0"):
        _campaign(d, journal=journal, trials=1, time_limit=60.0)
    with pytest.raises(InputDataError, match="steps"):
        _campaign(d, journal=journal, trials=1, steps=True)
    assert count_records(journal) == 2  # nothing lost by the refusals
    # restart: the old episodes are discarded
    calls = []
    _campaign(d, journal=journal, trials=1, seed=6, restart=True, on_episode=lambda *a: calls.append(a))
    assert len(calls) == 2 and count_records(journal) == 2
    # a case file that changed since its episodes were kept
    corridor_case(source_cell=(4, 20)).save(d / "b.npz")
    with pytest.raises(InputDataError, match=r"b\.npz differs"):
        _campaign(d, journal=journal, trials=1, seed=6)


def test_torn_last_line_is_dropped_and_redone(tmp_path):
    d = _cases(tmp_path / "cases")
    journal = tmp_path / "search.journal.jsonl"
    whole = _campaign(d, journal=journal, trials=1)
    lines = journal.read_text().splitlines(keepends=True)
    journal.write_text("".join(lines[:-1]) + lines[-1][: len(lines[-1]) // 2])  # killed while writing
    assert count_records(journal) == 1
    calls = []
    again = _campaign(d, journal=journal, trials=1, on_episode=lambda p, c, r, res: calls.append(p.stem))
    assert calls == ["b"] and _trials(again) == _trials(whole)
    assert journal.read_text().endswith("\n") and count_records(journal) == 2


def test_fixed_start_from_the_argument_or_the_case_file(tmp_path):
    import numpy as np

    from dgse.search.campaign import fixed_start

    occ = np.zeros((10, 30), np.uint8)
    occ[:, 12] = 1  # a wall with a door at rows 4-5
    occ[4:6, 12] = 0
    walled = corridor_case(occupancy=occ)
    assert fixed_start(walled) is None  # nothing given: every trial draws its start
    assert fixed_start(walled, (0.25, 0.85)) == (8, 2)
    assert fixed_start(walled.with_meta(start_m=[0.25, 0.85])) == (8, 2)
    with pytest.raises(
        InputDataError, match=r"start \(1.25, 0.15\) m \(start_m\) lies in a wall of case \(cell \(1, 12\)\)"
    ):
        fixed_start(walled, (1.25, 0.15))
    with pytest.raises(InputDataError, match=r"lies outside the map of a\.npz"):
        fixed_start(walled.with_meta(start_m=[9.0, 0.5]), origin="a.npz")
    sealed = occ.copy()
    sealed[4:6, 12] = 1
    with pytest.raises(InputDataError, match="cannot be reached"):
        fixed_start(corridor_case(occupancy=sealed), (0.25, 0.85))

    # every trial of every case starts there: the first cell of each trajectory
    walled.save(tmp_path / "a.npz")
    corridor_case(source_cell=(5, 20)).with_meta(start_m=[2.95, 0.05]).save(tmp_path / "b.npz")
    firsts: dict[str, list] = {"a": [], "b": []}

    def first(path, case, r, res):
        firsts[path.stem].append(res.trajectory_cells[0].tolist())

    common = {"trials": 2, "seed": 1, "time_limit": 30.0, "on_episode": first}
    data = run_trials(tmp_path, PeakEstimator(), UtilityPlanner(), start_m=(0.25, 0.85), **common)
    assert firsts == {"a": [[8, 2], [8, 2]], "b": [[8, 2], [8, 2]]}
    assert data["settings"]["start_m"] == [0.25, 0.85]
    assert [t["start_cell"] for c in data["per_case"] for t in c["trials"]] == [[8, 2]] * 4
    firsts = {"a": [], "b": []}
    data = run_trials(tmp_path, PeakEstimator(), UtilityPlanner(), **common)
    assert firsts["b"] == [[0, 29], [0, 29]]  # the case file's start
    assert len({tuple(c) for c in firsts["a"]}) == 2  # drawn, as without a start
    assert "start_m" not in data["settings"]


def test_sample_rate_is_passed_recorded_and_checked(tmp_path):
    d = _cases(tmp_path / "cases")
    book = tmp_path / "out.journal.jsonl"
    plain = _campaign(d / "a.npz", trials=1, journal=book)
    moving = _campaign(d / "a.npz", trials=1, sample_rate_hz=2.0)
    assert "sample_rate_hz" not in plain["settings"] and moving["settings"]["sample_rate_hz"] == 2.0
    [p], [m] = plain["per_case"][0]["trials"], moving["per_case"][0]["trials"]
    assert p["start_cell"] == m["start_cell"]  # the same trial seed
    assert p["n_readings"] == p["n_steps"] and m["n_readings"] > m["n_steps"]
    assert m["metrics"]["n_readings"] == m["n_readings"] and m["settings"]["sample_rate_hz"] == 2.0
    assert moving["aggregate"]["n_readings_mean"] == m["n_readings"]
    # another rate is another run: the journal of the plain one is refused
    with pytest.raises(InputDataError, match="sample_rate_hz"):
        _campaign(d / "a.npz", trials=1, journal=book, sample_rate_hz=2.0)
    with pytest.raises(InputDataError, match="sample_rate_hz must be a positive number"):
        _campaign(d, sample_rate_hz=-1.0)
