"""Noise models of Table I: parameter ranges, sample moments, clipping, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from dgse.errors import InputDataError
from dgse.sensing.noise import (
    NoiseModel,
    NoiseParams,
    NoiseRanges,
    draw_noise_params,
    gas_reading,
    wind_reading,
)

N = 20_000


def test_drawn_parameters_cover_table_one_ranges():
    rng = np.random.default_rng(1)
    cbar = 12.0
    ps = [draw_noise_params(rng, cbar) for _ in range(3000)]
    for name, hi in (("alpha_g", 1.0), ("sigma_env", 0.5 * cbar), ("alpha_w", 0.5), ("sigma_a_deg", 15.0)):
        v = np.array([getattr(p, name) for p in ps])
        assert v.min() >= 0 and v.max() <= hi
        assert v.min() < 0.01 * hi and v.max() > 0.99 * hi  # the whole range is used
        assert v.mean() == pytest.approx(hi / 2, rel=0.05)  # uniform


def test_sigma_env_scales_with_mean_concentration():
    a = draw_noise_params(np.random.default_rng(3), 1.0)
    b = draw_noise_params(np.random.default_rng(3), 40.0)
    assert b.sigma_env == pytest.approx(40.0 * a.sigma_env)
    assert (a.alpha_g, a.alpha_w, a.sigma_a_deg) == (b.alpha_g, b.alpha_w, b.sigma_a_deg)


def test_custom_and_noiseless_ranges():
    rng = np.random.default_rng(0)
    p = NoiseModel(NoiseRanges(alpha_g=(0.2, 0.2), sigma_env_frac=(0.1, 0.1))).draw(rng, 5.0)
    assert p.alpha_g == 0.2 and p.sigma_env == pytest.approx(0.5)
    assert NoiseModel.noiseless().draw(rng, 5.0) == NoiseParams.zero()
    with pytest.raises(InputDataError, match="alpha_w"):
        NoiseRanges(alpha_w=(0.5, 0.1))
    with pytest.raises(InputDataError, match="sigma_env"):
        NoiseParams(0.1, -1.0, 0.1, 1.0)
    with pytest.raises(InputDataError, match="mean concentration"):
        draw_noise_params(rng, float("nan"))


def test_noiseless_readings_equal_the_truth():
    rng = np.random.default_rng(0)
    c = np.array([0.0, 1.5, 300.0])
    w = np.array([[1.0, -2.0], [0.0, 0.0], [-0.3, 0.1]])
    assert np.array_equal(gas_reading(c, NoiseParams.zero(), rng), c)
    np.testing.assert_allclose(wind_reading(w, NoiseParams.zero(), rng), w, atol=1e-15)


def test_gas_reading_moments():
    p = NoiseParams(alpha_g=0.2, sigma_env=1.0, alpha_w=0.0, sigma_a_deg=0.0)
    c = np.full(N, 10.0)
    z = gas_reading(c, p, np.random.default_rng(7))
    sigma = 0.2 * 10.0 + 1.0
    assert z.mean() == pytest.approx(10.0, rel=0.01)
    assert z.std() == pytest.approx(sigma, rel=0.03)
    assert np.array_equal(c, np.full(N, 10.0))  # the truth is untouched


def test_gas_noise_floor_applies_at_zero_concentration_and_is_clipped():
    p = NoiseParams(alpha_g=0.0, sigma_env=2.0, alpha_w=0.0, sigma_a_deg=0.0)
    z = gas_reading(np.zeros(N), p, np.random.default_rng(8))
    assert z.min() == 0.0
    assert np.mean(z == 0) == pytest.approx(0.5, abs=0.015)  # half the draws were negative
    # the positive half is a half-normal of scale sigma_env
    assert z[z > 0].mean() == pytest.approx(2.0 * math.sqrt(2 / math.pi), rel=0.03)


def test_gas_clipping_fraction_matches_the_normal_cdf():
    p = NoiseParams(alpha_g=1.0, sigma_env=2.0, alpha_w=0.0, sigma_a_deg=0.0)
    z = gas_reading(np.full(N, 1.0), p, np.random.default_rng(9))
    sigma = 1.0 * 1.0 + 2.0
    assert np.all(z >= 0)
    assert np.mean(z == 0) == pytest.approx(norm.cdf(-1.0 / sigma), abs=0.01)


def test_wind_reading_speed_and_direction_moments():
    p = NoiseParams(alpha_g=0.0, sigma_env=0.0, alpha_w=0.1, sigma_a_deg=10.0)
    w = np.tile([3.0, 4.0], (N, 1))  # |w| = 5
    z = wind_reading(w, p, np.random.default_rng(10))
    speed = np.hypot(z[:, 0], z[:, 1])
    assert speed.mean() == pytest.approx(5.0, rel=0.01)
    assert speed.std() == pytest.approx(0.1 * 5.0, rel=0.03)
    dang = np.angle(np.exp(1j * (np.arctan2(z[:, 1], z[:, 0]) - math.atan2(4.0, 3.0))))
    assert abs(np.degrees(dang.mean())) < 0.3
    assert np.degrees(dang.std()) == pytest.approx(10.0, rel=0.03)


def test_wind_speed_noise_is_proportional_and_zero_wind_reads_zero():
    p = NoiseParams(alpha_g=0.0, sigma_env=0.0, alpha_w=0.3, sigma_a_deg=15.0)
    w = np.concatenate([np.tile([0.0, -0.5], (N, 1)), np.zeros((10, 2))])
    z = wind_reading(w, p, np.random.default_rng(11))
    speed = np.hypot(z[:N, 0], z[:N, 1])
    assert speed.std() == pytest.approx(0.3 * 0.5, rel=0.03)
    assert np.array_equal(z[N:], np.zeros((10, 2)))


def test_negative_speed_draws_are_clipped_to_zero():
    p = NoiseParams(alpha_g=0.0, sigma_env=0.0, alpha_w=0.5, sigma_a_deg=0.0)
    z = wind_reading(np.tile([1.0, 0.0], (N, 1)), p, np.random.default_rng(12))
    assert np.all(z[:, 0] >= 0)  # never reversed
    assert np.mean(z[:, 0] == 0) == pytest.approx(norm.cdf(-2.0), abs=0.005)


def test_readings_are_deterministic_per_seed():
    p = NoiseParams(0.5, 1.0, 0.2, 5.0)
    c = np.linspace(0, 50, 40)
    w = np.random.default_rng(0).normal(size=(40, 2))
    a = gas_reading(c, p, np.random.default_rng(5)), wind_reading(w, p, np.random.default_rng(5))
    b = gas_reading(c, p, np.random.default_rng(5)), wind_reading(w, p, np.random.default_rng(5))
    d = gas_reading(c, p, np.random.default_rng(6))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], d)


def test_wind_shape_is_checked():
    with pytest.raises(InputDataError, match=r"\(n, 2\)"):
        wind_reading(np.zeros((3, 3)), NoiseParams.zero(), np.random.default_rng(0))
