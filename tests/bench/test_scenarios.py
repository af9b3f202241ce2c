"""The scenario sets and variants the benchmark scripts share (dgse.bench.scenarios)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dgse.belief.knowledge import Knowledge
from dgse.bench import scenarios
from dgse.bench.scenarios import (
    SEARCH_SETS,
    VARIANTS,
    ToldWind,
    parse_seeds,
    perturbed_wind,
    search_cases,
    variant_case,
)
from dgse.errors import ConvergenceError, InputDataError
from dgse.world.case import Case


def _case() -> Case:
    """A 12 x 16 map with a wall, a swirling wind and an analytic plume (no solver needed)."""
    H, W, res = 12, 16, 0.1
    occ = np.zeros((H, W), np.uint8)
    occ[:4, 8] = 1
    i, j = np.mgrid[0:H, 0:W]
    wind = np.stack([0.5 + 0.1 * np.sin(i / 3.0), 0.2 * np.cos(j / 4.0)]).astype(np.float32)
    wind[:, occ == 1] = 0.0
    conc = 100.0 * np.exp(-((i - 6) ** 2 + (j - 3) ** 2) / 18.0)
    conc[occ == 1] = 0.0
    meta = {
        "name": "tiny_src0",
        "inlet_velocity": 0.5,
        "release_rate_gps": 1.0,
        "inlet": {"side": "west", "start_m": 0.2, "end_m": 0.8},
        "outlet": {"side": "east", "start_m": 0.2, "end_m": 0.8},
    }
    return Case(occ, wind, conc, (0.35, 0.65), res, meta)


def test_parse_seeds_reads_ranges_and_lists() -> None:
    assert parse_seeds("2000-2003") == [2000, 2001, 2002, 2003]
    assert parse_seeds("900-902,2005") == [900, 901, 902, 2005]
    assert parse_seeds("7") == [7]
    for bad in ("", "a-b", "5-3", "1,,2"):
        with pytest.raises(InputDataError, match="seeds must look like"):
            parse_seeds(bad)


def test_the_sets_keep_validation_and_test_apart() -> None:
    validation = set().union(*(set(r) for k, r in SEARCH_SETS.items() if k.startswith("validation")))
    assert validation.isdisjoint(SEARCH_SETS["test"])
    assert max(validation) < 2000 <= min(SEARCH_SETS["test"])


def test_perturbed_winds() -> None:
    case = _case()
    free = case.occupancy == 0
    u = np.asarray(case.wind, dtype=np.float64)
    assert np.array_equal(perturbed_wind(case, "steady"), u)
    assert np.array_equal(perturbed_wind(case, "filament"), u)
    assert np.allclose(perturbed_wind(case, "wind_x2"), 2 * u)
    rot = perturbed_wind(case, "wind_rotated")
    assert np.allclose(np.hypot(*rot), np.hypot(*u))  # the speed stays
    cos = (rot * u).sum(axis=0)[free] / np.hypot(*u)[free] ** 2
    assert np.allclose(cos, math.cos(math.radians(20.0)))
    smooth = perturbed_wind(case, "wind_smoothed")
    assert np.all(smooth[:, ~free] == 0)
    assert smooth[:, free].std() < u[:, free].std()  # smoother
    assert smooth[:, free].min() >= u[:, free].min() - 1e-12  # an average of free cells' winds
    with pytest.raises(InputDataError, match="unknown variant"):
        perturbed_wind(case, "wind_x3")


def test_variant_case_makes_the_filament_frames_once(tmp_path: Path, monkeypatch) -> None:
    case = _case()
    assert variant_case(case, "wind_rotated", tmp_path, "tiny") is case
    made = []

    def fake_filament(c: Case, settings, seed: int) -> Case:
        made.append(seed)
        return c

    import dgse.physics.filament as filament

    monkeypatch.setattr(filament, "make_filament_case", fake_filament)
    first = variant_case(case, "filament", tmp_path, "tiny")
    again = variant_case(case, "filament", tmp_path, "tiny")
    assert made == [0] and (tmp_path / "tiny_filament.npz").is_file()
    assert np.array_equal(first.concentration, again.concentration)


def test_search_cases_are_made_once_and_unconverged_seeds_noted(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(scenarios.SEARCH_SETS, "validation9", range(5, 8))
    calls = []

    def fake_random_cases(seed: int, n_sources: int) -> list[Case]:
        calls.append(seed)
        if seed == 6:
            raise ConvergenceError("stalled")
        return [_case()]

    import dgse.physics.scenario as scenario

    monkeypatch.setattr(scenario, "random_cases", fake_random_cases)
    d = search_cases(tmp_path, "validation9")
    assert d == tmp_path / "_cases_validation9"
    assert sorted(p.name for p in d.iterdir()) == [
        "validation5_src0.npz",
        "validation6_src0.unconverged",
        "validation7_src0.npz",
    ]
    search_cases(tmp_path, "validation9")
    assert calls == [5, 6, 7]  # nothing made twice, the unconverged seed not tried again
    assert search_cases(tmp_path, "validation9", limit=1).name == "_cases_validation9_1"
    with pytest.raises(InputDataError, match="unknown scenario set"):
        search_cases(tmp_path, "nope")


class _Recorder:
    knowledge_levels = ("map", "openings", "wind")
    name = "recorder"

    def __init__(self) -> None:
        self.told: list[Knowledge] = []

    def set_knowledge(self, knowledge: Knowledge) -> None:
        self.told.append(knowledge)

    def estimate(self, occupancy, resolution, observations):
        return ("belief", resolution)


def test_told_wind_changes_only_the_wind_it_is_told() -> None:
    case = _case()
    inner = _Recorder()
    est = ToldWind(inner, "wind_x2")
    est.set_knowledge(Knowledge.from_case(case, "wind"))
    assert np.allclose(inner.told[-1].wind, perturbed_wind(case, "wind_x2"))
    est.set_knowledge(Knowledge.from_case(case, "openings"))  # no wind: as it is
    assert inner.told[-1].wind is None and inner.told[-1].level == "openings"
    assert est.estimate(case.occupancy, 0.1, None) == ("belief", 0.1)
    assert est.name == "recorder" and est.knowledge_levels == _Recorder.knowledge_levels
    with pytest.raises(InputDataError, match="no wind variant"):
        ToldWind(inner, "filament")
    assert set(VARIANTS) > set(scenarios.WIND_VARIANTS)


def test_run_command_dispatches_and_exits_with_the_usage(capsys) -> None:
    import pytest

    from dgse.bench.commands import run_command

    seen: list[list[str]] = []
    run_command("doc", {"go": seen.append}, ["go", "-x", "1"])
    assert seen == [["-x", "1"]]
    for argv, code in (([], 2), (["nope"], 2), (["--help"], 0)):
        with pytest.raises(SystemExit) as e:
            run_command("doc", {"go": seen.append}, argv)
        assert e.value.code == code
    assert "commands: go" in capsys.readouterr().out


def test_gaden_cases_export_and_import_each_seed_once(tmp_path: Path, monkeypatch) -> None:
    from tests.search import solved_two_rooms

    case = solved_two_rooms()
    calls = []

    def fake_random_cases(seed: int, n_sources: int) -> list[Case]:
        calls.append(seed)
        if seed == scenarios.GADEN_FIRST_SEED + 1:
            raise ConvergenceError("stalled")
        return [case]

    import dgse.physics.scenario as scenario

    monkeypatch.setattr(scenario, "random_cases", fake_random_cases)
    d = scenarios.gaden_cases(tmp_path, 3)
    first = scenarios.GADEN_FIRST_SEED
    assert d == tmp_path / "_cases_gaden"
    assert sorted(p.name for p in d.iterdir()) == [
        f"gaden{first}_src0.npz",
        f"gaden{first + 1}_src0.unconverged",
        f"gaden{first + 2}_src0.npz",
    ]
    scenarios.gaden_cases(tmp_path, 3)
    assert calls == [first, first + 1, first + 2]  # made once
    # the case came through a GADEN folder: the same map and source, the openings by the wind
    got = Case.load(d / f"gaden{first}_src0.npz")
    assert (tmp_path / "_gaden" / f"gaden{first}" / "occupancy.yaml").is_file()
    np.testing.assert_array_equal(got.occupancy, case.occupancy)
    np.testing.assert_allclose(got.source, case.source, atol=1e-6)
    for mine, theirs in ((got.layout.inlets, case.layout.inlets), (got.layout.outlets, case.layout.outlets)):
        assert [(o.side, pytest.approx(o.start_m), pytest.approx(o.end_m)) for o in theirs] == [
            (o.side, o.start_m, o.end_m) for o in mine
        ]
    assert got.release_rate == pytest.approx(case.release_rate)
    assert got.meta["gaden"]["wind"] == ["wind_simulations/steady/wind_at_cell_centers_0.csv"]


def test_variant_case_passes_its_filament_settings(tmp_path: Path, monkeypatch) -> None:
    from dgse.physics.filament import FilamentSettings

    seen = []

    def fake_filament(c: Case, settings, seed: int) -> Case:
        seen.append(settings)
        return c

    import dgse.physics.filament as filament

    monkeypatch.setattr(filament, "make_filament_case", fake_filament)
    short = FilamentSettings(duration=20.0, warmup=10.0)
    variant_case(_case(), "filament", tmp_path / "short", "tiny", settings=short)
    variant_case(_case(), "filament", tmp_path / "default", "tiny")
    assert seen == [short, FilamentSettings()]
