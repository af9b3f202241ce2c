"""Bad input never shows a traceback: one ``error:`` line, a non-zero exit, checked before the work.

And a bug (an unexpected exception) prints one line naming a log file that
holds the traceback.
"""

from __future__ import annotations

import time

import pytest

from dgse.physics import engines as engines_mod
from dgse.physics.scenario import solve_cases
from tests.conftest import two_rooms
from tests.test_cli import _assert_user_error, _run


@pytest.fixture(scope="module")
def case_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli-errors")
    case = solve_cases(two_rooms(), 1.0, [((2.05, 0.55), 0.8)])[0]
    return case.save(d / "two_rooms_src0.npz")


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--method", "dgse-s", "--device", "cuda"], ["cuda", "use --device cpu"]),
        (["--method", "dgse-s", "--device", "gpu"], ["unknown device 'gpu'", "cpu, cuda"]),
        (["--method", "dgse-s", "-p", "foo=1"], ["unknown estimator 'dgse-s' option(s) foo", "known: K, T"]),
        (["--method", "dgse-s", "-p", "K=abc"], ["option K='abc' must be an integer"]),
        (["--method", "kdmv", "-p", "sigma=abc"], ["kdmv: option sigma='abc' must be a number"]),
        (["--method", "kdmv", "-p", "foo=1"], ["unknown kdmv option(s) foo"]),
    ],
)
def test_estimate_bad_options(capsys, tmp_path, case_file, args, fragments):
    code, out, err = _run(capsys, "estimate", case_file, "-n", "5", "-o", tmp_path / "b.npz", *args)
    _assert_user_error(code, out, err, *fragments)
    assert not (tmp_path / "b.npz").exists()


def test_outputs_are_checked_before_the_work(capsys, tmp_path, case_file):
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    # a folder where a file goes; a file where a folder goes; a file in the way of a folder
    t0 = time.perf_counter()
    _assert_user_error(*_run(capsys, "solve", case_file, "-o", tmp_path), "is a folder")
    _assert_user_error(*_run(capsys, "scenario", "--seed", "1", "--out", a_file), "is a file, not a folder")
    _assert_user_error(
        *_run(capsys, "generate", "--layouts", "2", "--out", a_file / "x.h5"), "is a file, not a folder"
    )
    _assert_user_error(
        *_run(capsys, "estimate", case_file, "-n", "5", "-o", tmp_path / "e.npz", "--plot", "fig.xyz"),
        "cannot write a figure as 'fig.xyz'",
    )
    _assert_user_error(*_run(capsys, "plume", case_file, "-o", tmp_path), "is a folder")
    assert time.perf_counter() - t0 < 30  # no solve, search or simulation ran first


def test_a_bug_prints_one_line_and_logs_the_traceback(capsys, monkeypatch, tmp_path):
    def broken() -> list[str]:
        raise RuntimeError("boom")

    monkeypatch.setenv("DGSE_LOG_DIR", str(tmp_path / "logs"))
    monkeypatch.setattr(engines_mod, "unavailable_engines", broken)
    code, out, err = _run(capsys, "engines")
    assert code == 1
    assert "Traceback" not in out + err
    line = err.strip()
    assert "\n" not in line and "RuntimeError: boom" in line and "bug in dgse" in line
    logs = list((tmp_path / "logs").glob("crash-*.log"))
    assert len(logs) == 1 and str(logs[0]) in line
    text = logs[0].read_text()
    assert "Traceback" in text and "RuntimeError: boom" in text and "command: dgse engines" in text


def test_demo_out_file_fails_within_seconds(capsys, tmp_path):
    a_file = tmp_path / "taken"
    a_file.write_text("x")
    t0 = time.perf_counter()
    _assert_user_error(*_run(capsys, "demo", "--out", a_file), "is a file, not a folder")
    assert time.perf_counter() - t0 < 10
    _assert_user_error(*_run(capsys, "demo", "--eta", "1.5", "--out", tmp_path / "d"), "--eta")


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--method", "dgse-s", "-p", "foo=1"], ["unknown estimator 'dgse-s' option(s) foo"]),
        (["--method", "dgse-s", "-O", "K=abc"], ["option K='abc' must be an integer"]),
        (["-P", "bogus=1"], ["unknown planner 'info' option(s) bogus"]),
        (["-P", "stop.levl=0.5"], ["option(s) stop.levl; known: stop.level"]),
        (["-P", "stop.level=1.5"], ["stop.level must lie in (0, 1]"]),
        (["--planner", "utility", "-P", "stop.eta=1.5"], ["stop.eta must lie in [0, 1]"]),
        (
            ["--method", "dgse-phys", "--knowledge", "openings", "-p", "fusion.flor=0"],
            ["fusion.flor; known: fusion.floor"],
        ),
        (["--method", "dgse-phys", "-p", "flows.speeds=fast"], ["flows.speeds='fast' must be a list"]),
        (["--method", "dgse-phys", "-p", "fusion..floor=0"], ["KEY a Python name (or dotted names)"]),
        (["--method", "adjoint", "-p", "q_max=lots"], ["q_max='lots' must be a number or None"]),
        (["--method", "dgse-s", "-p", "device=gpu"], ["unknown device 'gpu'"]),
    ],
)
def test_search_bad_options(capsys, tmp_path, case_file, args, fragments):
    out = tmp_path / "s.json"
    code, o, err = _run(capsys, "search", case_file, "--trials", "1", "--json", out, "--no-progress", *args)
    _assert_user_error(code, o, err, *fragments)
    assert not out.exists()


def test_knowledge_is_checked_and_recorded(capsys, tmp_path, case_file):
    import json

    import numpy as np

    _assert_user_error(
        *_run(capsys, "estimate", case_file, "-n", "5", "-o", tmp_path / "a.npz", "--method", "adjoint"),
        "adjoint works at knowledge level 'openings' or 'wind', not 'map': give --knowledge openings",
    )
    _assert_user_error(
        *_run(capsys, "demo", "--knowledge", "everything", "--out", tmp_path / "d"), "unknown knowledge level"
    )
    _assert_user_error(
        *_run(capsys, "search", case_file, "--method", "adjoint-oracle", "--knowledge", "openings"),
        "not 'openings': give --knowledge wind",
    )
    code, out, err = _run(
        capsys, "estimate", case_file, "-n", "8", "-o", tmp_path / "b.npz", "--method", "adjoint",
        "--knowledge", "openings", "-p", "candidate_speeds=[1.0]",
    )  # fmt: skip
    assert code == 0, err
    assert "knowledge: openings" in out
    with np.load(tmp_path / "b.npz", allow_pickle=False) as d:
        assert json.loads(str(d["extra"]))["knowledge"] == "openings"
        assert json.loads(str(d["info"]))["knowledge"] == "openings"
    out_json = tmp_path / "s.json"
    code, out, err = _run(
        capsys, "search", case_file, "--method", "adjoint", "--knowledge", "openings", "-p",
        "candidate_speeds=[1.0]", "--trials", "1", "--time-limit", "30", "--json", out_json, "--no-progress",
    )  # fmt: skip
    assert code == 0, err
    assert json.loads(out_json.read_text())["settings"]["knowledge"] == "openings"
