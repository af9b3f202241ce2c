"""G-GMRF and the sparse variance machinery on cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from dgse.errors import InputDataError
from dgse.mapping.gmrf import (
    GGMRFParams,
    SparseSPDFactor,
    diag_of_inverse,
    free_graph,
    gas_precision,
    ggmrf,
    selected_inverse_diag,
)
from tests.mapping import RES, channel, dense_readings, readings, rel_rmse


def _rooms(door: bool) -> np.ndarray:
    occ = np.zeros((10, 21), np.uint8)
    occ[:, 10] = 1
    if door:
        occ[4:6, 10] = 0
    return occ


def test_free_graph_cuts_edges_at_walls():
    g = free_graph(_rooms(door=False) == 0)
    assert g.n == 10 * 20
    cross = (g.cols[g.edge_a] < 10) != (g.cols[g.edge_b] < 10)
    assert not cross.any()
    assert g.edge_a.size == 2 * (10 * 9 + 9 * 10)
    lap = g.laplacian()
    assert abs(lap.sum(axis=1)).max() < 1e-12


@pytest.mark.parametrize("shape,door", [((7, 9), True), ((10, 21), False), ((10, 21), True)])
def test_selected_inverse_matches_the_dense_inverse(shape, door):
    occ = _rooms(door) if shape == (10, 21) else np.zeros(shape, np.uint8)
    g = free_graph(occ == 0)
    rng = np.random.default_rng(3)
    obs = rng.choice(g.n, 6, replace=False)
    H, _ = gas_precision(g, obs, np.ones(6), 0.8, 100.0, 1 / 6400)
    # plus a random sparse SPD perturbation that fills in differently
    R = sp.random(g.n, g.n, density=0.01, random_state=4)
    H = (H + 0.1 * (R @ R.T) + sp.identity(g.n) * 1e-3).tocsc()
    exact = np.diag(np.linalg.inv(H.toarray()))
    assert np.allclose(selected_inverse_diag(H), exact, rtol=1e-9)
    assert np.allclose(diag_of_inverse(H, "blocked"), exact, rtol=1e-9)
    mc = diag_of_inverse(H, "sampling", n_samples=4000, seed=1)
    assert np.median(np.abs(mc / exact - 1)) < 0.05
    with pytest.raises(InputDataError, match="unknown variance method"):
        SparseSPDFactor(H).inverse_diagonal("dense")


def test_dense_noiseless_readings_reproduce_the_field():
    occ, field = channel()
    gm = ggmrf(occ, RES, dense_readings(occ, field))
    assert rel_rmse(gm.mean_ppm, field) < 1e-3


def test_mean_between_two_readings_lies_between_them():
    occ = np.zeros((3, 25), np.uint8)
    gm = ggmrf(occ, RES, readings([(1, 2), (1, 22)], [10.0, 50.0]))
    row = gm.mean_ppm[1, 2:23]
    assert (row >= 10.0 - 1e-9).all() and (row <= 50.0 + 1e-9).all()
    assert (np.diff(row) > 0).all()


def test_a_wall_stops_the_smoothing_and_a_door_lets_it_through():
    obs = readings([(5, 3), (5, 17)], [100.0, 0.0])
    closed = ggmrf(_rooms(door=False), RES, obs)
    assert closed.mean_ppm[:, 11:].max() < 1e-6 * 100  # nothing leaks into the right room
    assert closed.mean_ppm[:, :10].min() > 90.0
    opened = ggmrf(_rooms(door=True), RES, obs)
    assert opened.mean_ppm[5, 11] > 10.0


def test_variance_is_positive_smaller_near_readings_and_scales_with_the_gas():
    occ = _rooms(door=True)
    obs = readings([(2, 2), (7, 15)], [40.0, 20.0])
    gm = ggmrf(occ, RES, obs)
    free = occ == 0
    v = gm.var_ppm
    assert (v[free] > 0).all() and gm.info["nll_comparable"] is True
    assert v[2, 2] < v[2, 5] < v[9, 9]
    assert v[2, 2] < (0.1 * 40.0) ** 2  # at most the observation noise sigma_z * gas_scale
    doubled = ggmrf(occ, RES, readings([(2, 2), (7, 15)], [80.0, 40.0]))
    assert np.allclose(doubled.mean_ppm, 2 * gm.mean_ppm) and np.allclose(doubled.var_ppm, 4 * v)
    fixed = ggmrf(occ, RES, obs, GGMRFParams(gas_scale=1.0))
    assert np.allclose(fixed.mean_ppm, gm.mean_ppm) and np.allclose(fixed.var_ppm, v / 40.0**2)


def test_an_unobserved_room_falls_back_to_the_prior():
    gm = ggmrf(_rooms(door=False), RES, readings([(5, 3)], [10.0]))
    # the room mean is known only through the prior: variance about (sigma_b * gas_scale)^2 / N_room
    assert gm.var_ppm[5, 15] == pytest.approx((80.0 * 10.0) ** 2 / 100, rel=0.02)
    sampled = ggmrf(_rooms(door=False), RES, readings([(5, 3)], [10.0]), variance="sampling", n_samples=500)
    assert sampled.info["variance_method"] == "sampling" and (sampled.var_ppm[_rooms(False) == 0] > 0).all()
