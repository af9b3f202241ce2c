"""dgse-phys on closed slices: an imported GADEN-like case with a walled map edge and no openings."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgse.belief.knowledge import Knowledge
from dgse.data.gaden import load_gaden
from dgse.errors import UnsupportedError
from dgse.estimators.phys import NetworkFusion, PhysicsGuidedEstimator
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.physics.scenario import solve_cases
from tests.conftest import two_rooms
from tests.walled_slice import write_gaden_slice


@pytest.fixture(scope="module")
def gaden_files(tmp_path_factory):
    solved = solve_cases(two_rooms(), 1.2, [((2.05, 0.55), 0.8)])[0]
    return write_gaden_slice(solved, tmp_path_factory.mktemp("gaden"))


@pytest.fixture(scope="module")
def closed(gaden_files):
    return load_gaden(*gaden_files)


def test_a_gaden_case_is_known_without_openings(closed):
    edge = np.concatenate(
        [closed.occupancy[0], closed.occupancy[-1], closed.occupancy[:, 0], closed.occupancy[:, -1]]
    )
    assert edge.all()  # the walled edge
    k = Knowledge.from_case(closed, "wind")
    assert not k.has_openings and k.inlet_velocity is None and k.wind is not None
    with pytest.raises(UnsupportedError, match="states no openings"):
        Knowledge.from_case(closed, "openings")


def _errors(closed, wind, n_obs=12, seeds=range(4)):
    est = PhysicsGuidedEstimator(fusion=NetworkFusion(weight=0.0, floor=0.0))  # the physics alone
    est.set_knowledge(Knowledge("wind", closed.occupancy, closed.resolution, wind=wind))
    out = []
    for seed in seeds:
        b = est.estimate(closed.occupancy, closed.resolution, draw_observations(closed, n_obs, seed=seed))
        assert np.isfinite(b.source_probs).all() and b.info["best_hypothesis"] == "given wind"
        out.append(b.localization_error(tuple(closed.source)))
    return out


def test_the_wind_level_finds_the_source_of_a_closed_slice(closed):
    """12 readings on the 3 x 2 m map: the given wind, its exchange through the slice kept, puts
    the source within 0.25 m every time; the reversed wind (its sinks where air enters) misses."""
    right = _errors(closed, closed.wind)
    assert max(right) < 0.25
    assert max(_errors(closed, -closed.wind)) > 0.25


def test_the_map_level_on_a_walled_map_is_dgse_s(closed):
    """No two free edge windows: no opening hypotheses; the belief is DGSE-S's, said so."""
    k = Knowledge.from_case(closed, "map")
    est = get_estimator("dgse-phys", knowledge=k)
    obs = draw_observations(closed, 10, seed=0)
    b = est.estimate(closed.occupancy, closed.resolution, obs)
    ref = get_estimator("dgse-s", model="default", seed=0, dtype="auto", channels_last=True)
    assert np.allclose(b.source_probs, ref.estimate(closed.occupancy, closed.resolution, obs).source_probs)
    assert b.info["hypotheses"] == [] and "free windows" in b.info["given_wind_note"]
    assert b.info["method"] == "dgse-phys" and b.info["knowledge"] == "map"


@pytest.mark.parametrize("level", ["wind", "map"])
def test_cli_evaluates_and_searches_an_imported_gaden_case(gaden_files, tmp_path, level):
    from dgse.cli.main import main

    snapshot, pgm = gaden_files
    case_file = tmp_path / "closed.npz"
    assert main(["import-gaden", str(snapshot), "--obstacles", str(pgm), "-o", str(case_file)]) == 0
    common = ["--method", "dgse-phys", "--knowledge", level, "-r", "1", "--no-progress"]
    ev = tmp_path / "evaluate.json"
    assert main(["evaluate", str(case_file), "-n", "8", *common, "-o", str(ev)]) == 0
    result = json.loads(ev.read_text())
    errors = [r["sl_error_m"] for r in result["per_case"]]
    assert errors and np.isfinite(errors).all() and result["knowledge"] == level
    se = tmp_path / "search.json"
    args = ["search", str(case_file), *common, "--time-limit", "12", "--min-start-distance", "0.5"]
    assert main([*args, "-o", str(se)]) == 0
    metrics = json.loads(se.read_text())
    assert metrics["settings"]["knowledge"] == level and metrics["aggregate"]["n_trials"] == 1
    assert np.isfinite(metrics["aggregate"]["error_m_mean"])
