"""The compiled censored-readings kernel: its normal-distribution functions against SciPy's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special

from dgse.posterior.censored_kernel import log_ndtr, log_ndtr_table, ndtri_exp


def test_log_ndtr_agrees_with_scipy_in_both_tails() -> None:
    x = np.concatenate([-np.logspace(-4, 4, 400), [0.0], np.logspace(-4, 1.6, 300)])
    ours = np.array([log_ndtr(float(v)) for v in x])
    ref = special.log_ndtr(x)
    np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-300)
    assert log_ndtr(-math.inf) == -math.inf
    assert log_ndtr(math.inf) == 0.0


def test_log_ndtr_table_is_within_1e_10_nats_of_scipy_and_exact_outside_its_range() -> None:
    # dense across the table's nodes (1/64 apart) and towards 0 from below
    x = np.concatenate([np.linspace(-38.0, -1e-9, 200_003), -np.logspace(-12, -2, 200)])
    ours = np.array([log_ndtr_table(float(v)) for v in x])
    err = np.abs(ours - special.log_ndtr(x))
    assert err.max() < 1e-10
    # outside [-38, 0) it is log_ndtr itself
    out = np.array([-1e3, -38.5, -0.0, 0.0, 1e-4, 3.0, 40.0])
    np.testing.assert_array_equal([log_ndtr_table(float(v)) for v in out], [log_ndtr(float(v)) for v in out])


def test_ndtri_exp_inverts_log_ndtr_over_the_whole_range() -> None:
    # from log p = -1e6 (far below double precision's p) to p = 1 - 1e-15
    y = np.concatenate([-np.logspace(6, -15, 800), [math.log(0.5), math.log(0.02425)]])
    ours = np.array([ndtri_exp(float(v)) for v in y])
    np.testing.assert_allclose(ours, special.ndtri_exp(y), rtol=1e-11, atol=1e-13)
    # a round trip through log Phi lands on the same value
    back = np.array([log_ndtr(float(v)) for v in ours])
    np.testing.assert_allclose(back, y, rtol=1e-11, atol=1e-15)


@pytest.mark.parametrize(("y", "expected"), [(0.0, math.inf), (-math.inf, -math.inf)])
def test_ndtri_exp_ends(y: float, expected: float) -> None:
    assert ndtri_exp(y) == expected


def test_ndtri_exp_above_zero_is_nan() -> None:
    assert math.isnan(ndtri_exp(0.5))


def test_mills_ratio_by_series_near_zero_and_by_the_table_beyond() -> None:
    from dgse.posterior.censored_kernel import _mills

    x = np.concatenate([np.linspace(-3e-3, 3e-3, 61), np.linspace(-5.0, 30.0, 71)])
    ours = np.array([_mills(float(v)) for v in x])
    ref = np.exp(-0.5 * x * x - special.log_ndtr(-x)) / math.sqrt(2.0 * math.pi)
    # the series to 1e-12; beyond it the table's 1e-10 nats of log Phi are its relative error
    near = np.abs(x) < 1e-3
    np.testing.assert_allclose(ours[near], ref[near], rtol=1e-12)
    np.testing.assert_allclose(ours[~near], ref[~near], rtol=1e-10)


def test_zeros_slopes_in_one_pass_are_the_separate_passes_to_the_bit() -> None:
    """``_zeros_slopes`` fuses ``G`` and its slopes into one pass (the tilted rate's Newton steps);
    a search's numbers must not move by it, so it must give the same bits as the two passes."""
    from dgse.posterior.censored_kernel import _log_phi_sum, _tau_sums, _zeros_slopes

    rng = np.random.default_rng(5)
    b = rng.exponential(1.0, 40) * (rng.random(40) < 0.7)
    b[:3] = [1e-6, 3e-4, 0.0]  # zeros in the Mills ratio's series range
    for lam in (0.0, 1e-5, 0.3, 2.0, 40.0):
        g0, g1, g2 = _zeros_slopes(lam, b)
        _s1, _s2, h1, h2 = _tau_sums(lam, 1.0, b)
        assert (g0, g1, g2) == (_log_phi_sum(lam, b), h1, h2)
        # and the slopes are those of G: central differences
        d = 1e-5 * max(lam, 1.0)
        fd1 = (_log_phi_sum(lam + d, b) - _log_phi_sum(lam - d, b)) / (2 * d)
        assert g1 == pytest.approx(fd1, rel=1e-4, abs=1e-6)


def test_log_phi_series_stands_for_a_faint_zero_within_2e_12_nats() -> None:
    """The Taylor series of ``log Phi(-x)`` that the faint zeros' power sums feed, against SciPy
    on the faint range ``|x| <= _SERIES_X``; its first two derivatives against ``-m`` and
    ``-m (m - x)`` (``m``: the Mills ratio)."""
    from dgse.posterior.censored_kernel import _SERIES, _SERIES_X, _series_slopes

    x = np.linspace(-_SERIES_X, _SERIES_X, 801)  # lambda < 0 in the tilted rate's Newton steps
    poly = np.polynomial.Polynomial(_SERIES)
    assert np.abs(poly(x) - special.log_ndtr(-x)).max() < 2e-12
    m = np.exp(-0.5 * x * x - special.log_ndtr(-x)) / math.sqrt(2.0 * math.pi)
    np.testing.assert_allclose(poly.deriv(1)(x), -m, rtol=1e-9)
    np.testing.assert_allclose(poly.deriv(2)(x), -m * (m - x), rtol=1e-8)
    # one zero b at lambda = 1: the power sums are b^k, G' = b f'(b) and G'' = b^2 f''(b)
    for v in (0.0, 0.05, _SERIES_X):
        want = (poly(v), v * poly.deriv(1)(v), v * v * poly.deriv(2)(v))
        assert _series_slopes(1.0, v ** np.arange(_SERIES.size)) == pytest.approx(want, rel=1e-13, abs=1e-15)


def test_split_zeros_give_the_sums_of_every_zero() -> None:
    """A candidate's zeros split into those it reaches and the faint ones (power sums): ``G``, its
    slopes and the Newton sums over ``log tau`` equal the sums over every zero, to the series'
    1e-12 nats a zero within the cap and to rounding above it (every zero summed)."""
    from dgse.posterior.censored_kernel import (
        _SERIES_ORDER,
        _SERIES_X,
        _g_split,
        _log_phi_sum,
        _slopes_split,
        _split_zeros,
        _tau_split,
        _tau_sums,
        _zeros_slopes,
    )

    rng = np.random.default_rng(8)
    b = np.concatenate([rng.exponential(1.0, 30), rng.exponential(1e-3, 60), np.zeros(20), [1e-7, 0.05]])
    rng.shuffle(b)
    cap = 20.0
    row = np.empty(b.size)
    mom = np.empty(_SERIES_ORDER + 1)
    nb = _split_zeros(b, cap, row, mom)
    faint = b <= _SERIES_X / cap
    assert nb == (~faint).sum() and 0 < nb < b.size
    # the reached zeros first, in their order; the faint ones' power sums
    np.testing.assert_array_equal(row[:nb], b[~faint])
    np.testing.assert_array_equal(np.sort(row), np.sort(b))
    np.testing.assert_allclose(mom, [(b[faint] ** k).sum() for k in range(_SERIES_ORDER + 1)], rtol=1e-13)
    for lam in (0.0, 1e-4, 0.7, cap, 2.0 * cap, -0.5):
        tol = 1e-12 * faint.sum() + 1e-12 * abs(_log_phi_sum(lam, b))
        assert _g_split(lam, row, nb, mom, cap) == pytest.approx(_log_phi_sum(lam, b), abs=tol)
        got = _slopes_split(lam, row, nb, mom, cap)
        np.testing.assert_allclose(got, _zeros_slopes(lam, b), rtol=1e-9, atol=tol)
        for e in (0.5, 1.0):
            np.testing.assert_allclose(
                _tau_split(lam / e, e, row, nb, mom, cap), _tau_sums(lam / e, e, b), rtol=1e-9, atol=tol
            )
    # an unbounded cap: only the exact zeros are faint, log(1/2) each at any lambda
    nb = _split_zeros(b, math.inf, row, mom)
    assert nb == (b > 0).sum() and mom[0] == (b == 0).sum() and mom[1] == 0.0
    assert _g_split(1e3, row, nb, mom, math.inf) == pytest.approx(_log_phi_sum(1e3, b), rel=1e-13)


def test_plug_in_factor_is_the_sum_of_log_phi() -> None:
    from dgse.posterior.censored_kernel import plug_in_log_factor

    rng = np.random.default_rng(3)
    Bt = rng.exponential(1.0, (50, 7)) * (rng.random((50, 7)) < 0.6)  # zeros a candidate does not reach
    lam = rng.exponential(2.0, 50)
    want = special.log_ndtr(-lam[:, None] * Bt).sum(axis=1)
    # each of the 7 terms within the table's 1e-10 nats
    np.testing.assert_allclose(plug_in_log_factor(Bt, lam), want, rtol=0.0, atol=7e-10)


def test_tilted_plug_in_factor_is_the_plug_in_one_where_the_zeros_do_not_move_the_rate() -> None:
    """Where the positive readings pin the rate (large ``aa``), the zeros' plug-in factor is
    :func:`plug_in_log_factor`'s; where many zeros see a candidate the positive readings see
    weakly, the rate moves towards 0 and the factor is far less negative, what the positive
    readings lose by the move charged against it."""
    from dgse.posterior.censored_kernel import plug_in_log_factor, tilted_plug_in_log_factor

    rng = np.random.default_rng(4)
    n, c = 40, 12
    Bt = rng.exponential(1.0, (n, c))
    qhat = rng.uniform(0.5, 2.0, n)
    t = np.full(n, 0.0)
    pinned = np.full(n, 1e8)
    plain = plug_in_log_factor(Bt, qhat)  # lambda = q sqrt(tau) with tau = 1
    np.testing.assert_allclose(tilted_plug_in_log_factor(Bt, qhat, pinned, t, 5.0), plain, atol=1e-12)
    loose = np.full(n, 1.0)
    tilted = tilted_plug_in_log_factor(Bt, qhat, loose, t, 5.0)
    assert np.all(tilted > plain + 1.0)
    # a maximum over q: at least its value at q = 0, at most c log(1/2) (each zero's bound)
    assert np.all(tilted >= c * np.log(0.5) - 0.5 * qhat**2 - 1e-9)
    assert np.all(tilted <= c * np.log(0.5) + 1e-9)


def _factor(Bt, qhat, aa, beta_n, alpha_n, margin, tilt_min=None):
    """The kernel on its own, with the censored correction's rules and a given scan margin."""
    from dgse.posterior import adjoint, censored_kernel

    u, log_wu, xh, wh = adjoint._censored_nodes(
        adjoint.CENSORED_Q_NODES, adjoint.CENSORED_Q_PIECES, adjoint.CENSORED_TAU_NODES
    )
    n = qhat.size
    scanned = np.zeros(n, dtype=np.uint8)
    out = censored_kernel.censored_log_factor(
        Bt, qhat, aa, beta_n, alpha_n, 5.0, np.zeros(n), u, log_wu, xh, wh,
        adjoint._chebyshev_coefficient_matrix(adjoint.CENSORED_CHEBYSHEV_POINTS),
        adjoint.CENSORED_NEWTON_STEPS, adjoint.CENSORED_FLOOR, margin, scanned,
        censored_kernel.TILT_MIN if tilt_min is None else tilt_min,
    )  # fmt: skip
    return out, scanned


def test_scan_agrees_with_gauss_hermite_where_that_is_right_and_takes_over_where_not() -> None:
    """Two candidates the positive readings see well (rate 2 of at most 5, a narrow noise
    posterior), one they put far above q_max while the zeros see it and push its rate
    below 0.  With rate nodes that stay where the positive readings put the rate
    (``tilt_min=inf``, the kernel before 2026-11-28 e), Gauss-Hermite around the clipped
    rate is 2.8 nats too low on the third and the default margin scans it; with nodes
    that follow the zeros, Gauss-Hermite is right on all three and nothing is scanned."""
    Bt = np.array([[0.3, 0.1, 0.0], [0.05, 0.2, 0.1], [1.1, 0.6, 0.0]])
    qhat = np.array([2.0, 1.5, 18.0])
    aa = np.array([40.0, 25.0, 0.011])
    beta_n = np.array([4.0, 4.0, 2.1])
    off = math.inf
    gh, none = _factor(Bt, qhat, aa, beta_n, 7.5, math.inf, off)
    scan, every = _factor(Bt, qhat, aa, beta_n, 7.5, -math.inf, off)
    default, which = _factor(Bt, qhat, aa, beta_n, 7.5, 0.5, off)
    assert not none.any() and every.all()
    np.testing.assert_allclose(gh[:2], scan[:2], atol=0.01)
    assert list(which) == [0, 0, 1]
    assert default[2] == scan[2]
    assert gh[2] < scan[2] - 1.0
    tilted, tilted_which = _factor(Bt, qhat, aa, beta_n, 7.5, 0.5)
    tilted_scan, _ = _factor(Bt, qhat, aa, beta_n, 7.5, -math.inf)
    assert not tilted_which.any()
    np.testing.assert_allclose(tilted, tilted_scan, atol=0.02)
    np.testing.assert_allclose(tilted, scan, atol=0.02)
