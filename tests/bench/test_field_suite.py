"""The ``field`` benchmark suite, quick: every group and method, its table's numbers, the resume.

The steady scenario files of the ``test`` and ``building`` groups are written here beforehand
(files that exist are reused, :mod:`dgse.bench.scenarios`): a small solved two-room case
stands for both, as solving a generated layout or an office floor takes a minute of CPU; the
``gaden`` group writes that case as a GADEN scenario folder and imports it back, as a full run
does with its generated layouts.  The filament frames are simulated by the suite (quick
settings: 20 s of frames).
"""

from __future__ import annotations

import json
import math
import statistics
from pathlib import Path

import pytest
import torch

from dgse.bench import run_suite
from dgse.bench.field import GROUPS, PAPER_DGSE_S, QUICK_METHODS, TABLE_COLUMNS, shortest_path_time
from dgse.bench.report import write_report
from dgse.bench.summary import build_summary
from dgse.journal import count_records
from dgse.presets import PRESETS, PROTOCOL
from dgse.search.metrics import SUCCESS_RADIUS_M
from dgse.world.case import Case
from tests.search import solved_two_rooms

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def two_rooms_case() -> Case:
    return solved_two_rooms()


@pytest.fixture
def field_root(tmp_path: Path, two_rooms_case: Case, monkeypatch: pytest.MonkeyPatch) -> Path:
    import dgse.physics.scenario as scenario

    base = tmp_path / "_scenarios"
    two_rooms_case.with_meta(name="test2000").save(base / "_cases_test_1" / "test2000_src0.npz")
    two_rooms_case.with_meta(name="building3000").save(base / "_cases_0.2m" / "building3000_src0.npz")
    # the generated layout of the GADEN group: the same small case (its export and import run)
    monkeypatch.setattr(scenario, "random_cases", lambda seed, n_sources: [two_rooms_case])
    return tmp_path


def _table(manifest: dict, name: str) -> tuple[list[str], list[list]]:
    t = next(t for s in manifest["sections"] for t in s["tables"] if t["file"] == f"{name}.csv")
    return t["columns"], t["rows"]


