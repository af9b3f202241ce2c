"""Network input and targets: channel values, masks, canvas sizes, cropping back."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.data.rasterize import (
    CH_GAS,
    CH_OCCUPANCY,
    CH_VALID,
    CH_WIND_X,
    CH_WIND_Y,
    N_CHANNELS,
    canvas_shape_for,
    cell_to_index,
    crop,
    crop_posterior,
    index_to_cell,
    log_to_ppm,
    make_sample,
    rasterize,
    targets,
)
from dgse.errors import InputDataError
from dgse.sensing.noise import NoiseParams
from dgse.sensing.sensors import Observations, measure, random_observations
from dgse.world.case import Case
from dgse.world.grid import Grid
from tests.sensing.test_sensors import synthetic_case


def boxed_case(H: int, W: int) -> Case:
    """An ``H x W`` room with a solid pillar, uniform wind, a bump of gas at the centre."""
    occ = np.zeros((H, W), dtype=np.uint8)
    occ[H // 4 : H // 4 + 3, W // 4 : W // 4 + 2] = 1
    free = occ == 0
    g = Grid((H, W))
    X, Y = g.meshgrid()
    sx, sy = g.center_of(H // 2, W // 2)
    conc = 20.0 * np.exp(-((X - sx) ** 2 + (Y - sy) ** 2)) * free
    wind = np.stack([np.full((H, W), 0.7), np.full((H, W), -0.2)]) * free
    return Case(occ, wind, conc, (sx, sy), 0.1, {"name": "box"})


@pytest.mark.parametrize(
    ("shape", "side"),
    [
        ((20, 30), 100),
        ((100, 100), 100),
        ((100, 60), 100),
        ((102, 102), 112),
        ((150, 50), 160),
        ((50, 150), 160),
        ((100, 101), 112),
        ((128, 10), 128),
    ],
)
def test_canvas_sizes(shape, side):
    assert canvas_shape_for(shape) == (side, side)


def test_canvas_size_options():
    assert canvas_shape_for((102, 102), stride=1) == (102, 102)
    assert canvas_shape_for((102, 102), stride=32) == (128, 128)
    assert canvas_shape_for((20, 30), minimum=112) == (112, 112)


@pytest.mark.parametrize("shape", [(100, 100), (102, 102), (150, 50), (20, 30)])
def test_input_channels(shape):
    case = boxed_case(*shape)
    S = canvas_shape_for(shape)
    obs = random_observations(case, 25, np.random.default_rng(0))
    x = rasterize(case.occupancy, obs, S)
    H, W = shape
    assert x.shape == (N_CHANNELS, *S) and x.dtype == np.float32
    i, j = obs.cells[:, 0], obs.cells[:, 1]
    observed = np.zeros(S, dtype=bool)
    observed[i, j] = True
    # gas: log(z + 1) at observed cells, -1 everywhere else (padding included)
    np.testing.assert_allclose(x[CH_GAS, i, j], np.log1p(obs.gas), rtol=1e-6)
    assert np.all(x[CH_GAS][~observed] == -1.0)
    assert np.all(x[CH_GAS][observed] >= 0.0)
    # wind: readings at observed cells, 0 elsewhere
    np.testing.assert_allclose(x[CH_WIND_X, i, j], obs.wind[:, 0], rtol=1e-6)
    np.testing.assert_allclose(x[CH_WIND_Y, i, j], obs.wind[:, 1], rtol=1e-6)
    assert np.all(x[CH_WIND_X][~observed] == 0) and np.all(x[CH_WIND_Y][~observed] == 0)
    # occupancy: the map's, and solid (1) on the padding
    np.testing.assert_array_equal(x[CH_OCCUPANCY, :H, :W], case.occupancy)
    pad = np.ones(S, dtype=bool)
    pad[:H, :W] = False
    assert np.all(x[CH_OCCUPANCY][pad] == 1.0)
    # valid mask: 1 exactly on the map
    np.testing.assert_array_equal(x[CH_VALID], (~pad).astype(np.float32))
    # back to the map
    np.testing.assert_array_equal(crop(x[CH_OCCUPANCY], shape), case.occupancy)


def test_no_observations_gives_an_empty_input():
    case = boxed_case(20, 30)
    x = rasterize(case.occupancy, Observations.empty(), (100, 100))
    assert np.all(x[CH_GAS] == -1) and not x[CH_WIND_X].any() and not x[CH_WIND_Y].any()


def test_repeated_observations_are_averaged():
    cells = np.array([[3, 4], [3, 4], [5, 6], [3, 4]])
    gas = np.array([1.0, 2.0, 7.0, 6.0])
    wind = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [2.0, 2.0]])
    x = rasterize(np.zeros((10, 10), np.uint8), Observations(cells, gas, wind), (100, 100))
    assert x[CH_GAS, 3, 4] == pytest.approx(np.log1p(3.0))  # mean of the raw ppm readings
    assert x[CH_WIND_X, 3, 4] == pytest.approx(1.0) and x[CH_WIND_Y, 3, 4] == pytest.approx(1.0)
    assert x[CH_GAS, 5, 6] == pytest.approx(np.log1p(7.0))
    assert (x[CH_GAS] >= 0).sum() == 2


def test_observation_in_a_wall_or_off_the_map_is_rejected():
    case = synthetic_case()
    bad = Observations(np.array([[5, 15]]), [1.0], [[0.0, 0.0]])
    with pytest.raises(InputDataError, match=r"\(5, 15\) lies in a wall"):
        rasterize(case.occupancy, bad, (100, 100))
    off = Observations(np.array([[25, 3]]), [1.0], [[0.0, 0.0]])
    with pytest.raises(InputDataError, match=r"\(25, 3\) lies outside"):
        rasterize(case.occupancy, off, (100, 100))
    with pytest.raises(InputDataError, match="smaller than the map"):
        rasterize(np.zeros((120, 20), np.uint8), Observations.empty(), (100, 100))


@pytest.mark.parametrize("shape", [(100, 100), (102, 102), (150, 50)])
def test_targets(shape):
    case = boxed_case(*shape)
    S = canvas_shape_for(shape)
    t = targets(case, S)
    H, W = shape
    assert t.wind.shape == (2, *S) and t.log_concentration.shape == S and t.source.shape == S
    assert t.wind.dtype == t.log_concentration.dtype == t.source.dtype == np.float32
    np.testing.assert_array_equal(crop(t.wind, shape), case.wind)
    np.testing.assert_allclose(crop(t.log_concentration, shape), np.log1p(case.concentration), rtol=1e-6)
    np.testing.assert_allclose(
        log_to_ppm(crop(t.log_concentration, shape)), case.concentration, rtol=1e-5, atol=1e-6
    )
    assert t.source.sum() == 1.0 and t.source[case.source_cell] == 1.0
    assert t.source_cell == case.source_cell
    assert int(np.argmax(t.source)) == t.source_index == cell_to_index(case.source_cell, S)
    assert t.valid.dtype == bool and t.valid.sum() == H * W and t.valid[:H, :W].all()
    pad = ~t.valid
    assert not t.wind[:, pad].any() and not t.log_concentration[pad].any()


def test_make_sample_uses_the_default_canvas():
    case = synthetic_case()
    obs = measure(case, np.array([[2, 2]]), NoiseParams.zero(), np.random.default_rng(0))
    s = make_sample(case, obs)
    assert s.canvas_shape == (100, 100) and s.map_shape == (20, 30)
    assert s.inputs.shape == (5, 100, 100)
    big = make_sample(boxed_case(150, 50), Observations.empty())
    assert big.canvas_shape == (160, 160) and big.map_shape == (150, 50)


def test_index_helpers_and_posterior_crop():
    S = (112, 112)
    for cell in [(0, 0), (5, 7), (111, 111)]:
        assert index_to_cell(cell_to_index(cell, S), S) == cell
    with pytest.raises(InputDataError, match="outside the canvas"):
        cell_to_index((112, 0), S)
    p = np.full(S, 1.0 / (112 * 112))
    q = crop_posterior(p, (102, 50))
    assert q.shape == (102, 50) and q.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(q, 1.0 / (102 * 50))
    assert crop_posterior(p, (102, 50), renormalize=False).sum() < 1.0
