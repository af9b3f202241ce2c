"""The tabled Student-t interval mass against SciPy's CDF."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from dgse.posterior import student_t
from dgse.posterior.student_t import log_interval, log_interval_exact


@pytest.mark.parametrize("nu", [2.0, 5.0, 31.0, 400.0, 3000.0])
def test_the_table_agrees_with_the_exact_mass(nu: float) -> None:
    rng = np.random.default_rng(int(nu))
    n = 3000
    far = np.exp(rng.uniform(-5, 25, n))
    lo = np.concatenate([rng.normal(0.0, 3.0, n), -far, far])
    hi = lo + np.exp(rng.uniform(-12, 8, lo.size))
    hi[::5] = np.inf
    ours = log_interval(lo, hi, nu)
    exact = log_interval_exact(lo, hi, nu)
    assert np.array_equal(np.isfinite(ours), np.isfinite(exact))
    fin = np.isfinite(exact)
    np.testing.assert_allclose(ours[fin], exact[fin], rtol=1e-8, atol=1e-7)


def test_the_exact_mass_is_scipys_where_that_is_representable() -> None:
    nu = 7.0
    lo = np.array([-3.0, -0.5, 0.2, 2.0, -40.0])
    hi = np.array([-1.0, 0.5, 4.0, np.inf, -39.0])
    want = np.log(stats.t.cdf(hi, nu) - stats.t.cdf(lo, nu))
    np.testing.assert_allclose(log_interval(lo, hi, nu), want, rtol=1e-9)
    np.testing.assert_allclose(log_interval_exact(lo, hi, nu), want, rtol=1e-12)


def test_far_tails_and_whole_line() -> None:
    nu = 9.0
    # the whole line holds all the mass; far-out intervals stay finite (no underflow to -inf)
    assert log_interval(np.array([-np.inf]), np.array([np.inf]), nu)[0] == pytest.approx(0.0, abs=1e-12)
    far = log_interval(np.array([1e15, -1e16]), np.array([np.inf, -1e15]), nu)
    assert np.isfinite(far).all() and (far < -300).all()
    assert math.isnan(log_interval(np.array([math.nan]), np.array([1.0]), nu)[0])


def test_narrow_intervals_take_the_density_times_the_width(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the readings hardly see a candidate its interval is ~1e-150 wide: density x width."""
    nu = 6.0
    lo = np.array([-0.0, 0.0, -8.0, 3.0, -1e-160])
    hi = lo + np.array([1.4e-150, 5e-151, 7e-10, 1e-9, 1e-160])
    width = hi - lo  # as represented
    want = np.log(stats.t.pdf(0.5 * (lo + hi), nu)) + np.log(width)
    np.testing.assert_allclose(log_interval(lo, hi, nu), want, rtol=1e-12)
    np.testing.assert_allclose(log_interval(lo, hi, nu), log_interval_exact(lo, hi, nu), rtol=1e-14)
    # in the compiled loop: no call of the exact function (SciPy's CDF per value) for them
    exact = log_interval_exact(lo, hi, nu)

    def refuse(*_args: object) -> None:
        raise AssertionError("narrow intervals went the exact way")

    monkeypatch.setattr(student_t, "log_interval_exact", refuse)
    np.testing.assert_array_equal(log_interval(lo, hi, nu), exact)
