"""GW-GMRF: joint gas and wind on cases with known answers."""

from __future__ import annotations

import numpy as np

from dgse.mapping.gmrf import ggmrf
from dgse.mapping.gwgmrf import GWGMRFParams, gwgmrf
from tests.mapping import RES, channel, dense_readings, readings, rel_rmse


def _sparse_cells(free: np.ndarray, n: int, seed: int) -> np.ndarray:
    cells = np.argwhere(free)
    return cells[np.random.default_rng(seed).choice(len(cells), n, replace=False)]


def test_uniform_wind_is_recovered_from_sparse_readings():
    occ = np.zeros((16, 30), np.uint8)
    gm = gwgmrf(occ, RES, readings(_sparse_cells(occ == 0, 12, 2), 5.0, (1.0, 0.5)))
    assert gm.wind_mean is not None and gm.wind_var is not None
    assert np.abs(gm.wind_mean[0] - 1.0).max() < 1e-3 and np.abs(gm.wind_mean[1] - 0.5).max() < 1e-3
    assert gm.info["converged"] and gm.info["iterations"] <= 15
    assert np.allclose(gm.mean_ppm, 5.0, rtol=1e-3)
    assert (gm.wind_var > 0).all()


def test_wind_respects_walls():
    occ = np.zeros((16, 31), np.uint8)
    occ[:, 15] = 1
    occ[6:10, 15] = 0  # a door
    obs = readings(_sparse_cells(occ[:, :15] == 0, 12, 2), 5.0, (1.0, 0.0))
    ux = gwgmrf(occ, RES, obs).wind_mean[0]
    interior = np.abs(ux[:, 3:8]).mean()
    assert interior > 0.6
    assert np.abs(ux[:4, 14]).max() < 0.15 * interior  # no flow into the wall ...
    assert ux[6:10, 15].mean() > 0.3 * interior  # ... but through the door
    closed = occ.copy()
    closed[6:10, 15] = 1
    shut = gwgmrf(closed, RES, obs)
    assert np.abs(shut.wind_mean[:, :, 16:]).max() < 1e-9  # no smoothing across a wall
    assert (shut.wind_mean[:, closed == 1] == 0).all()


def test_closed_boundary_forbids_net_through_flow():
    occ = np.zeros((12, 24), np.uint8)
    obs = readings(_sparse_cells(occ == 0, 10, 5), 1.0, (1.0, 0.0))
    gm = gwgmrf(occ, RES, obs, GWGMRFParams(closed_boundary=True))
    flux = gm.wind_mean[0].sum(axis=0)  # x-flux through each column
    assert np.abs(flux[[0, -1]]).max() < 0.2 * np.abs(gm.wind_mean[0]).sum(axis=0).max()


def test_dense_noiseless_readings_reproduce_the_gas_field():
    occ, field = channel()
    gm = gwgmrf(occ, RES, dense_readings(occ, field, wind=(0.0, 0.5)))  # wind across the gradient
    assert rel_rmse(gm.mean_ppm, field) < 1e-3
    assert np.abs(gm.wind_mean[1] - 0.5).max() < 1e-3


def test_gas_is_non_negative_and_its_variance_smaller_near_readings():
    occ = np.zeros((12, 24), np.uint8)
    cells = _sparse_cells(occ == 0, 8, 7)
    gas = np.array([0.0, 0.0, 50.0, 0.0, 3.0, 0.0, 0.0, 20.0])
    gm = gwgmrf(occ, RES, readings(cells, gas, (0.7, -0.3)))
    assert (gm.mean_ppm >= 0).all()
    v = gm.var_ppm
    far = np.unravel_index(np.argmax(v), v.shape)
    assert v[cells[2, 0], cells[2, 1]] < 0.5 * v[far]
    assert gm.info["nll_comparable"] is True
    # the coupling only adds information: the marginal gas variance is at most G-GMRF's
    # (the Schur complement of the joint precision dominates the gas-only precision)
    g_only = ggmrf(occ, RES, readings(cells, gas))
    assert (v <= g_only.var_ppm * (1 + 1e-9)).all() and v.max() > 0.1 * g_only.var_ppm.max()
