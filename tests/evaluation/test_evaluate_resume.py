"""evaluate() and ``dgse evaluate`` keep finished estimates, resume after Ctrl-C, refuse other settings.

Hand-made corridor cases and the deterministic PeakEstimator of tests.search
(no solver, no network): seconds.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import shlex

import pytest

from dgse.cli.main import main
from dgse.errors import InputDataError
from dgse.evaluation.evaluate import evaluate
from dgse.journal import count_records
from dgse.options import Settings
from tests.search import PeakEstimator, UniformEstimator, corridor_case

#: The module (``dgse.evaluation.evaluate`` is also the name of the function the package exports).
evaluation = importlib.import_module("dgse.evaluation.evaluate")


@pytest.fixture
def case_dir(tmp_path):
    d = tmp_path / "cases"
    d.mkdir()
    corridor_case().save(d / "a.npz")
    corridor_case(source_cell=(4, 12)).save(d / "b.npz")
    return d


def _untimed(result):
    return [{k: v for k, v in r.items() if k != "seconds"} for r in result["per_case"]]


def _stats(result):
    """aggregate and by_case without the timing statistics."""
    drop = ("seconds_per_estimate",)
    aggs = {n: {k: v for k, v in a.items() if not k.startswith(drop)} for n, a in result["aggregate"].items()}
    return aggs, {
        c: {n: {k: v for k, v in a.items() if not k.startswith(drop)} for n, a in per.items()}
        for c, per in result["by_case"].items()
    }


def test_interrupted_evaluation_resumes_to_the_same_result(case_dir, tmp_path):
    journal = tmp_path / "e.journal.jsonl"
    run = {"observation_counts": [3, 6], "trials": 2, "seed": 4}
    whole = evaluate(case_dir, PeakEstimator(sigma=0.2), **run)

    def stop_after(n):
        def callback(done, total, record):
            if done == n:
                raise KeyboardInterrupt

        return callback

    with pytest.raises(KeyboardInterrupt):
        evaluate(case_dir, PeakEstimator(sigma=0.2), **run, journal=journal, progress=stop_after(5))
    assert count_records(journal) == 5
    seen = []
    again = evaluate(
        case_dir,
        PeakEstimator(sigma=0.2),
        **run,
        journal=journal,
        progress=lambda done, total, rec: seen.append((done, total, rec["case"], rec["n_obs"], rec["trial"])),
    )
    assert seen == [(6, 8, "b", 3, 1), (7, 8, "b", 6, 0), (8, 8, "b", 6, 1)]  # only the missing ones
    assert _untimed(again) == _untimed(whole) and _stats(again) == _stats(whole)
    assert count_records(journal) == 8
    # other settings: refused, with what differs
    with pytest.raises(InputDataError, match=r"seed was 4, now 5.*restart=True"):
        evaluate(case_dir, PeakEstimator(sigma=0.2), [3], seed=5, journal=journal)
    with pytest.raises(InputDataError, match='method was "peak", now "uniform"'):
        evaluate(case_dir, UniformEstimator(), [3], seed=4, journal=journal)
    # fewer counts reuse what fits; a changed case is noticed
    part = evaluate(case_dir, PeakEstimator(sigma=0.2), [6], trials=1, seed=4, journal=journal)
    assert _untimed(part) == [r for r in _untimed(whole) if r["n_obs"] == 6 and r["trial"] == 0]
    corridor_case(source_cell=(4, 13)).save(case_dir / "b.npz")
    with pytest.raises(InputDataError, match="'b' differs"):
        evaluate(case_dir, PeakEstimator(sigma=0.2), [3], seed=4, journal=journal)
    fresh = evaluate(case_dir, PeakEstimator(sigma=0.2), [3], seed=4, journal=journal, restart=True)
    assert fresh["n_cases"] == 2 and count_records(journal) == 2


@dataclasses.dataclass(eq=False)
class SetPeak(PeakEstimator):
    """PeakEstimator as a dataclass: its settings are its fields."""

    sigma: float = 0.2

    def __post_init__(self) -> None:
        PeakEstimator.__init__(self, sigma=self.sigma)


def test_a_journal_of_other_estimator_settings_is_refused(case_dir, tmp_path):
    """A dataclass estimator's settings, defaults included, are part of the journal's identity:
    resuming with another setting (a changed default reads the same) is refused, naming it."""
    journal = tmp_path / "s.journal.jsonl"
    evaluate(case_dir, SetPeak(), [3], seed=4, journal=journal)
    again = evaluate(case_dir, SetPeak(sigma=0.2), [3], seed=4, journal=journal)
    assert again["n_cases"] == 2 and count_records(journal) == 2
    with pytest.raises(InputDataError, match=r"estimator\.settings\.sigma was 0\.2, now 0\.3"):
        evaluate(case_dir, SetPeak(sigma=0.3), [3], seed=4, journal=journal)


@dataclasses.dataclass(frozen=True)
class _Width(Settings):
    sigma: float = 0.2


@dataclasses.dataclass(eq=False)
class NestedPeak(PeakEstimator):
    """PeakEstimator whose setting lives in a settings object."""

    width: _Width = dataclasses.field(default_factory=_Width)

    def __post_init__(self) -> None:
        PeakEstimator.__init__(self, sigma=self.width.sigma)


def test_a_settings_objects_fields_are_part_of_the_journals_identity(case_dir, tmp_path):
    """A field of a settings object counts as any setting: recorded by its name, and a journal
    of another value is refused, naming the nested field."""
    journal = tmp_path / "n.journal.jsonl"
    first = evaluate(case_dir, NestedPeak(), [3], seed=4, journal=journal)
    assert first["estimator"]["settings"]["width"] == {"sigma": 0.2}
    assert evaluate(case_dir, NestedPeak(), [3], seed=4, journal=journal)["n_cases"] == 2
    with pytest.raises(InputDataError, match=r"estimator\.settings\.width"):
        evaluate(case_dir, NestedPeak(width=_Width(sigma=0.3)), [3], seed=4, journal=journal)


@pytest.fixture
def peak_method(monkeypatch):
    """``--method peak`` builds a PeakEstimator from its ``--param`` arguments."""
    from dgse.estimators.registry import ESTIMATORS

    monkeypatch.setattr(ESTIMATORS, "_entries", dict(ESTIMATORS._entries))
    ESTIMATORS.register("peak", PeakEstimator)


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_ctrl_c_prints_what_was_kept_and_the_command_that_resumes(
    case_dir, tmp_path, capsys, monkeypatch, peak_method
):
    args = ["evaluate", case_dir, "-m", "peak", "-p", "sigma=0.2", "-n", "3,6", "-r", 2, "--no-progress"]
    whole = tmp_path / "whole.json"
    assert _run(capsys, *args, "--json", whole)[0] == 0
    real, calls = evaluation._one_estimate, []

    def interrupted(*a, **kw):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(evaluation, "_one_estimate", interrupted)
    out = tmp_path / "e.json"
    code, text, err = _run(capsys, *args, "--json", out)
    assert code == 130 and "Traceback" not in text + err, (text, err)
    line = err.strip()
    assert "\n" not in line and line.startswith("interrupted: 3 finished estimates kept in "), err
    assert str(tmp_path / "e.journal.jsonl") in line and not out.exists()
    monkeypatch.setattr(evaluation, "_one_estimate", real)
    words = shlex.split(line.split("resume with: ", 1)[1])
    assert words[:2] == ["dgse", "evaluate"]
    code, text, err = _run(capsys, *words[1:])
    assert code == 0, err
    assert "3 finished estimates of an earlier run in" in text and "8 estimates in" in text
    assert _untimed(json.loads(out.read_text())) == _untimed(json.loads(whole.read_text()))
    code, _, err = _run(capsys, *args, "-p", "sigma=0.3", "--json", out)
    assert code == 2 and "sigma" in err and "--restart" in err and "Traceback" not in err
    # no --json: dgse-out/evaluate-<method>.json, the journal beside it
    monkeypatch.chdir(tmp_path)
    code, text, err = _run(capsys, *args[:-1], "--progress")
    assert code == 0, err
    assert (tmp_path / "dgse-out" / "evaluate-peak.json").is_file()
    assert count_records(tmp_path / "dgse-out" / "evaluate-peak.journal.jsonl") == 8
