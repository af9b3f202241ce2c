"""``dgse search``: JSON with the required keys, the GIF, user errors as one red line."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from PIL import Image

from dgse.cli.main import main
from dgse.cli.search import trial_seed
from dgse.models.checkpoint import save_model
from dgse.models.networks import create_model
from dgse.world.layout_io import save_layout
from tests.conftest import two_rooms
from tests.search import solved_two_rooms

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
    fast = ["-O", "K=2", "-O", "T=1", "-O", "canvas_minimum=32"]
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
        capsys, cases / "two_rooms_src0.npz", "--model", model, "--trials", 2, "--seed", 3,
        "--time-limit", 5, "--min-start-distance", 1.0, "--json", d / "again.json", "--no-progress", *fast,
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
        (["{cases}", "-O", "oops"], "KEY=VALUE"),
        (["{layout}"], "layout file"),
    ],
)
def test_user_errors_are_one_red_line(setup, capsys, args, fragment):
    _, cases, model = setup
    args = [a.format(cases=cases, layout=cases / "a_layout.npz") for a in args]
    if "--method" not in args:
        args += ["--model", str(model)]
    code, out, err = _run(capsys, *args, "--no-progress")
    assert code == 2, (out, err)
    line = err.strip()
    assert line.startswith("error: ") and "\n" not in line and fragment in line, err
    assert "Traceback" not in out + err
