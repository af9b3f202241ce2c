"""Belief: validation and derived quantities on hand-made posteriors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.errors import InputDataError


def _occ() -> np.ndarray:
    occ = np.zeros((4, 5), np.uint8)
    occ[:, 2] = 1  # a wall column
    return occ


def test_source_estimate_entropy_hand_made():
    occ = _occ()
    p = np.zeros((4, 5))
    p[1, 0] = 0.25  # centre (0.05, 0.15) at res 0.1
    p[3, 4] = 0.75  # centre (0.45, 0.35)
    b = Belief(occ, 0.1, p, info={"method": "hand"})
    x, y = b.source_estimate()
    assert x == pytest.approx(0.25 * 0.05 + 0.75 * 0.45)
    assert y == pytest.approx(0.25 * 0.15 + 0.75 * 0.35)
    assert b.most_likely_cell() == (3, 4)
    assert b.entropy() == pytest.approx(-(0.25 * math.log(0.25) + 0.75 * math.log(0.75)))
    assert b.n_candidates == 16 and b.max_entropy == pytest.approx(math.log(16))
    assert b.localization_error((x + 0.3, y + 0.4)) == pytest.approx(0.5)
    assert b.method == "hand" and math.isnan(b.info["seconds"])
    assert b.grid.shape == (4, 5) and b.wind_mean is None and b.conc_mean_ppm is None


def test_uniform_entropy_is_log_n():
    occ = _occ()
    p = normalize_source_probs(np.ones(occ.shape), occ)
    assert p[:, 2].sum() == 0 and p.sum() == pytest.approx(1)
    b = Belief(occ, 0.1, p)
    assert b.entropy() == pytest.approx(math.log(16))
    assert b.normalized_entropy() == pytest.approx(1.0)


def test_lognormal_concentration_moments():
    occ = _occ()
    p = normalize_source_probs(np.ones(occ.shape), occ)
    m = np.full(occ.shape, 1.0)
    v = np.full(occ.shape, 0.5)
    b = Belief(occ, 0.1, p, log_conc_mean=m, log_conc_var=v)
    np.testing.assert_allclose(b.conc_mean_ppm, np.exp(1.25) - 1)
    np.testing.assert_allclose(b.conc_var_ppm, (np.exp(0.5) - 1) * np.exp(2.5))
    # Monte Carlo check of the lognormal formulas
    rng = np.random.default_rng(0)
    c = np.expm1(rng.normal(1.0, math.sqrt(0.5), 400_000))
    assert c.mean() == pytest.approx(b.conc_mean_ppm[0, 0], rel=1e-2)
    assert c.var() == pytest.approx(b.conc_var_ppm[0, 0], rel=3e-2)
    no_var = Belief(occ, 0.1, p, log_conc_mean=m)
    np.testing.assert_allclose(no_var.conc_mean_ppm, np.e - 1)
    assert no_var.conc_var_ppm is None


def test_concentration_space_point_map_and_interval():
    occ = _occ()
    p = normalize_source_probs(np.ones(occ.shape), occ)
    m = np.full(occ.shape, 2.0)
    v = np.full(occ.shape, 16.0)  # a large log-space variance: the lognormal mean is e^8 times the median
    b = Belief(occ, 0.1, p, log_conc_mean=m, log_conc_var=v)
    assert b.conc_space == "log"
    np.testing.assert_allclose(b.conc_median_ppm, np.expm1(2.0))
    np.testing.assert_allclose(b.conc_point_ppm, b.conc_median_ppm)
    np.testing.assert_allclose(b.conc_mean_ppm, np.expm1(10.0))  # the mean stays the lognormal mean
    lo, hi = b.conc_interval_ppm(1.0)
    np.testing.assert_allclose(lo, np.expm1(-2.0))
    np.testing.assert_allclose(hi, np.expm1(6.0))
    # a ppm-native belief (as GasMap.to_belief writes it): its mean and a Gaussian interval
    for info in ({"conc_space": "ppm"}, {"conc_representation": "ppm moments, lognormal moment match"}):
        g = Belief(occ, 0.1, p, log_conc_mean=m, log_conc_var=np.full(occ.shape, 0.5), info=info)
        assert g.conc_space == "ppm"
        np.testing.assert_allclose(g.conc_point_ppm, g.conc_mean_ppm)
        lo, hi = g.conc_interval_ppm(2.0)
        np.testing.assert_allclose(hi - lo, 4.0 * np.sqrt(g.conc_var_ppm))
        np.testing.assert_allclose((hi + lo) / 2, g.conc_mean_ppm)
    assert Belief(occ, 0.1, p, log_conc_mean=m).conc_interval_ppm() is None
    assert Belief(occ, 0.1, p).conc_point_ppm is None and Belief(occ, 0.1, p).conc_median_ppm is None
    with pytest.raises(InputDataError, match="conc_space"):
        Belief(occ, 0.1, p, info={"conc_space": "linear"})


def test_validation_errors():
    occ = _occ()
    p = normalize_source_probs(np.ones(occ.shape), occ)
    with pytest.raises(InputDataError, match="sum"):
        Belief(occ, 0.1, 2 * p)
    with pytest.raises(InputDataError, match="solid"):
        Belief(occ, 0.1, np.full(occ.shape, 1 / 20))
    with pytest.raises(InputDataError, match="shape"):
        Belief(occ, 0.1, p, wind_mean=np.zeros((2, 3, 3)))
    with pytest.raises(InputDataError, match="negative"):
        Belief(occ, 0.1, p, wind_mean=np.zeros((2, 4, 5)), wind_var=-np.ones((2, 4, 5)))
    with pytest.raises(InputDataError, match="without"):
        Belief(occ, 0.1, p, log_conc_var=np.ones((4, 5)))
    with pytest.raises(InputDataError, match="resolution"):
        Belief(occ, 0.0, p)
    with pytest.raises(InputDataError, match="free"):
        normalize_source_probs(np.where(occ == 1, 1.0, 0.0), occ)
    with pytest.raises(InputDataError):
        normalize_source_probs(np.full(occ.shape, np.nan), occ)


def test_reducible_variance_is_part_of_the_variance():
    occ = np.zeros((3, 4), np.uint8)
    p = np.full((3, 4), 1 / 12)
    mean, var = np.zeros((2, 3, 4)), np.full((2, 3, 4), 0.5)
    b = Belief(occ, 0.1, p, wind_mean=mean, wind_var=var, wind_var_reducible=0.2 * var)
    assert np.allclose(b.wind_var_to_explore, 0.1) and b.log_conc_var_to_explore is None
    assert np.array_equal(Belief(occ, 0.1, p, wind_mean=mean, wind_var=var).wind_var_to_explore, var)
    with pytest.raises(InputDataError, match="exceeds wind_var"):
        Belief(occ, 0.1, p, wind_mean=mean, wind_var=var, wind_var_reducible=2 * var)
    with pytest.raises(InputDataError, match="without log_conc_var"):
        Belief(occ, 0.1, p, log_conc_mean=np.zeros((3, 4)), log_conc_var_reducible=np.zeros((3, 4)))
    with pytest.raises(InputDataError, match="shape"):
        Belief(occ, 0.1, p, wind_mean=mean, wind_var=var, wind_var_reducible=np.zeros((3, 4)))
