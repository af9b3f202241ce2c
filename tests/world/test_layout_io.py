"""Layout files: save/load round trip, case files as layouts, validation messages."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.world.case import Case
from dgse.world.generate import random_layout, random_ood_layout
from dgse.world.layout import Layout, Opening
from dgse.world.layout_io import load_layout, npz_kind, save_layout


def _same(a: Layout, b: Layout) -> None:
    assert b.occupancy.dtype == np.uint8
    np.testing.assert_array_equal(a.occupancy, b.occupancy)
    assert (a.inlets, a.outlets, a.walls) == (b.inlets, b.outlets, b.walls)
    assert (a.name, a.resolution) == (b.name, b.resolution)


@pytest.mark.parametrize("make", [lambda: random_layout(3), lambda: random_ood_layout(5)])
def test_round_trip(tmp_path, make):
    lay = make()
    path = save_layout(lay, tmp_path / "sub" / "lay")
    assert path.name == "lay.npz" and path.exists()
    assert npz_kind(path) == "layout"
    _same(lay, load_layout(path))
    with np.load(path) as data:
        assert sorted(data.files) == ["meta", "occupancy"]
        meta = json.loads(str(data["meta"]))
    assert meta["kind"] == "layout" and meta["name"] == lay.name


def test_case_file_is_read_as_its_layout(tmp_path):
    lay = random_layout(4)
    H, W = lay.occupancy.shape
    src = lay.grid.center_of(*np.argwhere(lay.free)[0])
    meta = {
        "name": "c_src0",
        "layout": lay.name,
        **lay.meta(),
        "inlet_velocity": 1.0,
        "release_rate_gps": 0.5,
    }
    case = Case(lay.occupancy, np.zeros((2, H, W)), np.zeros((H, W)), src, lay.resolution, meta)
    path = case.save(tmp_path / "c.npz")
    assert npz_kind(path) == "case"
    _same(lay, load_layout(path))


def _write(path, **arrays):
    np.savez(path, **arrays)
    return path


def _meta(**kw) -> np.ndarray:
    m = {
        "resolution": 0.1,
        "inlet": {"side": "west", "start_m": 0.2, "end_m": 0.8},
        "outlet": {"side": "east", "start_m": 0.2, "end_m": 0.8},
        **kw,
    }
    return np.array(json.dumps(m))


OCC = np.zeros((10, 12), np.uint8)


@pytest.mark.parametrize(
    ("arrays", "message"),
    [
        ({"occupancy": OCC}, "missing key(s) meta"),
        ({"occupancy": OCC.astype(np.int64), "meta": _meta()}, "dtype int64, expected uint8"),
        ({"occupancy": OCC[0], "meta": _meta()}, "must be a 2-D map"),
        ({"occupancy": OCC, "meta": np.array("{not json")}, "meta is not a JSON object"),
        ({"occupancy": OCC, "meta": _meta(width_m=3.0)}, "width_m=3.0 does not match 12 cells"),
        (
            {"occupancy": OCC, "meta": _meta(inlet={"side": "west", "start_m": 0.5, "end_m": 2})},
            "runs outside the west side",
        ),
        (
            {"occupancy": OCC, "meta": _meta(inlet={"side": "up", "start_m": 0, "end_m": 1})},
            "unknown boundary side 'up'",
        ),
        ({"occupancy": OCC, "meta": _meta(outlet=None)}, "bad opening"),
        ({"occupancy": OCC, "meta": _meta(inlets=[])}, "at least one inlet"),
        ({"occupancy": OCC, "meta": np.array("{}")}, "meta has no 'inlet'"),
        ({"occupancy": OCC, "meta": _meta(walls=[1, 2])}, "bad layout meta"),
    ],
)
def test_bad_layout_files_name_the_problem(tmp_path, arrays, message):
    path = _write(tmp_path / "bad.npz", **arrays)
    with pytest.raises(InputDataError) as e:
        load_layout(path)
    assert message in str(e.value) and str(path) in str(e.value)


def test_good_hand_written_file_loads(tmp_path):
    lay = load_layout(_write(tmp_path / "ok.npz", occupancy=OCC, meta=_meta()))
    assert lay.name == "ok" and lay.inlets == (Opening("west", 0.2, 0.8),)


def test_unreadable_files(tmp_path):
    with pytest.raises(InputDataError, match="no such file"):
        load_layout(tmp_path / "nope.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(InputDataError, match=r"not an \.npz file"):
        npz_kind(tmp_path / "text.npz")
    with pytest.raises(InputDataError, match="is a directory"):
        load_layout(tmp_path)
    other = _write(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(InputDataError, match="neither a case file nor a layout file"):
        npz_kind(other)
