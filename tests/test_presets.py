"""A named method is what was measured: ``dgse search --method M`` runs M's preset.

The search benchmark (``dgse bench search``) and the command resolve the same preset;
on one small case they must run the same episodes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dgse.bench.search import METHODS
from dgse.cli.main import main
from dgse.errors import UnsupportedError
from dgse.files import json_safe
from dgse.physics.scenario import solve_cases
from dgse.presets import DEFAULT_METHOD, PRESETS, preset, resolve
from dgse.search.campaign import estimator_options, run_trials
from dgse.world.layout import Layout, Opening


@pytest.fixture(scope="module")
def case_file(tmp_path_factory) -> Path:
    """3 x 3 m, a wall from the south up to y = 1.8 m, inlet west high, outlet east low."""
    occ = np.zeros((30, 30), np.uint8)
    occ[:18, 14:16] = 1
    layout = Layout(occ, (Opening("west", 1.8, 2.6),), (Opening("east", 0.3, 1.1),), name="tiny")
    (case,) = solve_cases(layout, 1.0, [((2.4, 0.6), 1.0)])
    return case.save(tmp_path_factory.mktemp("presets") / "tiny.npz")


def test_presets_extend_per_level_and_user_options_win() -> None:
    phys = PRESETS["dgse-phys"]
    at_map = resolve("dgse-phys", "map", search=True)
    at_openings = resolve("dgse-phys", "openings", search=True)
    assert at_map.planner_options == {**phys.planner_options, **phys.at_level["map"]["planner"]}
    assert at_openings.planner_options == dict(phys.planner_options)
    assert at_map.estimator_options["evidence.effective_readings"] == 100.0
    assert at_map.estimator_options["evidence.effective_growth"] == 0.0
    # a search at openings never tempers the gas evidence; a random-readings estimate does
    assert at_openings.estimator_options["evidence.effective_readings"] == math.inf
    random_readings = resolve("dgse-phys", "openings", search=False)
    assert "evidence.effective_readings" not in random_readings.estimator_options
    # random-readings estimates do not take the search options
    assert resolve("dgse-phys", "map", search=False).estimator_options == {}
    assert resolve("dgse-s", "map", search=False).estimator_options == {}
    assert phys.planner == at_map.planner == at_openings.planner == "info"
    user = resolve("dgse-phys", "openings", search=True, planner_options={"stop.level": 0.8})
    assert user.planner_options["stop.level"] == 0.8
    # another planner than the preset's keeps its own defaults
    assert resolve("dgse-phys", "openings", search=True, planner="infotaxis").planner_options == {}
    assert resolve(None, "wind", search=True).method == DEFAULT_METHOD["wind"] == "dgse-phys"
    assert preset("kdmv").estimator == "kdmv" and preset("kdmv").planner == "utility"
    with pytest.raises(UnsupportedError, match="unknown estimator 'nope'"):
        preset("nope")


def test_bench_search_compares_the_presets() -> None:
    assert [m.name for m in METHODS] == ["dgse-s", "dgse-phys", "dualmode", "grgsl", "pmfs", "pf-infotaxis"]
    assert all(m is PRESETS[m.name] for m in METHODS)


@pytest.mark.parametrize("level", ["openings", "map"])
def test_cli_search_runs_the_benchmarks_episodes(case_file: Path, tmp_path: Path, level: str, capsys) -> None:
    out = tmp_path / "search.json"
    args = ["search", str(case_file), "--method", "dgse-phys", "--knowledge", level, "--trials", "1"]
    args += ["--time-limit", "40", "--no-progress", "--steps", "--json", str(out)]
    assert main(args) == 0, capsys.readouterr()
    cli = json.loads(out.read_text())
    run = resolve("dgse-phys", level, search=True)
    assert cli["resolved"]["planner_options"] == run.planner_options
    assert {k: v for k, v in cli["resolved"]["estimator_options"].items() if k != "seed"} == json_safe(
        run.estimator_options
    )  # an infinite option is written as null
    # the episode as the search benchmark runs it (dgse.bench.search: the preset at this level)
    m = next(m for m in METHODS if m.name == "dgse-phys")
    bench = run_trials(
        str(case_file),
        m.estimator,
        m.planner,
        1,
        0,
        estimator_options=estimator_options(m.estimator, options=m.estimator_options_at(level, search=True)),
        planner_options=m.planner_options_at(level),
        time_limit=40.0,
        steps=True,
        knowledge=level,
    )
    a, b = cli["per_case"][0]["trials"][0], bench["per_case"][0]["trials"][0]
    for key in ("reason", "error_m", "search_time_s", "distance_m"):
        assert a[key] == b[key], key
    assert [s["cell"] for s in a["steps"]] == [s["cell"] for s in b["steps"]]
