"""``dgse import-gaden-scenario``: a GADEN scenario folder to a layout or case file; bad folders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgse.cli.main import main
from dgse.data.gaden_scenario import load_gaden_scenario, read_stl, read_wind_csv
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
    g.write_ascii_stl(d / "cad_models/door_north.stl", g._box(0.0, 0.4, 2.4, 2.5, 0.0, 2.0))
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
