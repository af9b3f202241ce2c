"""The ``search`` benchmark suite, quick: every part runs, lists its files, and resumes from its pieces.

The ``filament`` and ``ood`` scenario files are written here beforehand
(scenario files that exist are reused, :mod:`dgse.bench.core`): the quick
``test`` scenarios with synthetic intermittent frames, and a small solved
two-room case as the out-of-domain one.  Generating real ones (the filament
model, the built-in solver on an out-of-domain layout) takes minutes of CPU
for some layouts; this test is about the suite, not about those generators.
"""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import torch

from dgse.bench import run_suite
from dgse.bench.search import METHODS
from dgse.world.case import Case
from tests.search import solved_two_rooms

torch.set_num_threads(1)


def _prepare(bench_root, root):
    src = bench_root / "_scenarios" / "test"
    (root / "_scenarios").mkdir(parents=True)
    shutil.copytree(src, root / "_scenarios" / "test")
    fil = root / "_scenarios" / "filament"
    fil.mkdir()
    rng = np.random.default_rng(0)
    for p in sorted(src.glob("*.npz")):
        c = Case.load(p)
        gate = rng.random((20, *c.occupancy.shape)) < 0.5  # the plume is there half of the time
        frames = np.where(gate, 2.0 * c.concentration, 0.0).astype(np.float32)
        Case(
            c.occupancy, c.wind, c.concentration, c.source, c.resolution, {**c.meta, "frame_dt": 1.0}, frames
        ).save(fil / p.name)
    ood = root / "_scenarios" / "ood"
    ood.mkdir()
    solved_two_rooms().save(ood / "ood000.npz")


def test_search_suite_quick(bench_root, tmp_path):
    _prepare(bench_root, tmp_path)
    manifest = run_suite("search", tmp_path, quick=True, seed=0)
    m = json.loads(manifest.read_text())
    assert m["suite"] == "search" and m["quick"] is True
    out = manifest.parent
    titles = [s["title"] for s in m["sections"]]
    assert any("tab:active_search_results" in t for t in titles)
    assert any("fig:path_compare" in t for t in titles) and any("table de" in t for t in titles)
    assert all(s["text"] for s in m["sections"])
    figures = {f["file"] for s in m["sections"] for f in s["figures"]}
    tables = {t["file"]: t for s in m["sections"] for t in s["tables"]}
    assert {"path_compare.png", "search_process.png"} <= figures
    assert {"search_steady.csv", "search_filament.csv", "dgse_s_summary.csv"} <= set(tables)
    for f in [*figures, *tables, "search_process.gif", "search_results.json"]:
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    # every method in both comparison tables (per scenario and "all"); success rates are percentages
    for name in ("search_steady.csv", "search_filament.csv"):
        t = tables[name]
        cols = t["columns"]
        assert {r[cols.index("method")] for r in t["rows"]} == {mm.display for mm in METHODS}
        assert len(t["rows"]) == 3 * len(METHODS)  # two scenarios and "all"
        for r in t["rows"]:
            assert 0.0 <= r[cols.index("SR [%]")] <= 100.0
    res = json.loads((out / "search_results.json").read_text())
    for kind in ("test", "filament"):
        for mm in METHODS:
            agg = res["comparison"][kind][mm.name]
            assert agg["n_trials"] == 2 and 0.0 <= agg["success_rate"] <= 1.0
        assert res["dgse_s"][kind]["n_trials"] == 2
    assert {"ood_eta075.csv", "ood_eta088.csv"} <= set(tables)
    for eta in ("0.75", "0.88"):
        assert res["ood"][eta]["n_trials"] == 1 and 0.0 <= res["ood"][eta]["success_rate"] <= 1.0
    # the filament runs read the frames, the steady ones do not; every method met the same starts
    runs = {k: json.loads((out / f"run_{k}.json").read_text()) for k in ("dgse-s_test", "pmfs_filament")}
    assert runs["dgse-s_test"]["settings"]["frames"] is False
    assert runs["pmfs_filament"]["per_case"][0]["trials"][0]["settings"]["use_frames"] is True
    starts = {
        k: [
            c["trials"][0]["start_cell"]
            for c in json.loads((out / f"run_{k}_test.json").read_text())["per_case"]
        ]
        for k in ("dgse-s", "dualmode", "grgsl")
    }
    assert starts["dgse-s"] == starts["dualmode"] == starts["grgsl"]
    # a second run reuses every piece (no episode runs again)
    pieces = sorted((out / "runs").glob("*.json"))
    assert len(pieces) == 2 * 2 * len(METHODS) + 2  # 2 scenarios x 2 kinds x methods; ood x 2 etas
    before = {p.name: p.stat().st_mtime_ns for p in pieces}
    n = len(pieces) * 1  # one trial per piece
    assert m["notes"] == [f"All {n} episodes were run in this invocation."]
    again = json.loads(run_suite("search", tmp_path, quick=True, seed=0).read_text())
    assert {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")} == before
    assert again["notes"][0].startswith(f"0 episodes were run in this invocation and {n} were reused")


def test_pieces_from_before_knowledge_levels_count_as_map() -> None:
    from dgse.bench.search import stored_plan

    old = {"plan": {"method": "dgse-s", "trials": 1, "case": "layout-000004_src0"}}
    assert stored_plan(old) == {**old["plan"], "knowledge": "map"}
    new = {"plan": {**old["plan"], "knowledge": "openings"}}
    assert stored_plan(new)["knowledge"] == "openings"
    assert stored_plan({"per_case": []}) is None


def test_dgse_phys_plans_per_knowledge_level():
    """The suite's DGSE-phys adds the map level's planner options there only, and says so."""
    from dgse.bench.search import _level_extras

    phys = next(m for m in METHODS if m.name == "dgse-phys")
    at_map = phys.planner_options_at("map")
    assert at_map["deadline.estimate_radius_m"] == 1.0
    at_openings = phys.planner_options_at("openings")
    assert "deadline.estimate_radius_m" not in at_openings
    assert "1 m disk" in _level_extras("map") and "disk" not in _level_extras("openings")
    # the report names the planner and the stop the preset runs, as the planner states them
    from dgse.bench.search import _phys_planner_words
    from dgse.planning.planners import get_planner

    words = _phys_planner_words("openings")
    assert words.startswith("information planner (") and get_planner("info").describe_stop() in words
    assert "5th reading" in words and "60 s before the time limit" in words
    # and the estimator options the map searches were measured with, there only
    assert phys.estimator_options_at("map", search=True)["evidence.effective_readings"] == 100.0
    assert phys.estimator_options_at("openings", search=True) == {
        **phys.search_estimator_options,
        "evidence.effective_readings": math.inf,
    }
    assert "evidence.effective_readings" not in phys.estimator_options_at("openings", search=False)
    assert "not tempered" in _level_extras("openings")
    assert "at most 100 readings" in _level_extras("map")