def test_field_suite_quick(field_root: Path) -> None:
    manifest_path = run_suite("field", field_root, quick=True, seed=0)
    m = json.loads(manifest_path.read_text())
    out = manifest_path.parent
    assert m["suite"] == "field" and m["quick"] is True and out == field_root / "field"
    assert (out / "field_st_per.png").stat().st_size > 0

    # a row per group and method, in the suite's columns
    cols, rows = _table(m, "field_search")
    assert cols == TABLE_COLUMNS
    displays = [PRESETS[n].display for n in QUICK_METHODS]
    assert [(r[0], r[1]) for r in rows] == [(g, d) for g, _ in GROUPS for d in displays]
    col = {c: i for i, c in enumerate(cols)}

    for group, _ in GROUPS:
        for name in QUICK_METHODS:
            run = json.loads((out / f"run_{name}_{group}.json").read_text())
            assert run["settings"]["frames"] is True and run["settings"]["time_limit_s"] == 20.0
            eps = [t for c in run["per_case"] for t in c["trials"]]
            assert len(eps) == 1  # 1 scenario x 1 trial
            row = next(r for r in rows if r[0] == group and r[1] == PRESETS[name].display)
            assert row[col["episodes"]] == len(eps) and row[col["scenarios"]] == 1
            # SR: the share of episodes the method ended itself within the limit, within 2 m
            within = [
                t["terminated"]
                and t["search_time_s"] <= t["time_limit_s"]
                and t["error_m"] <= SUCCESS_RADIUS_M
                for t in eps
            ]
            assert row[col["SR [%]"]] == pytest.approx(100.0 * sum(within) / len(eps))
            assert all(t["metrics"]["success"] == w for t, w in zip(eps, within, strict=True))
            assert row[col["error [m]"]] == pytest.approx(
                statistics.fmean(t["error_m"] for t in eps), abs=1e-3
            )
            assert row[col["ST median [s]"]] == pytest.approx(
                statistics.median(t["search_time_s"] for t in eps), abs=0.05
            )
            # the shortest-path time: the shortest path at the robot's speed plus one reading
            spt = statistics.fmean(t["shortest_path_m"] / PROTOCOL.speed + PROTOCOL.dwell for t in eps)
            assert row[col["shortest-path time [s]"]] == pytest.approx(spt, abs=0.05)
            assert eps[0]["shortest_path_m"] >= PROTOCOL.min_start_distance
        # every method met the same starts
        starts = {
            tuple(
                json.loads((out / f"run_{n}_{group}.json").read_text())["per_case"][0]["trials"][0][
                    "start_cell"
                ]
            )
            for n in QUICK_METHODS
        }
        assert len(starts) == 1

    # the GADEN group went through the GADEN folder and its import
    folder = field_root / "_scenarios" / "_gaden" / "gaden4000"
    assert (folder / "occupancy.yaml").is_file() and (folder / "cad_models" / "opening_0.stl").is_file()
    imported = Case.load(field_root / "_scenarios" / "_cases_gaden" / "gaden4000_src0.npz")
    assert imported.meta["gaden"]["inlets"] == ["cad_models/opening_0.stl"]
    # the readings came from filament frames
    frames = Case.load(field_root / "_scenarios" / "field-filament-quick" / "gaden4000_src0_filament.npz")
    assert frames.frames is not None and frames.frames.shape[0] == 40  # 20 s of 0.5 s frames

    # the paper's table beside ours, with its mean
    pcols, prows = _table(m, "paper_dgse_s")
    assert [r[0] for r in prows] == [str(e["environment"]) for e in PAPER_DGSE_S] + ["mean"]
    st = pcols.index("ST [s]")
    assert prows[-1][st] == pytest.approx(statistics.fmean(e["st_s"][0] for e in PAPER_DGSE_S), abs=1e-3)

    # the summary has the table, every number of it cited
    text, cited = build_summary(field_root)
    table = [line for line in text.splitlines() if line.startswith("| ")]
    assert len(table) == 1 + len(GROUPS) * len(QUICK_METHODS) + 1  # header, rows, the paper's row
    assert table[-1].startswith("| paper | DGSE-S (mean of its 6 GADEN environments)")
    assert {c.text for c in cited} >= {f"{r[col['SR [%]']]:.0f}" for r in rows}
    page = write_report(field_root).read_text()
    assert "Search with filament readings" in page and page.count("data:image/png;base64,") >= 1

    # a second run resumes every episode from the journals and computes none
    journals = sorted((out / "journals").glob("*.jsonl"))
    assert len(journals) == len(GROUPS) * len(QUICK_METHODS)
    first = json.loads((out / "field_results.json").read_text())
    assert first["episodes"] == {"total": 9, "kept_from_earlier_runs": 0}
    # an interrupted run: one journal lost its episode
    lost = journals[0]
    lost.write_text(lost.read_text().splitlines()[0] + "\n")
    assert count_records(lost) == 0
    run_suite("field", field_root, quick=True, seed=0)
    again = json.loads((out / "field_results.json").read_text())
    assert again["episodes"] == {"total": 9, "kept_from_earlier_runs": 8}
    assert all(count_records(j) == 1 for j in journals)
    assert again["table"] == first["table"] or _same_but_step_times(again["table"], first["table"])
    m2 = json.loads((out / "suite.json").read_text())
    assert any("8 of 9 episodes were kept" in n for n in m2["notes"])


def _same_but_step_times(a: list[dict], b: list[dict]) -> bool:
    """Rows equal up to the measured computation times (a rerun measures them again)."""
    drop = ("step median [s]",)
    return [{k: v for k, v in r.items() if k not in drop} for r in a] == [
        {k: v for k, v in r.items() if k not in drop} for r in b
    ]


def test_shortest_path_time_is_length_over_speed_plus_one_dwell() -> None:
    assert shortest_path_time(5.0) == pytest.approx(5.0 / PROTOCOL.speed + PROTOCOL.dwell)
    assert shortest_path_time(2.0, speed=1.0, dwell=0.5) == pytest.approx(2.5)
    assert shortest_path_time(None) is None and shortest_path_time(math.inf) is None
