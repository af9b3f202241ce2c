"""``dgse import-gaden-scenario``: a GADEN scenario folder to a layout or case file; bad folders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgse.cli.main import main
from dgse.data.gaden_scenario import (
    box_triangles,
    export_gaden_scenario,
    import_gaden_scenario,
    load_gaden_scenario,
    read_stl,
    read_wind_csv,
    write_stl,
    write_wind_csv,
)
from dgse.errors import InputDataError
from dgse.world.case import Case
from dgse.world.layout import Opening
from dgse.world.layout_io import load_layout, npz_kind
from tests.data import gaden_scenario_data as g


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return g.write_gaden_scenario(tmp_path_factory.mktemp("gaden") / "house")


def _run(capsys, *args) -> tuple[int, str, str]:
    code = main(["import-gaden-scenario", *(str(a) for a in args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_import_gives_the_layout_openings_source_and_start(folder, tmp_path, capsys):
    out = tmp_path / "house.npz"
    code, text, err = _run(capsys, folder, "-o", out)
    assert code == 0, err
    assert npz_kind(out) == "layout" and "west 1.8-2.4 m" in text
    layout = load_layout(out)
    # walls and doors lie on cell faces at 0.1 m: the map's cells are the building's, cell for cell
    np.testing.assert_array_equal(layout.occupancy, g.occupancy(0.1).astype(np.uint8))
    assert layout.inlets == (Opening("west", *g.WEST_DOOR),)  # ASCII STL; the wind blows in here
    assert layout.outlets == (Opening("east", *g.EAST_DOOR),)  # binary STL, header "solid ..."
    rows, cols = layout.inlets[0].cells(layout.grid)
    assert cols.tolist() == [0] * 6 and rows.tolist() == list(range(18, 24))
    with np.load(out) as z:
        meta = json.loads(str(z["meta"]))
    assert meta["source_m"] == pytest.approx(g.SOURCE) and meta["start_m"] == pytest.approx(g.START)
    assert meta["map_origin_m"] == pytest.approx(g.ORIGIN) and meta["source_z_m"] == g.SOURCE_Z
    assert meta["gaden"]["inlets"] == ["cad_models/door_west.stl"]
    assert meta["gaden"]["scene"] == "scene.yaml" and len(meta["gaden"]["wind"]) == 2


def test_stl_ascii_and_binary_and_the_wind_csv(folder):
    west, east = read_stl(folder / "cad_models/door_west.stl"), read_stl(folder / "cad_models/door_east.stl")
    assert west.shape == east.shape == (12, 3, 3)
    lo, hi = east.reshape(-1, 3).min(axis=0), east.reshape(-1, 3).max(axis=0)
    ox, oy = g.ORIGIN
    np.testing.assert_allclose(lo, [ox + g.WIDTH - g.WALL, oy + g.EAST_DOOR[0], 0.0], atol=1e-6)
    np.testing.assert_allclose(hi, [ox + g.WIDTH, oy + g.EAST_DOOR[1], 2.0], atol=1e-6)
    pts, wind = read_wind_csv(folder / "wind_simulations/1ms/wind_at_cell_centers_0.csv")
    assert pts.shape == wind.shape and set(np.round(pts[:, 2], 2)) == {0.45, 0.55, 1.05}
    assert wind[pts[:, 2] > 1.0, 0].mean() == pytest.approx(g.WIND_ABOVE, abs=0.01)  # U columns first


def test_wind_slice_height_decides_inlets_and_outlets(folder):
    sc = load_gaden_scenario(folder)
    free = sc.layout.free
    assert sc.height == g.SOURCE_Z and sc.wind.shape == (2, 30, 40)
    assert sc.wind[0][free].mean() == pytest.approx(g.WIND_U, abs=0.01)  # both time steps averaged
    assert np.abs(sc.wind[:, ~free]).max() == 0.0
    assert sc.inlet_speed == pytest.approx(g.WIND_U, abs=0.02)
    # higher up the air blows back: the east door becomes the inlet
    high = load_gaden_scenario(folder, height=1.05)
    assert high.wind[0][free].mean() == pytest.approx(g.WIND_ABOVE, abs=0.01)
    assert [o.side for o in high.layout.inlets] == ["east"] and [o.side for o in high.layout.outlets] == [
        "west"
    ]
    # without wind every model must be named; names override the wind
    with pytest.raises(InputDataError, match="without a wind file"):
        load_gaden_scenario(folder, use_wind=False)
    named = load_gaden_scenario(folder, use_wind=False, inlets=["door_east"], outlets=["door_west.stl"])
    assert [o.side for o in named.layout.inlets] == ["east"] and named.wind is None


def test_solve_writes_a_case_that_keeps_the_start(folder, tmp_path, capsys):
    out = tmp_path / "case.npz"
    code, _, err = _run(capsys, folder, "-o", out, "--solve", "--rate", 0.5)
    assert code == 0, err
    case = Case.load(out)
    assert case.meta["start_m"] == pytest.approx(g.START)
    assert case.inlet_velocity == pytest.approx(g.WIND_U, abs=0.02) and case.release_rate == 0.5
    assert tuple(case.source) == pytest.approx(g.SOURCE)
    assert case.concentration[case.source_cell] == case.concentration.max() > 0


def test_older_formats_launch_xml_source_and_numbered_outlets(tmp_path):
    d = g.write_gaden_scenario(tmp_path / "old")
    (d / "environment_configurations/config1/simulations/sim1/sim.yaml").unlink()
    (d / "environment_configurations/config1/config.yaml").unlink()
    launch = d / "launch"
    launch.mkdir()
    sx, sy = g.SOURCE[0] + g.ORIGIN[0], g.SOURCE[1] + g.ORIGIN[1]
    (launch / "GADEN.launch").write_text(
        f'<launch>\n <arg name="source_location_x" default="{sx}" />\n'
        f' <arg name="source_location_y" default="{sy}" />\n <arg name="source_location_z" default="0.5" />\n'
        ' <node pkg="gaden_filament_simulator" exec="filament_simulator">\n  #comment text\n'
        '  <param name="source_position_x" value="$(var source_location_x)"/>\n'
        '  <param name="source_position_y" value="$(var source_location_y)"/>\n'
        '  <param name="outlets_model_0" value="$(find-pkg-share env)/B/cad_models/door_east.stl"/>\n'
        '  <param name="outlets_model_1" value="$(find-pkg-share env)/B/cad_models/door_west.stl"/>\n'
        " </node>\n</launch>\n"
    )
    sc = load_gaden_scenario(d)
    assert sc.source == pytest.approx(g.SOURCE) and sc.files["simulation"] == "launch/GADEN.launch"
    assert sc.files["outlets"] == ["cad_models/door_east.stl"]
    # a second configuration with other openings and its own wind simulation (by its prefix)
    other = d / "launch" / "B2"
    other.mkdir()
    (other / "GADEN_preprocessing.launch").write_text(
        '<launch>\n <arg name="simulation" default="calm" />\n <node pkg="gaden_preprocessing">\n'
        '  <param name="outlets_model_0" value="$(find-pkg-share env)/B/cad_models/door_west.stl"/>\n'
        '  <param name="outlets_model_1" value="$(find-pkg-share env)/B/cad_models/door_north.stl"/>\n'
        '  <param name="wind_files"\n'
        '   value="$(find-pkg-share env)/B/wind_simulations/$(var simulation)/$(var simulation)"/>\n'
        " </node>\n</launch>\n"
    )
    write_stl(d / "cad_models/door_north.stl", box_triangles(0.0, 0.4, 2.4, 2.5, 0.0, 2.0))
    calm = d / "wind_simulations" / "calm"
    calm.mkdir()
    for t, src in enumerate(sorted((d / "wind_simulations/1ms").glob("*.csv"))):
        text = src.read_text().splitlines()
        rows = np.loadtxt(text[1:], delimiter=",")
        rows[:, 1] = -rows[:, 0]  # blows south instead: in at the north door, out at the west one
        rows[:, 0] = 0.0
        np.savetxt(calm / f"calm_{t}.csv", rows, delimiter=",", header=text[0], comments="", fmt="%.6f")
    with pytest.raises(InputDataError, match="several lists of outlet models"):
        load_gaden_scenario(d)
    b2 = load_gaden_scenario(d, settings_path=other / "GADEN_preprocessing.launch")
    assert b2.files["wind"] == ["wind_simulations/calm/calm_0.csv", "wind_simulations/calm/calm_1.csv"]
    assert [(o.side, o.start_m, o.end_m) for o in b2.layout.inlets] == [("north", 1.0, 1.4)]
    assert [o.side for o in b2.layout.outlets] == ["west"]
    (other / "GADEN_preprocessing.launch").unlink()
    # two scenes with other starts: which one is asked for
    (d / "scene2.yaml").write_text("robots:\n  - position: [0.5, 0.5, 0.0]\n")
    with pytest.raises(InputDataError, match="several robot starts"):
        load_gaden_scenario(d)
    assert load_gaden_scenario(d, scene=d / "scene2.yaml").start == pytest.approx((1.5, 1.0))


@pytest.mark.parametrize(
    ("kwargs", "args", "fragment"),
    [
        ({"with_map": False}, [], "no ROS map YAML"),
        ({"west_door_shift": (-3.0, 0.0)}, [], "door_west.stl: the outlet (x -4.00..-3.90"),
        (
            {"west_door_shift": (1.0, 0.0)},
            [],
            "is not at the map's edge (nearest: the north side, 0.60 m away",
        ),
        ({"source": (2.05, 0.5)}, [], "sim.yaml) lies in a wall (grid cell (5, 20))"),
        ({}, ["--start", "1.05", "0.0"], "start (1.050, 0.000) m (map frame) lies in a wall"),
        ({}, ["--inlet", "nope.stl"], "--inlet nope.stl: no such outlet model"),
        ({}, ["--solve"], "a case needs a positive release rate"),
    ],
)
def test_bad_folders_are_one_error_line(tmp_path, capsys, kwargs, args, fragment):
    d = g.write_gaden_scenario(tmp_path / "bad", **kwargs)
    code, out, err = _run(capsys, d, "-o", tmp_path / "x.npz", *args)
    line = err.strip()
    assert code == 2 and line.startswith("error: ") and "\n" not in line, (out, err)
    assert fragment in line, line
    assert "Traceback" not in out + err and not (tmp_path / "x.npz").exists()


def test_source_and_start_options_are_map_frame(folder, tmp_path, capsys):
    out = tmp_path / "opt.npz"
    args = ("--source", "0.0", "1.0", "--height", "0.5", "--start", "2.5", "0.0")
    code, _, err = _run(capsys, folder, "-o", out, *args)
    assert code == 0, err
    with np.load(out) as z:
        meta = json.loads(str(z["meta"]))
    assert meta["source_m"] == pytest.approx((1.0, 1.5)) and meta["start_m"] == pytest.approx((3.5, 0.5))
    assert meta["gaden"]["simulation"] is None and meta["gaden"]["scene"] is None
    code, _, err = _run(capsys, folder, "-o", out, "--source", "0.0", "1.0")  # no --height: slice at z 0
    assert code == 2 and "give --height" in err


def test_the_writers_give_back_what_the_readers_read(tmp_path):
    tris = box_triangles(-1.0, 0.5, 2.0, 2.25, 0.0, 2.0)
    assert tris.shape == (12, 3, 3)
    lo, hi = tris.reshape(-1, 3).min(axis=0), tris.reshape(-1, 3).max(axis=0)
    np.testing.assert_allclose([lo, hi], [[-1.0, 2.0, 0.0], [0.5, 2.25, 2.0]])
    for binary in (False, True):
        path = write_stl(tmp_path / f"box_{binary}.stl", tris, binary=binary)
        assert path.read_bytes().startswith(b"solid")  # a binary header may start so too
        np.testing.assert_allclose(read_stl(path), tris, atol=1e-6)
    rng = np.random.default_rng(0)
    pts, wind = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    got_pts, got_wind = read_wind_csv(
        write_wind_csv(tmp_path / "w" / "wind_at_cell_centers_0.csv", pts, wind)
    )
    np.testing.assert_allclose(got_pts, pts, atol=1e-6)
    np.testing.assert_allclose(got_wind, wind, atol=1e-6)
    with pytest.raises(InputDataError, match=r"\(n, 3\)"):
        write_wind_csv(tmp_path / "bad.csv", pts, wind[:, :2])


def _corner_case() -> Case:
    """A 2 x 1.5 m room, an inlet from the south-west corner along the south side, an outlet
    north at the east corner, a west-to-east wind with a northward turn (no solver needed)."""
    H, W, res = 15, 20, 0.1
    occ = np.zeros((H, W), np.uint8)
    occ[5:10, 10] = 1
    i, j = np.mgrid[0:H, 0:W]
    wind = np.stack([np.full((H, W), 0.3), 0.02 * i + 0.1]).astype(np.float32) * (occ == 0)
    conc = 50.0 * np.exp(-((i - 3) ** 2 + (j - 15) ** 2) / 10.0) * (occ == 0)
    meta = {
        "name": "corner",
        "inlet_velocity": 0.4,
        "release_rate_gps": 0.05,
        "inlet": {"side": "south", "start_m": 0.0, "end_m": 0.5},
        "outlet": {"side": "north", "start_m": 1.5, "end_m": 2.0},
    }
    return Case(occ, wind, conc, (1.55, 0.35), res, meta)


def test_an_exported_case_imports_back(tmp_path):
    case = _corner_case()
    origin = (-3.0, 1.25)
    d = export_gaden_scenario(case, tmp_path / "corner", origin=origin, start=(0.25, 1.25))
    for part in ("occupancy.yaml", "occupancy.pgm", "cad_models/opening_0.stl", "scene.yaml"):
        assert (d / part).is_file(), part
    sc = load_gaden_scenario(d, resolution=case.resolution)
    np.testing.assert_array_equal(sc.layout.occupancy, case.occupancy)
    # the openings at the corners keep their sides; the wind tells the inlet from the outlet
    assert sc.layout.inlets == case.layout.inlets and sc.layout.outlets == case.layout.outlets
    np.testing.assert_allclose(sc.origin, origin)
    np.testing.assert_allclose(sc.source, case.source, atol=1e-6)
    np.testing.assert_allclose(sc.start, (0.25, 1.25), atol=1e-9)
    assert sc.source_z == 0.5 and sc.height == 0.5
    np.testing.assert_allclose(sc.wind, case.wind, atol=1e-6)
    rows, cols = case.layout.inlets[0].cells(case.grid)
    assert sc.inlet_speed == pytest.approx(float(case.wind[1, rows, cols].mean()), abs=1e-6)
    # without the wind file the openings must be named
    bare = export_gaden_scenario(case, tmp_path / "bare", wind=False)
    assert not (bare / "wind_simulations").exists()
    with pytest.raises(InputDataError, match="cannot tell inlets from outlets"):
        load_gaden_scenario(bare, resolution=case.resolution)
    sc = load_gaden_scenario(bare, resolution=case.resolution, inlets=["opening_0"], outlets=["opening_1"])
    assert sc.layout.inlets == case.layout.inlets and sc.wind is None


def test_an_exported_case_solves_again_to_the_same_case(tmp_path):
    from tests.search import solved_two_rooms

    case = solved_two_rooms()
    d = export_gaden_scenario(case, tmp_path / "rooms")
    out, _ = import_gaden_scenario(d, tmp_path / "rooms.npz", solve=True, release_rate=case.release_rate)
    again = Case.load(out)
    np.testing.assert_array_equal(again.occupancy, case.occupancy)
    assert again.inlet_velocity == pytest.approx(case.inlet_velocity, rel=0.05)
    np.testing.assert_allclose(again.wind, case.wind, atol=0.05)
