"""Kernel DM+V and DM+V/W on cases with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.mapping.kernel import KernelParams, kdmv, kdmvw, kernel_weights
from tests.mapping import RES, channel, dense_readings, readings, rel_rmse


def test_dense_noiseless_readings_reproduce_the_field():
    occ, field = channel()
    obs = dense_readings(occ, field)
    # the kernel smooths: error grows with its width, small for a narrow one
    assert rel_rmse(kdmv(occ, RES, obs, KernelParams(sigma=0.1)).mean_ppm, field) < 0.02
    assert rel_rmse(kdmv(occ, RES, obs).mean_ppm, field) < 0.12  # gdm's 0.38 m
    assert rel_rmse(kdmvw(occ, RES, obs).mean_ppm, field) < 0.08  # wind across the gradient narrows it


def test_kernel_is_a_normalized_gaussian_stretched_along_the_wind():
    ax = (np.arange(-100, 100) + 0.5) * 0.05
    xx, yy = np.meshgrid(ax, ax)
    cells = np.stack([xx.ravel(), yy.ravel()], axis=1)
    obs = np.zeros((1, 2))
    for wind in ([2.0, 0.0], [0.0, -2.0], [1.0, 1.0]):
        w = kernel_weights(cells, obs, np.array([wind]), 0.38, 0.33)[0]
        assert w.sum() * 0.05**2 == pytest.approx(1.0, rel=1e-3)
        d = np.array(wind) / np.hypot(*wind)
        along = np.abs(cells @ d)
        across = np.abs(cells @ np.array([-d[1], d[0]]))
        a = 0.38 + 0.33 * float(np.hypot(*wind))
        assert np.sqrt((w * along**2).sum() / w.sum()) == pytest.approx(a, rel=0.02)
        assert np.sqrt((w * across**2).sum() / w.sum()) == pytest.approx(0.38**2 / a, rel=0.05)
    iso = kernel_weights(cells, obs, None, 0.38, 0.33)[0]
    assert iso.max() == pytest.approx(1 / (2 * math.pi * 0.38**2), rel=0.02)


def test_wind_spreads_a_reading_downwind_and_upwind_not_across():
    occ = np.zeros((21, 21), np.uint8)
    obs = readings([(10, 10), (0, 0)], [100.0, 0.0], (2.0, 0.0))
    # far from the readings the map is r0 = 50; the 100 ppm reading lifts it along the wind only
    g = kdmvw(occ, RES, obs).mean_ppm - 50.0
    assert g[10, 16] > 1.0 and g[10, 16] > 100 * abs(g[16, 10])  # 0.6 m along x (the wind) vs along y
    g_iso = kdmv(occ, RES, obs).mean_ppm - 50.0
    assert g_iso[10, 16] == pytest.approx(g_iso[16, 10]) and g_iso[10, 16] > 0.1


def test_variance_blends_local_and_global_spread():
    occ = np.zeros((10, 40), np.uint8)
    cells = [(i, j) for i in range(3, 7) for j in range(2, 6)] + [(5, 35)]
    gas = [10.0] * 16 + [90.0]
    gm = kdmv(occ, RES, readings(cells, gas))
    r = np.array(gas)
    assert gm.var_ppm[5, 20] == pytest.approx(r.var(), rel=1e-3)  # no kernel mass: v0
    assert gm.mean_ppm[5, 20] == pytest.approx(r.mean(), rel=1e-3)  # ... and r0
    assert gm.var_ppm[4, 3] < 0.1 * r.var()  # among consistent readings
    assert (gm.var_ppm > 0).all() and gm.info["nll_comparable"] is False


def test_kernels_pass_through_walls_as_in_the_original():
    occ = np.zeros((9, 20), np.uint8)
    occ[:, 10] = 1  # a full wall
    g = kdmv(occ, RES, readings([(4, 8), (4, 19)], [100.0, 0.0])).mean_ppm
    assert g[4, 11] > 30.0 and g[4, 10] == 0.0  # right behind the wall; the wall cell holds 0
