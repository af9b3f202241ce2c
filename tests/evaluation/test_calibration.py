import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.evaluation.calibration import (
    DEFAULT_LEVELS,
    SIGMA_LEVELS,
    calibration_difference,
    calibration_error,
    chance_calibration_error,
    coverage_curve,
    credible_level,
    interval_hits,
)


def test_calibrated_gaussian_covers_its_levels():
    rng = np.random.default_rng(0)
    mean = rng.normal(size=200_000)
    sd = rng.uniform(0.1, 3.0, size=mean.size)
    truth = mean + sd * rng.normal(size=mean.size)
    hits, n = interval_hits(truth, mean, sd**2, SIGMA_LEVELS)
    assert n == mean.size
    np.testing.assert_allclose(hits / n, SIGMA_LEVELS, atol=0.005)


def test_overconfident_gaussian_undercovers_and_mask_counts_only_selected():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=(2, 50, 60))
    mean = np.zeros_like(truth)
    mask = np.zeros((50, 60), bool)
    mask[:10] = True
    hits, n = interval_hits(truth, mean, np.full_like(truth, 0.25), (0.6826894921370859,), mask=mask)
    assert n == 2 * 10 * 60
    assert hits[0] / n < 0.45  # sd 0.5 claimed, 1 true: covers P(|z| < 0.5) = 0.38


def test_credible_level_by_hand():
    p = np.array([[0.5, 0.2], [0.2, 0.1]])
    assert credible_level(p, (0, 0)) == pytest.approx(0.25)
    assert credible_level(p, (0, 1)) == pytest.approx(0.5 + 0.2)  # ties: half of 0.4
    assert credible_level(p, (1, 1)) == pytest.approx(0.9 + 0.05)


def test_posterior_sampled_from_itself_is_calibrated():
    rng = np.random.default_rng(2)
    levels = []
    for _ in range(3000):
        p = rng.dirichlet(np.full(30, 0.3))
        truth = rng.choice(30, p=p)
        levels.append(credible_level(p, truth))
    cov = coverage_curve(levels)
    assert calibration_error(cov) < 0.02
    # a posterior that always points at the wrong cells is badly calibrated
    bad = [credible_level(np.r_[0.9, np.full(29, 0.1 / 29)], 5) for _ in range(10)]
    assert calibration_error(coverage_curve(bad, DEFAULT_LEVELS)) > 0.3


def test_chance_calibration_error_is_the_sampling_noise_of_a_calibrated_posterior():
    # one case: |1{u <= p} - p| has mean 2 p (1 - p) at each level
    lv = np.asarray(DEFAULT_LEVELS)
    exact = float((2 * lv * (1 - lv)).mean())
    assert chance_calibration_error(1) == pytest.approx(exact, rel=0.02)
    # it shrinks like 1 / sqrt(n): 25 times the cases, a fifth of the noise
    small, large = chance_calibration_error(6), chance_calibration_error(150)
    assert 4.0 < small / large < 6.0
    with pytest.raises(InputDataError):
        chance_calibration_error(0)


def test_calibration_difference_resamples_whole_scenarios():
    """A clear difference (one method's truth always in its tails) has an interval away from 0;
    two calibrated methods' has one around 0; and scenarios whose trials agree make the
    interval wider than independent estimates would."""
    rng = np.random.default_rng(3)
    groups = np.repeat(np.arange(20), 10)
    good = rng.uniform(size=200)
    sure = 0.7 + 0.3 * rng.uniform(size=200)  # overconfident: the truth above level 0.7
    d = calibration_difference(sure, good, groups, n_boot=300)
    assert d["difference"] == pytest.approx(
        calibration_error(coverage_curve(sure)) - calibration_error(coverage_curve(good))
    )
    assert d["low"] > 0.1 and d["groups"] == 20
    other = rng.uniform(size=200)
    same = calibration_difference(other, good, groups, n_boot=300)
    assert same["low"] < 0.0 < same["high"]
    # each scenario's trials share a level (plus a little noise): fewer independent draws
    shared = np.clip(np.repeat(rng.uniform(size=20), 10) + rng.normal(0, 0.02, 200), 0, 1)
    clustered = calibration_difference(shared, good, groups, n_boot=300)
    spread = calibration_difference(shared, good, np.arange(200), n_boot=300)
    assert clustered["high"] - clustered["low"] > 1.5 * (spread["high"] - spread["low"])
    with pytest.raises(InputDataError):
        calibration_difference(good, good[:-1], groups)
    with pytest.raises(InputDataError):
        calibration_difference(good, good, groups, coverage=1.0)


def test_bad_input():
    with pytest.raises(InputDataError):
        interval_hits(np.zeros(3), np.zeros(4), np.ones(3))
    with pytest.raises(InputDataError):
        credible_level(np.zeros(4), 0)
    with pytest.raises(InputDataError):
        coverage_curve([0.5], levels=(0.0, 0.5))
