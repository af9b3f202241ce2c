"""``dgse search``: JSON with the required keys, the GIF, user errors as one red line."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from PIL import Image

from dgse.cli.main import main
from dgse.models.checkpoint import save_model
from dgse.models.networks import create_model
from dgse.search.campaign import trial_seed
from dgse.world.layout_io import save_layout
from tests.conftest import two_rooms
from tests.search import PeakEstimator, corridor_case, solved_two_rooms

torch.set_num_threads(1)

REQUIRED = (
    "success_rate",
    "error_m_mean",
    "search_time_s_mean",
    "distance_m_mean",
    "step_seconds_mean",
    "per_mean",
)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("search")
    cases = d / "cases"
    solved_two_rooms().save(cases / "two_rooms_src0.npz")
    save_layout(two_rooms(), cases / "a_layout.npz")  # a layout file in the directory is skipped
    torch.manual_seed(0)
    model = save_model(create_model("dgse-s", "small", base_width=4, depth=2), d / "tiny.safetensors")
    return d, cases, model


def _run(capsys, *args) -> tuple[int, str, str]:
    code = main(["search", *(str(a) for a in args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_search_writes_json_and_gif(setup, capsys):
    d, cases, model = setup
    out_json, gifs = d / "out" / "metrics.json", d / "gifs"
    fast = ["-p", "K=2", "-p", "T=1", "-p", "canvas_minimum=32"]
    code, out, err = _run(
        capsys, cases, "--method", "dgse-s", "--model", model, "--trials", 2, "--seed", 3,
        "--time-limit", 20, "--min-start-distance", 1.0, "--json", out_json, "--animate", gifs,
        "--no-progress", *fast,
    )  # fmt: skip
    assert code == 0, (out, err)
    assert "two_rooms_src0" in out and "SR" in out and "metrics.json" in out
    data = json.loads(out_json.read_text())
    agg = data["aggregate"]
    assert all(k in agg for k in REQUIRED), agg.keys()
    assert agg["n_trials"] == 2 and 0.0 <= agg["success_rate"] <= 1.0
    [case] = data["per_case"]
    assert case["case"] == "two_rooms_src0" and case["metrics"]["n_trials"] == 2
    assert len(case["trials"]) == 2
    t0 = case["trials"][0]
    assert t0["method"] == "dgse-s" and t0["planner"] == "utility" and t0["n_steps"] >= 1
    assert t0["metrics"]["search_time_s"] <= 20.0 and "success" in t0["metrics"]
    assert data["settings"]["seed"] == 3 and data["settings"]["time_limit_s"] == 20.0
    gif = gifs / "two_rooms_src0.gif"
    with Image.open(gif) as im:
        assert im.format == "GIF" and im.size[0] > 200
    # seeded: the same starts again (and a different seed gives other starts)
    code, _, _ = _run(
        capsys, cases / "two_rooms_src0.npz", "--method", "dgse-s", "--model", model, "--trials", 2,
        "--seed", 3, "--time-limit", 5, "--min-start-distance", 1.0, "--json", d / "again.json",
        "--no-progress", *fast,
    )  # fmt: skip
    assert code == 0
    again = json.loads((d / "again.json").read_text())["per_case"][0]["trials"]
    assert [t["start_cell"] for t in again] == [t["start_cell"] for t in case["trials"]]


def test_trial_seeds_are_independent():
    a = np.random.default_rng(trial_seed(0, "x", 0)).integers(1 << 30)
    assert a == np.random.default_rng(trial_seed(0, "x", 0)).integers(1 << 30)
    assert a != np.random.default_rng(trial_seed(0, "x", 1)).integers(1 << 30)
    assert a != np.random.default_rng(trial_seed(0, "y", 0)).integers(1 << 30)


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["nowhere"], "no such file"),
        (["{cases}", "--method", "nope"], "unknown estimator"),
        (["{cases}", "--planner", "nope"], "unknown planner"),
        (["{cases}", "--trials", "0"], "--trials"),
        (["{cases}", "--sample-rate", "0"], "--sample-rate must be a positive number"),
        (["{cases}", "--sample-rate", "nan"], "--sample-rate"),
        (["{cases}", "-O", "oops"], "KEY=VALUE"),
        (["{layout}"], "layout file"),
    ],
)
def test_user_errors_are_one_red_line(setup, capsys, args, fragment):
    _, cases, model = setup
    args = [a.format(cases=cases, layout=cases / "a_layout.npz") for a in args]
    if "--method" not in args:
        args += ["--method", "dgse-s", "--model", str(model)]
    code, out, err = _run(capsys, *args, "--no-progress")
    assert code == 2, (out, err)
    line = err.strip()
    assert line.startswith("error: ") and "\n" not in line and fragment in line, err
    assert "Traceback" not in out + err


# -- -p/--param, keeping episodes, Ctrl-C, resuming ------------------------------------------------
@pytest.fixture
def peak(tmp_path, monkeypatch):
    """Two corridor case files; ``--method peak`` builds a PeakEstimator (its arguments recorded)."""
    from dgse.estimators.registry import ESTIMATORS
    from dgse.options import options_from

    built: list[dict] = []

    @options_from(PeakEstimator)
    def make_peak(**kwargs):
        built.append(kwargs)
        return PeakEstimator(**kwargs)

    monkeypatch.setattr(ESTIMATORS, "_entries", dict(ESTIMATORS._entries))
    ESTIMATORS.register("peak", make_peak)
    cases = tmp_path / "cases"
    cases.mkdir()
    corridor_case().save(cases / "a.npz")
    corridor_case(source_cell=(5, 20)).save(cases / "b.npz")
    return cases, built


PEAK = ["-m", "peak", "-p", "adaptive=true", "--eta", "0.4", "--trials", "2", "--time-limit", "90",
        "--min-start-distance", "1"]  # fmt: skip


def _untimed_trials(path):
    data = json.loads(path.read_text())
    timings = ("step_seconds", "preprocessing_s", "inference_s", "planning_s")
    return [
        {**t, "metrics": {k: v for k, v in t["metrics"].items() if not k.startswith(timings)}}
        for c in data["per_case"]
        for t in c["trials"]
    ]


def test_param_reaches_the_estimator_and_planner_has_no_short_form(peak, tmp_path, capsys):
    cases, built = peak
    out = tmp_path / "p.json"
    code, _, err = _run(capsys, cases, *PEAK, "-p", "sigma=0.1", "--json", out, "--no-progress")
    assert code == 0, err
    assert built == [{"adaptive": True, "sigma": 0.1}]
    settings = json.loads(out.read_text())["settings"]
    assert settings["estimator_options"] == {"adaptive": True, "sigma": 0.1}
    # --eta is the utility planner's stop.eta; -P dotted keys set its settings' fields
    assert settings["planner_options"] == {"stop.eta": 0.4}
    dotted = tmp_path / "d.json"
    args = ("-P", "stop.min_observations=2", "-P", "weights.w_d=0.2", "--json", dotted, "--no-progress")
    code, _, err = _run(capsys, cases, *PEAK, *args)
    assert code == 0, err
    planner_options = json.loads(dotted.read_text())["settings"]["planner_options"]
    assert planner_options == {"stop.eta": 0.4, "stop.min_observations": 2, "weights.w_d": 0.2}
    # --sample-rate: readings on the way, recorded in the settings and in each trial's counts
    moving = tmp_path / "m.json"
    code, _, err = _run(capsys, cases, *PEAK, "--sample-rate", "2", "--json", moving, "--no-progress")
    assert code == 0, err
    data = json.loads(moving.read_text())
    assert data["settings"]["sample_rate_hz"] == 2.0
    trials = [t for c in data["per_case"] for t in c["trials"]]
    assert sum(t["n_readings"] for t in trials) > sum(t["n_steps"] for t in trials)
    assert "sample_rate_hz" not in json.loads(dotted.read_text())["settings"]
    # -O/--option: the old spelling still works (hidden from --help)
    other = tmp_path / "o.json"
    code, _, err = _run(capsys, cases, *PEAK, "-O", "sigma=0.2", "--json", other, "--no-progress")
    assert code == 0, err
    assert built[-1] == {"adaptive": True, "sigma": 0.2}
    # -p is not the planner any more: a planner name is not KEY=VALUE
    code, _, err = _run(capsys, cases, "-p", "utility", "--no-progress")
    assert code == 2 and "--param needs KEY=VALUE" in err
    code, help_text, _ = _run(capsys, "--help")
    help_text = " ".join(help_text.split()).replace("- ", "-")  # as wrapped, also after a hyphen
    assert "--param" in help_text and "--option" not in help_text and "dgse-out/search-" in help_text


def test_ctrl_c_keeps_finished_episodes_and_the_printed_command_resumes(peak, tmp_path, capsys, monkeypatch):
    import shlex

    import dgse.search.episode as episode

    cases, _ = peak
    whole = tmp_path / "whole.json"
    assert _run(capsys, cases, *PEAK, "--json", whole, "--no-progress")[0] == 0
    real, calls = episode.run_episode, []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt  # Ctrl-C during the third episode
        return real(*args, **kwargs)

    monkeypatch.setattr(episode, "run_episode", interrupted)
    out = tmp_path / "res" / "m.json"
    code, text, err = _run(capsys, cases, *PEAK, "--json", out, "--no-progress")
    assert code == 130 and "Traceback" not in text + err, (text, err)
    line = err.strip()
    assert "\n" not in line and line.startswith("interrupted: 2 finished episodes kept in "), err
    assert str(tmp_path / "res" / "m.journal.jsonl") in line and not out.exists()
    command = line.split("resume with: ", 1)[1]
    monkeypatch.setattr(episode, "run_episode", real)
    words = shlex.split(command)
    assert words[:2] == ["dgse", "search"] and "--restart" not in words
    code, text, err = _run(capsys, *words[2:])
    assert code == 0, err
    assert "2 finished episodes of an earlier run in" in text and "4 episodes in" in text
    assert "(2 kept from an earlier run)" in text
    assert _untimed_trials(out) == _untimed_trials(whole)
    # other settings into the same file: refused with what differs and how to start afresh
    code, _, err = _run(capsys, cases, *PEAK, "--seed", "1", "--json", out, "--no-progress")
    assert code == 2 and "seed was 0, now 1" in err and "--restart" in err and "Traceback" not in err
    code, text, err = _run(capsys, cases, *PEAK, "--seed", "1", "--json", out, "--no-progress", "--restart")
    assert code == 0, err
    assert "kept from an earlier run" not in text
    assert json.loads(out.read_text())["settings"]["seed"] == 1


def test_default_output_and_progress(peak, tmp_path, capsys, monkeypatch):
    cases, _ = peak
    monkeypatch.chdir(tmp_path)
    code, text, err = _run(capsys, cases / "a.npz", *PEAK, "--trials", "1", "--progress")
    assert code == 0, err
    assert (tmp_path / "dgse-out" / "search-peak-utility.json").is_file()
    assert (tmp_path / "dgse-out" / "search-peak-utility.journal.jsonl").is_file()
    assert "search-peak-utility.json" in text.replace("\n", "")


def test_sigterm_is_an_interrupt():
    import os
    import signal

    from dgse.cli.common import sigterm_as_interrupt

    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt), sigterm_as_interrupt():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs between bytecodes
            pass
    assert signal.getsignal(signal.SIGTERM) == before


def test_step_text_and_default_names():
    from dgse.cli.common import default_output
    from dgse.cli.demo import step_text
    from dgse.cli.search import _step_text
    from dgse.search.episode import StepRecord

    rec = StepRecord(4, (1, 2), 123.4, 5.0, (0.1, 0.0), 3.0, 0.71, (1.0, 2.0), 0.456)
    assert _step_text("a", 0, 5, rec, 2000.0) == "a trial 1/5: step 4, 123/2000 s, H 0.71, error 0.46 m"
    from dgse.planning.planners import get_planner

    stop = get_planner("utility", **{"stop.eta": 0.78}).describe_stop()
    assert step_text(rec, 2000.0, stop) == (
        "searching: step 4, 123 of 2000 s simulated, entropy 0.71 of log N (stops when the entropy is "
        "at most 0.78 of log N), error 0.46 m"
    )
    info = get_planner("info").describe_stop()
    assert info == "95% of the source posterior lies within 2 m of its mean"
    assert str(default_output("search", "my/model x", "utility")) == "dgse-out/search-my_model_x-utility.json"


def test_start_option_fixes_the_start_and_refuses_a_wall(peak, tmp_path, capsys):
    cases, _ = peak
    out = tmp_path / "s.json"
    code, _, err = _run(
        capsys, cases / "a.npz", *PEAK, "--start", "0.25", "0.55", "--json", out, "--no-progress"
    )
    assert code == 0, err
    data = json.loads(out.read_text())
    assert data["settings"]["start_m"] == [0.25, 0.55]
    assert [t["start_cell"] for t in data["per_case"][0]["trials"]] == [[5, 2], [5, 2]]
    walled = corridor_case()
    occ = walled.occupancy.copy()
    occ[:, 2] = 1
    occ[0, 2] = 0
    corridor_case(occupancy=occ).save(tmp_path / "w.npz")
    code, out_text, err = _run(capsys, tmp_path / "w.npz", *PEAK, "--start", "0.25", "0.55", "--no-progress")
    line = err.strip()
    assert code == 2 and "\n" not in line and "Traceback" not in out_text + err
    assert (
        line == f"error: start (0.25, 0.55) m (--start) lies in a wall of {tmp_path / 'w.npz'} (cell (5, 2))"
    )
