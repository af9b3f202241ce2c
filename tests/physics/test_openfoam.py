"""The OpenFOAM backend: registration, a synthetic layout and the committed OpenFOAM test case.

Tests that run OpenFOAM are marked ``openfoam`` and skipped where the
executables are missing (install with ``apt-get install openfoam``).  The
case files they re-solve are committed in ``tests/fixtures/openfoam``
(``python3 scripts/make_test_data.py`` makes them).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dgse.errors import ConvergenceError, InputDataError, UnsupportedError
from dgse.physics import engines
from dgse.physics import openfoam as of
from dgse.physics.constants import Physics
from dgse.physics.engines import Source
from dgse.world.case import Case
from dgse.world.generate import random_layout
from dgse.world.layout import Layout, Opening
from tests.conftest import OPENFOAM_CASES

HAVE_OPENFOAM = of.find_openfoam() is not None


def needs_openfoam(test):
    """Mark ``test`` ``openfoam`` and skip it where OpenFOAM is not installed."""
    test = pytest.mark.openfoam(test)
    return pytest.mark.skipif(not HAVE_OPENFOAM, reason="OpenFOAM not installed (apt-get install openfoam)")(
        test
    )


def _two_rooms() -> Layout:
    """30 x 20 cells (3 x 2 m): a wall at x = 1.5-1.6 m with a door at y = 0.8-1.2 m."""
    occ = np.zeros((20, 30), dtype=np.uint8)
    occ[:, 15] = 1
    occ[8:12, 15] = 0
    return Layout(occ, (Opening("west", 1.2, 1.8),), (Opening("east", 0.2, 0.8),), name="two_rooms")


# --------------------------------------------------------------------------------------
# availability (no OpenFOAM needed)
# --------------------------------------------------------------------------------------
def test_missing_openfoam_gives_install_hint(monkeypatch):
    monkeypatch.setattr(of.shutil, "which", lambda *a, **k: None)
    assert of.find_openfoam() is None
    assert of.OpenFOAMEngine.unavailable() is not None
    assert "openfoam" not in engines.engine_names()
    with pytest.raises(UnsupportedError, match=r"simpleFoam .*not found on PATH") as exc:
        engines.get_engine("openfoam")
    assert "apt-get install openfoam" in str(exc.value)
    with pytest.raises(UnsupportedError, match="apt-get install openfoam"):
        of.OpenFOAMEngine()


def test_search_path_and_explicit_bin_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv(of.BIN_DIR_ENV, raising=False)
    monkeypatch.delenv("FOAM_APPBIN", raising=False)
    monkeypatch.setattr(of, "FALLBACK_BIN_DIRS", ())
    assert of.find_openfoam() is None
    assert of.OpenFOAMEngine.unavailable() is not None
    with pytest.raises(UnsupportedError, match="apt-get install openfoam"):
        engines.get_engine("openfoam")
    # fake executables in a directory named by DGSE_OPENFOAM_BIN
    for name in of.REQUIRED_UTILITIES:
        exe = tmp_path / "bin" / name
        exe.parent.mkdir(exist_ok=True)
        exe.write_text("#!/bin/sh\n")
        exe.chmod(0o755)
    monkeypatch.setenv(of.BIN_DIR_ENV, str(tmp_path / "bin"))
    assert of.find_openfoam() == str(tmp_path / "bin")
    assert of.OpenFOAMEngine.unavailable() is None
    assert "openfoam" in engines.engine_names()
    env = of.openfoam_environment(str(tmp_path / "bin"))
    assert env["PATH"].split(os.pathsep)[0] == str(tmp_path / "bin")


def test_ascii_field_parser():
    vec = "nonuniform List<vector> \n3\n(\n(1 2 0)\n(3 4 0)\n(-5e-1 6 0)\n)\n;\n"
    assert of._parse_values(vec, 3, 3).tolist() == [[1, 2, 0], [3, 4, 0], [-0.5, 6, 0]]
    assert of._parse_values("nonuniform List<scalar> 3(1 2 3);", 3, 1).tolist() == [1, 2, 3]
    assert of._parse_values("nonuniform List<scalar> 4{-0.25};", None, 1).tolist() == [-0.25] * 4
    assert of._parse_values("uniform (1 0 0);", 2, 3).tolist() == [[1, 0, 0], [1, 0, 0]]
    assert of._parse_values("uniform 0;", 2, 1).tolist() == [0, 0]


# --------------------------------------------------------------------------------------
# OpenFOAM runs
# --------------------------------------------------------------------------------------
@needs_openfoam
def test_synthetic_layout(tmp_path):
    layout = _two_rooms()
    src = Source((2.25, 1.45), 0.5)
    sol = of.OpenFOAMEngine(keep_dir=tmp_path).solve(layout, 1.0, [src])
    H, W = layout.occupancy.shape
    solid = layout.occupancy == 1
    assert sol.flow.wind.shape == (2, H, W)
    assert sol.flow.info["converged"] and sol.info["converged"]
    assert sol.flow.info["iterations"] > 10
    # the facts every engine reports under the same keys (recorded in case files)
    assert sol.info["flow_iterations"] == sol.flow.info["iterations"] and sol.info["flow_converged"] is True
    assert set(sol.info["wall_clock_s"]) >= {"flow", "gas", "gas_per_source", "layout_total"}
    assert np.all(sol.flow.wind[:, solid] == 0) and np.all(sol.concentrations[0][solid] == 0)
    for f in (sol.flow.k, sol.flow.epsilon, sol.flow.nut):
        assert f.shape == (H, W) and np.all(f[~solid] > 0)
    # air enters through the west inlet at 1 m/s and leaves through the east outlet
    rows, _cols = layout.inlets[0].cells(layout.grid)
    assert np.allclose(sol.flow.wind[0, rows, 0], 1.0, rtol=0.1)
    vol = sol.info["volume_flux_m3s"]
    assert vol["inlet"] == pytest.approx(-0.6, rel=1e-6)
    assert vol["outlet"] == pytest.approx(0.6, rel=1e-4)
    # gas: mass balance and the peak at the source
    c = sol.concentrations[0]
    assert c.shape == (H, W) and c.min() >= 0 and np.isfinite(c).all()
    assert sol.outlet_flux_ratio[0] == pytest.approx(1.0, abs=0.02)
    assert sol.info["gas"][0]["total_out_ratio"] == pytest.approx(1.0, abs=1e-4)
    peak = np.array(np.unravel_index(np.argmax(c), c.shape))
    assert np.abs(peak - np.array(layout.grid.cell_of(*src.position))).max() <= 2
    secs = sol.info["seconds"]
    assert set(secs) >= {"mesh", "flow", "gas", "total"} and len(secs["gas"]) == 1
    assert Path(sol.info["case_dir"]).is_dir()


@needs_openfoam
def test_several_openings_and_obstacle():
    occ = np.zeros((20, 24), dtype=np.uint8)
    occ[8:12, 10:14] = 1  # a free-standing block
    layout = Layout(
        occ,
        (Opening("south", 0.3, 0.9), Opening("west", 1.0, 1.6)),
        (Opening("north", 1.5, 2.1), Opening("east", 0.2, 0.6)),
        name="openings",
    )
    sources = [Source((1.85, 0.55), 0.2), Source((0.55, 1.05), 1.0)]
    sol = of.OpenFOAMEngine().solve(layout, 0.8, sources)
    vol = sol.info["volume_flux_m3s"]
    assert vol["inlet"] == pytest.approx(-0.8 * 1.2, rel=1e-6)
    assert vol["outlet"] == pytest.approx(0.96, rel=1e-4)
    rows, cols = layout.inlets[0].cells(layout.grid)
    assert np.allclose(sol.flow.wind[1, rows, cols], 0.8, rtol=0.15)  # south inlet: +y
    assert np.all(sol.flow.wind[:, occ == 1] == 0)
    assert len(sol.concentrations) == 2
    for ratio, gi in zip(sol.outlet_flux_ratio, sol.info["gas"], strict=True):
        assert ratio == pytest.approx(1.0, abs=0.02)
        assert gi["total_out_ratio"] == pytest.approx(1.0, abs=1e-4)


@needs_openfoam
def test_a_closed_room_is_left_at_rest_and_gas_free():
    """Free cells that no opening reaches (a closed room, a walled-in cell) stay out of the
    OpenFOAM mesh: wind and gas are 0 there, and the open part balances its gas."""
    occ = _two_rooms().occupancy.copy()
    occ[12:19, 3:10] = 1
    occ[13:18, 4:9] = 0
    occ[2:5, 21:24] = 1
    occ[3, 22] = 0
    layout = Layout(occ, (Opening("west", 0.2, 1.0),), (Opening("east", 0.2, 1.0),), name="pockets")
    closed = np.zeros(occ.shape, bool)
    closed[13:18, 4:9] = closed[3, 22] = True
    sol = of.OpenFOAMEngine().solve(layout, 1.0, [Source((2.05, 0.55), 0.5)])
    assert sol.flow.info["converged"]
    assert np.all(sol.flow.wind[:, closed] == 0) and np.all(sol.concentrations[0][closed] == 0)
    assert sol.outlet_flux_ratio[0] == pytest.approx(1.0, abs=0.02)
    with pytest.raises(InputDataError, match="closed region"):
        of.OpenFOAMEngine().solve(layout, 1.0, [Source((0.65, 1.55), 0.5)])


@needs_openfoam
def test_unconverged_flow_raises_or_is_flagged():
    layout = _two_rooms()
    src = [Source((2.25, 1.45), 0.5)]
    with pytest.raises(ConvergenceError, match="did not reach residuals") as exc:
        of.OpenFOAMEngine(max_iterations=5).solve(layout, 1.0, src)
    assert exc.value.info["converged"] is False and exc.value.info["iterations"] == 5
    sol = of.OpenFOAMEngine(max_iterations=5, allow_unconverged=True).solve(layout, 1.0, src)
    assert sol.flow.info["converged"] is False and sol.info["converged"] is False


@needs_openfoam
def test_failing_utility_names_it_and_quotes_its_log(monkeypatch):
    monkeypatch.setattr(of, "_block_mesh_dict", lambda layout, depth: "vertices ( oops\n")
    with pytest.raises(of.OpenFOAMError, match="OpenFOAM blockMesh failed") as exc:
        of.OpenFOAMEngine().solve(_two_rooms(), 1.0, [])
    assert "last lines of the log" in str(exc.value) and exc.value.log_tail


@needs_openfoam
def test_reproduces_committed_case():
    """small_src0 (50 x 50 cells, a source that also diffuses out of the inlet)."""
    case = Case.load(OPENFOAM_CASES / "small_src0.npz")
    layout = case.layout
    src = Source((float(case.source[0]), float(case.source[1])), case.release_rate)
    sol = of.OpenFOAMEngine().solve(layout, case.inlet_velocity, [src])
    free = layout.free
    dw = sol.flow.wind - case.wind
    rel_l2 = np.sqrt((dw[:, free] ** 2).sum() / (case.wind[:, free] ** 2).sum())
    dlog = np.log1p(sol.concentrations[0]) - np.log1p(case.concentration)
    log_rmse = np.sqrt(np.mean(dlog[free] ** 2))
    assert rel_l2 < 0.02
    assert log_rmse < 0.05
    # about 0.15 % of the gas leaves through the inlet: the ratio must tell that apart from 1
    ref_ratio = case.meta["mass_balance"]["outlet_flux_ratio"]
    assert 1 - ref_ratio > 1e-3
    assert sol.outlet_flux_ratio[0] == pytest.approx(ref_ratio, abs=1e-4)
    assert sol.info["gas"][0]["inlet_diffusive_loss_ratio"] == pytest.approx(1 - ref_ratio, abs=1e-4)
    # solve_cases keeps no OpenFOAM iteration count; the fixture script records it
    ref_iters = case.meta["fixture"]["openfoam"]["flow_iterations"]
    assert abs(sol.flow.info["iterations"] - ref_iters) <= 0.1 * ref_iters
    assert Physics().ppm_per_gm3 == pytest.approx(case.meta["physics"]["ppm_per_gm3"])


@needs_openfoam
def test_timeout_stops_the_run():
    # a 10 x 10 m layout (the largest of the training distribution): its flow alone takes
    # about 8 s; the committed 5 x 5 m case is solved in about 1 s, too soon to time out
    # (every utility is given at least 1 s)
    layout = random_layout(0, width_range=(10.0, 10.0), height_range=(10.0, 10.0))
    with pytest.raises(of.OpenFOAMTimeoutError, match="timeout of 1 s"):
        of.OpenFOAMEngine(timeout=1.0).solve(layout, 0.5, [])


def test_an_engine_is_imported_alone():
    """A process that solves with OpenFOAM does not import the built-in solver (numba, SciPy
    sparse): its start-up is part of what the speed comparison times."""
    code = (
        "import sys; from dgse.physics.engines import get_engine\n"
        "try:\n    get_engine('openfoam')\nexcept Exception:\n    pass\n"
        "print('dgse.physics.builtin' in sys.modules, 'numba' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
