"""Floor plan import: ROS map_server maps and plain images."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from dgse.errors import InputDataError
from dgse.world.floorplan import (
    FloorPlan,
    layout_from_floorplan,
    load_png_map,
    load_ros_map,
    occupancy_rectangles,
    resample_occupancy,
)
from dgse.world.generate import free_components
from dgse.world.layout import Opening, rasterize_walls

FREE, OCC, UNKNOWN = 254, 0, 205
YAML = (
    "image: {image}\nresolution: {res}\norigin: [{ox}, {oy}, 0.0]\nnegate: {negate}\n"
    "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
)


def _room_image() -> np.ndarray:
    """60 x 100 pixels: a 90 x 50 px room with 1 px walls inside a 5 px unknown margin.

    A 10 x 10 px block sits near the image's top-left corner (the map's north-west).
    """
    img = np.full((60, 100), UNKNOWN, np.uint8)
    img[5:55, 5:95] = FREE
    img[5, 5:95] = img[54, 5:95] = OCC
    img[5:55, 5] = img[5:55, 94] = OCC
    img[10:20, 10:20] = OCC
    return img


def _write_map(tmp_path, img, *, res=0.05, ox=-2.0, oy=-1.0, negate=0, fmt="pgm", text=None):
    name = f"map.{fmt}"
    Image.fromarray(img).save(tmp_path / name)
    y = tmp_path / "map.yaml"
    y.write_text(text or YAML.format(image=name, res=res, ox=ox, oy=oy, negate=negate))
    return y


def test_ros_round_trip_flip_crop_origin(tmp_path):
    fp = load_ros_map(_write_map(tmp_path, _room_image()), 0.1)
    assert isinstance(fp, FloorPlan) and fp.resolution == 0.1
    occ = fp.occupancy
    assert occ.dtype == np.uint8
    # cropped to the known 90 x 50 px = 4.5 x 2.5 m, resampled to 0.1 m cells
    assert occ.shape == (25, 45)
    # origin: lower-left of the crop; 5 px of unknown on the left and at the bottom
    assert fp.origin == pytest.approx((-2.0 + 5 * 0.05, -1.0 + 5 * 0.05))
    # thin 1 px outer walls survive as 1-cell walls
    assert occ[0].all() and occ[-1].all() and occ[:, 0].all() and occ[:, -1].all()
    assert not occ[1:-1, 1:-1][:, 8:].any() and not occ[1:16, 1:-1].any()
    # the block near the image's top-left is near our top rows (north), west columns:
    # image rows 10-19 -> map rows 40-49 from the bottom -> crop rows 35-44 -> cells 17-22
    block = np.argwhere(occ[1:-1, 1:-1]) + 1
    assert block[:, 0].min() == 17 and block[:, 0].max() == 22
    assert block[:, 1].min() == 2 and block[:, 1].max() == 7
    assert free_components(occ)[1] == 1


def test_ros_resampling_rules_and_resolutions(tmp_path):
    y = _write_map(tmp_path, _room_image())
    any_ = load_ros_map(y, 0.1, rule="any").occupancy
    all_ = load_ros_map(y, 0.1, rule="all").occupancy
    maj = load_ros_map(y, 0.1, rule="majority").occupancy
    # block of 10 px at a half-cell offset: 6 x 6 cells (any), 4 x 4 (all)
    assert any_[1:-1, 1:-1].sum() == 36 and all_[1:-1, 1:-1].sum() == 16
    assert all_.sum() <= maj.sum() <= any_.sum()
    # 1 px walls cover half a 0.1 m cell: gone with "all"
    assert not all_[0].any()
    # finer output grid: 0.05 m -> one cell per pixel
    fine = load_ros_map(y, 0.05)
    assert fine.occupancy.shape == (50, 90)
    assert fine.occupancy[1:-1, 1:-1].sum() == 100
    # non-integer ratio keeps thin walls
    odd = load_ros_map(y, 0.07).occupancy
    assert odd[0].all() and odd[:, 0].all() and odd[-1].all() and odd[:, -1].all()
    # coarse map pixels (0.2 m) on a 0.1 m grid: each pixel gives 2 x 2 cells
    img = np.full((6, 8), FREE, np.uint8)
    img[0, :] = OCC
    up = load_ros_map(_write_map(tmp_path, img, res=0.2), 0.1).occupancy
    assert up.shape == (12, 16) and up[-2:].all() and not up[:-2].any()


def test_ros_no_crop_unknown_negate_png(tmp_path):
    img = _room_image()
    img[30:40, 50:60] = UNKNOWN  # unknown patch inside the room: solid
    fp = load_ros_map(_write_map(tmp_path, img), 0.1, crop=False)
    assert fp.occupancy.shape == (30, 50) and fp.origin == pytest.approx((-2.0, -1.0))
    assert fp.occupancy[:2].all() and fp.occupancy[:, :2].all()  # unknown margin is solid
    assert fp.occupancy[10:15, 25:30].all()  # image rows 30-39 -> map rows 20-29
    free_unknown = load_ros_map(_write_map(tmp_path, img), 0.1, unknown_is_solid=False)
    assert free_unknown.occupancy[5:10, 23:28].sum() == 0
    # negate: dark means free
    neg = load_ros_map(_write_map(tmp_path, 255 - _room_image(), negate=1), 0.1)
    plain = load_ros_map(_write_map(tmp_path, _room_image()), 0.1)
    assert np.array_equal(neg.occupancy, plain.occupancy)
    # PNG image with a ROS YAML
    png = load_ros_map(_write_map(tmp_path, _room_image(), fmt="png"), 0.1)
    assert png.occupancy.shape == (25, 45)


def test_ros_yaml_errors(tmp_path):
    with pytest.raises(InputDataError, match="does not exist"):
        load_ros_map(tmp_path / "nothing.yaml")
    y = tmp_path / "bad.yaml"
    y.write_text("resolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(InputDataError, match="'image'"):
        load_ros_map(y)
    y.write_text("image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(InputDataError, match=r"image .*gone\.pgm does not exist"):
        load_ros_map(y)
    Image.fromarray(_room_image()).save(tmp_path / "m.pgm")
    y.write_text("image: m.pgm\nresolution: fine\norigin: [0, 0, 0]\n")
    with pytest.raises(InputDataError, match="'resolution' must be a number"):
        load_ros_map(y)
    y.write_text("image: m.pgm\nresolution: 0.05\n")
    with pytest.raises(InputDataError, match="'origin'"):
        load_ros_map(y)
    y.write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 3\n")
    with pytest.raises(InputDataError, match="'negate'"):
        load_ros_map(y)
    y.write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: fancy\n")
    with pytest.raises(InputDataError, match="mode"):
        load_ros_map(y)
    y.write_text("image: [m.pgm\n  resolution: :\n")
    with pytest.raises(InputDataError, match="cannot parse"):
        load_ros_map(y)
    y.write_text("- a\n- b\n")
    with pytest.raises(InputDataError, match="mapping"):
        load_ros_map(y)
    (tmp_path / "junk.pgm").write_bytes(b"not an image")
    y.write_text("image: junk.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(InputDataError, match="cannot read floor plan image"):
        load_ros_map(y)
    # an empty (all unknown) map
    with pytest.raises(InputDataError, match="no free space"):
        load_ros_map(_write_map(tmp_path, np.full((20, 20), UNKNOWN, np.uint8)))
    # defaults for the optional keys, yaw ignored with a warning
    y.write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0.5]\n")
    with pytest.warns(UserWarning, match="yaw"):
        assert load_ros_map(y).occupancy.shape == (25, 45)


def test_png_map(tmp_path):
    img = np.full((40, 60, 3), 255, np.uint8)  # white = free
    img[0, :] = img[-1, :] = img[:, 0] = img[:, -1] = (20, 20, 20)
    img[2:6, 2:6] = (0, 0, 0)  # dark block at the image's top-left
    img[30:38, 40:50] = (200, 200, 200)  # light grey: free
    Image.fromarray(img).save(tmp_path / "plan.png")
    fp = load_png_map(tmp_path / "plan.png", 0.1, width_m=6.0)
    assert fp.occupancy.shape == (40, 60) and fp.origin == (0.0, 0.0)
    assert fp.occupancy[34:38, 2:6].all() and fp.occupancy[:, 0].all()
    assert not fp.occupancy[2:10, 40:50].any()
    half = load_png_map(tmp_path / "plan.png", 0.1, pixel_size=0.05)
    assert half.occupancy.shape == (20, 30) and half.occupancy[-3:-1, 1:3].all()
    assert load_png_map(tmp_path / "plan.png").occupancy.shape == (40, 60)
    # transparent pixels count as white
    rgba = np.zeros((10, 10, 4), np.uint8)
    rgba[0, :, 3] = 255  # one opaque black row at the top
    Image.fromarray(rgba).save(tmp_path / "alpha.png")
    occ = load_png_map(tmp_path / "alpha.png").occupancy
    assert occ[-1].all() and not occ[:-1].any()
    with pytest.raises(InputDataError, match="not both"):
        load_png_map(tmp_path / "plan.png", pixel_size=0.1, width_m=6.0)
    with pytest.raises(InputDataError, match="does not exist"):
        load_png_map(tmp_path / "missing.png")
    Image.fromarray(np.zeros((5, 5), np.uint8)).save(tmp_path / "black.png")
    with pytest.raises(InputDataError, match="no free"):
        load_png_map(tmp_path / "black.png")


def test_layout_from_floorplan(tmp_path):
    fp = load_ros_map(_write_map(tmp_path, _room_image()), 0.1)
    # the cropped map has its outer walls on the boundary: nothing free there
    with pytest.raises(
        InputDataError, match=r"the west inlet at 0.5-1.5 m touches no free cell.*carve_depth_m"
    ):
        layout_from_floorplan(fp, None, Opening("west", 0.5, 1.5), [("east", 1.0, 2.0)])
    lay = layout_from_floorplan(
        fp,
        None,
        {"side": "left", "start_m": 0.5, "end_m": 1.5},
        [("east", 1.0, 2.0)],
        name="office",
        carve_depth_m=0.2,
    )
    assert lay.name == "office" and lay.inlets[0].side == "west"
    assert lay.occupancy[5:15, 0].sum() == 0 and lay.occupancy[4, 0] == 1
    assert np.array_equal(rasterize_walls(lay.grid, lay.walls), lay.occupancy)
    assert free_components(lay.occupancy)[1] == 1
    # plain arrays, unreachable pockets filled
    occ = np.zeros((20, 30), np.uint8)
    occ[:, 15] = 1
    occ[5:8, 20:23] = 1
    occ[6, 21] = 0  # a sealed free pocket
    lay = layout_from_floorplan(occ, 0.1, [Opening("west", 0.2, 1.0)], [Opening("south", 0.2, 1.2)])
    assert lay.occupancy[:, 16:].all()  # the right half is unreachable: filled
    kept = layout_from_floorplan(
        occ,
        0.1,
        [Opening("west", 0.2, 1.0)],
        [Opening("south", 0.2, 1.2)],
        fill_unreachable=False,
    )
    assert kept.occupancy[6, 21] == 0
    with pytest.raises(InputDataError, match="no outlet reaches"):
        layout_from_floorplan(occ, 0.1, [("west", 0.2, 1.0)], [("east", 0.2, 1.2)])
    with pytest.raises(InputDataError, match="outside the south side"):
        layout_from_floorplan(occ, 0.1, [("west", 0.2, 1.0)], [("south", 2.5, 3.5)])
    with pytest.raises(InputDataError, match="not an Opening"):
        layout_from_floorplan(occ, 0.1, [42], [("south", 0.2, 1.0)])
    with pytest.raises(InputDataError, match="resolution"):
        layout_from_floorplan(occ, None, [("west", 0.2, 1.0)], [("south", 0.2, 1.0)])


def test_occupancy_rectangles_cover_exactly():
    rng = np.random.default_rng(0)
    for _ in range(20):
        occ = (rng.random((17, 23)) < 0.4).astype(np.uint8)
        rects = occupancy_rectangles(occ)
        back = np.zeros_like(occ)
        for r0, r1, c0, c1 in rects:
            assert not back[r0:r1, c0:c1].any()  # disjoint
            back[r0:r1, c0:c1] = 1
        assert np.array_equal(back, occ)


def test_resample_occupancy_direct():
    solid = np.zeros((4, 4), bool)
    solid[0, 0] = True
    assert resample_occupancy(solid, 0.1, 0.2).tolist() == [[1, 0], [0, 0]]
    assert resample_occupancy(solid, 0.1, 0.2, "majority").sum() == 0
    # 3 pixels of 0.1 m on 0.2 m cells: the second cell lies half outside (solid)
    assert resample_occupancy(np.zeros((3, 3), bool), 0.1, 0.2).tolist() == [[0, 1], [1, 1]]
    with pytest.raises(InputDataError, match="rule"):
        resample_occupancy(solid, 0.1, 0.2, "some")
