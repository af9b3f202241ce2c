"""Case files: lossless round trip and validation with messages that name the problem."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgse.errors import CaseFileError
from dgse.world.case import Case
from dgse.world.grid import Grid


def _arrays(openfoam_cases_dir):
    with np.load(openfoam_cases_dir / "small_src0.npz") as d:
        return {k: d[k] for k in d.files}


def _wall_under_source(a):
    """Make the source's cell solid (wind and gas 0 there, as in any solid cell)."""
    i, j = Grid(a["occupancy"].shape, float(a["resolution"])).cell_of(*(float(v) for v in a["source"]))
    for key in ("occupancy", "wind", "concentration"):
        a[key] = a[key].copy()
    a["occupancy"][i, j] = 1
    a["wind"][:, i, j] = 0
    a["concentration"][i, j] = 0


def _write(tmp_path, arrays, name="bad.npz"):
    p = tmp_path / name
    np.savez(p, **arrays)
    return p


def test_openfoam_case_loads_and_round_trips(openfoam_cases_dir, tmp_path):
    case = Case.load(openfoam_cases_dir / "small_src0.npz")
    assert case.grid == Grid((50, 50), 0.1)
    assert case.free[case.source_cell]
    back = Case.load(case.save(tmp_path / "copy.npz"))
    for key in ("occupancy", "wind", "concentration", "source"):
        a, b = getattr(case, key), getattr(back, key)
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert back.resolution == case.resolution and back.meta == case.meta
    with np.load(tmp_path / "copy.npz") as d:
        assert d["occupancy"].dtype == np.uint8 and d["resolution"].dtype == np.float32
        assert json.loads(str(d["meta"])) == case.meta


def test_saving_one_case_file_from_several_threads_at_once(openfoam_cases_dir, tmp_path):
    """Runs that make the same case set concurrently must not trip over each other's temp file."""
    from concurrent.futures import ThreadPoolExecutor

    case = Case.load(openfoam_cases_dir / "small_src0.npz")
    target = tmp_path / "shared.npz"
    with ThreadPoolExecutor(4) as pool:
        paths = list(pool.map(lambda _: case.save(target), range(8)))
    assert paths == [target] * 8
    assert np.array_equal(Case.load(target).concentration, case.concentration)
    assert [p.name for p in tmp_path.iterdir()] == ["shared.npz"]  # no temp file left


def test_frames_round_trip(openfoam_cases_dir, tmp_path):
    a = _arrays(openfoam_cases_dir)
    frames = np.stack([a["concentration"] * s for s in (0.5, 1.0, 1.5)]).astype(np.float32)
    meta = {**json.loads(str(a["meta"])), "frame_dt": 1.0}
    case = Case.from_arrays({**a, "frames": frames, "meta": np.array(json.dumps(meta))})
    back = Case.load(case.save(tmp_path / "frames.npz"))
    assert np.array_equal(back.frames, frames) and back.meta["frame_dt"] == 1.0


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda a: a.pop("wind"), "missing key"),
        (lambda a: a.update(occupancy=a["occupancy"].astype(np.int64)), "occupancy has dtype int64"),
        (lambda a: a.update(wind=a["wind"][:, :10]), "wind has shape"),
        (lambda a: a.update(concentration=a["concentration"].astype(np.float64)), "expected float32"),
        (_wall_under_source, "solid cell"),
        (lambda a: a.update(source=np.array([50.0, 2.0], np.float32)), "outside the map"),
        (lambda a: a.update(meta=np.array("not json")), "meta is not a JSON object"),
        (lambda a: a.update(concentration=-a["concentration"]), "negative"),
        (lambda a: a.update(resolution=np.float32(-0.1)), "resolution must be positive"),
        (
            lambda a: a.update(meta=np.array(json.dumps({**json.loads(str(a["meta"])), "width_m": 3}))),
            "width_m=3 does not match",
        ),
        (lambda a: a.update(frames=a["concentration"][None].astype(np.float32)), "no frame_dt"),
    ],
)
def test_bad_case_files_name_the_problem(openfoam_cases_dir, tmp_path, mutate, message):
    a = _arrays(openfoam_cases_dir)
    mutate(a)
    with pytest.raises(CaseFileError, match=message):
        Case.load(_write(tmp_path, a))


def test_not_an_npz_file(tmp_path):
    p = tmp_path / "junk.npz"
    p.write_text("hello")
    with pytest.raises(CaseFileError, match=r"not a readable \.npz"):
        Case.load(p)
    with pytest.raises(CaseFileError, match="no such file"):
        Case.load(tmp_path / "missing.npz")


def test_grid_geometry():
    g = Grid.from_size(7.6, 9.8)
    assert g.shape == (98, 76) and g.width_m == 7.6
    assert g.cell_of(0.05, 0.15) == (1, 0)
    assert g.center_of(1, 0) == pytest.approx((0.05, 0.15))
    canvas = Grid((102, 60)).canvas_shape(minimum=100, stride=8)
    assert canvas == (104, 104)
    field = np.arange(6.0).reshape(2, 3)
    g2 = Grid((2, 3))
    emb = g2.embed(field, (4, 4), fill=-1)
    assert emb.shape == (4, 4) and emb[0, 0] == 0 and emb[3, 3] == -1
    assert np.array_equal(g2.crop(emb), field)
    assert g2.valid_mask((4, 4)).sum() == 6


@pytest.mark.parametrize("resolution", [0.1, 0.05, 0.25])
def test_a_point_on_a_cell_edge_is_in_the_same_cell_as_float32_and_float64(resolution):
    """Edge ``k * resolution`` belongs to cell ``k`` whichever precision holds the position."""
    g = Grid((400, 400), resolution)
    for k in range(1, 400):
        edge = k * resolution
        for x in (edge, float(np.float32(edge)), float(np.float64(np.float32(edge)))):
            assert g.cell_of(x, 0.5 * resolution) == (0, k), (k, x)
    # off an edge: the cell that holds the point
    assert g.cell_of(0.3 * resolution, 2.7 * resolution) == (2, 0)
    assert g.cell_of(3 * resolution * (1 - 1e-2), 0.0) == (0, 2)


def test_a_source_on_a_cell_edge_keeps_its_cell_after_save_and_load(tmp_path):
    """A source at x = 0.3 m, the edge of a free cell (3) and a wall (2), is valid and stays in cell 3."""
    occ = np.zeros((10, 10), np.uint8)
    occ[:, 2] = 1
    z = np.zeros((10, 10), np.float32)
    case = Case(occ, np.zeros((2, 10, 10)), z, np.array([0.3, 0.9]), 0.1, {"name": "edge"})
    back = Case.load(case.save(tmp_path / "edge.npz"))
    assert case.source_cell == back.source_cell == Grid((10, 10), 0.1).cell_of(0.3, 0.9) == (9, 3)
