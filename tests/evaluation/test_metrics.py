"""Metrics of one estimate against hand-computed values on a 3 x 4 map."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dgse.belief.belief import Belief
from dgse.errors import InputDataError
from dgse.evaluation.metrics import (
    METRIC_KEYS,
    PROB_FLOOR,
    evaluate_belief,
    gaussian_nll,
    lognormal_nll_ppm,
    rmse,
    source_cross_entropy,
    source_localization_error,
)
from dgse.world.case import Case

RES = 0.1
E = math.e


def _case() -> Case:
    """3 x 4 cells, cell (2, 3) solid; wind (1, 0) m/s, c = e - 1 ppm (log(1 + c) = 1) on free cells.

    The source sits in cell (1, 0): centre (0.05, 0.15) m.
    """
    occ = np.zeros((3, 4), np.uint8)
    occ[2, 3] = 1
    free = occ == 0
    wind = np.stack([np.where(free, 1.0, 0.0), np.zeros((3, 4))]).astype(np.float32)
    conc = np.where(free, E - 1.0, 0.0).astype(np.float32)
    return Case(occ, wind, conc, np.array([0.05, 0.15]), RES, {"name": "hand"})


def _belief(info: dict | None = None, **fields) -> Belief:
    occ = _case().occupancy
    p = np.zeros((3, 4))
    p[0, 0] = p[0, 2] = 0.5
    return Belief(occ, RES, fields.pop("source_probs", p), info={"method": "hand", **(info or {})}, **fields)


def _fields(solid_garbage: float = 0.0) -> dict[str, np.ndarray]:
    """Wind mean off by (+0.1, -0.2), variance 1; log-conc mean 1.5 (truth 1), variance 0.25."""
    wm = np.stack([np.full((3, 4), 1.1), np.full((3, 4), -0.2)])
    lm = np.full((3, 4), 1.5)
    # solid cells must not count
    wm[:, 2, 3] = solid_garbage
    lm[2, 3] = solid_garbage
    return {
        "wind_mean": wm,
        "wind_var": np.ones((2, 3, 4)),
        "log_conc_mean": lm,
        "log_conc_var": np.full((3, 4), 0.25),
    }


def test_primitives():
    assert rmse(np.array([1.0, 3.0]), np.array([0.0, 0.0])) == pytest.approx(math.sqrt(5.0))
    # N(0, 1) at 0: 0.5 log(2 pi); at 2 with variance 4: 0.5 (log(8 pi) + 1)
    assert gaussian_nll(np.zeros(1), np.zeros(1), np.ones(1)) == pytest.approx(0.5 * math.log(2 * math.pi))
    assert gaussian_nll(np.array([2.0]), np.zeros(1), np.array([4.0])) == pytest.approx(
        0.5 * (math.log(8 * math.pi) + 1.0)
    )
    # a zero variance is floored, not infinite
    assert math.isfinite(gaussian_nll(np.array([1.0]), np.zeros(1), np.zeros(1)))
    assert math.isnan(rmse(np.zeros(0), np.zeros(0)))
    with pytest.raises(InputDataError):
        rmse(np.zeros(2), np.zeros(3))


def test_source_error_and_cross_entropy():
    b = _belief()
    # estimate: x = 0.5 * 0.05 + 0.5 * 0.25 = 0.15, y = 0.05; truth (0.05, 0.15)
    assert b.source_estimate() == pytest.approx((0.15, 0.05))
    assert source_localization_error(b, (0.05, 0.15)) == pytest.approx(math.hypot(0.1, 0.1))
    # zero mass at the true cell: the floor
    assert source_cross_entropy(b, (1, 0)) == pytest.approx(-math.log(PROB_FLOOR))
    assert source_cross_entropy(b, (0, 2)) == pytest.approx(math.log(2.0))
    with pytest.raises(InputDataError, match="outside"):
        source_cross_entropy(b, (3, 0))


def test_all_metrics_hand_computed():
    case = _case()
    m = evaluate_belief(_belief(**_fields(solid_garbage=100.0)), case).to_dict()
    assert tuple(m) == METRIC_KEYS
    assert m["sl_error_m"] == pytest.approx(math.hypot(0.1, 0.1))
    # most likely cell: the first of the two maxima, (0, 0) centre (0.05, 0.05)
    assert m["map_error_m"] == pytest.approx(0.1)
    assert m["ce"] == pytest.approx(27.631021, abs=1e-5)
    assert m["entropy"] == pytest.approx(math.log(2.0))
    assert m["normalized_entropy"] == pytest.approx(math.log(2.0) / math.log(11.0))
    # wind: errors 0.1 (x) and 0.2 (y) on every free cell, unit variance
    assert m["wf_rmse"] == pytest.approx(math.sqrt((0.01 + 0.04) / 2))
    assert m["wf_nll"] == pytest.approx(0.5 * (math.log(2 * math.pi) + 0.025))
    # log concentration: error 0.5, variance 0.25
    assert m["cf_rmse"] == pytest.approx(0.5)
    assert m["cf_nll"] == pytest.approx(0.5 * (math.log(2 * math.pi * 0.25) + 1.0))
    # ppm, a log-space belief (DGSE): the median exp(1.5) - 1 against c = e - 1, and the exact
    # density of c: NLL of log(1 + c) = 1 under N(1.5, 0.25) plus log(1 + c) = 1
    assert m["cf_rmse_ppm"] == pytest.approx(math.exp(1.5) - E)
    assert m["cf_nll_ppm"] == pytest.approx(m["cf_nll"] + 1.0)


def test_ppm_space_belief_is_scored_by_its_own_gaussian():
    """A GDM-style belief (ppm moments, lognormal moment match) keeps its ppm mean and Gaussian NLL."""
    case = _case()
    f = _fields()
    mean_ppm = math.exp(1.5 + 0.125) - 1.0
    var_ppm = (math.exp(0.25) - 1.0) * math.exp(3.0 + 0.25)
    err = mean_ppm - (E - 1.0)
    expected_nll = 0.5 * (math.log(2 * math.pi * var_ppm) + err**2 / var_ppm)
    for info in ({"conc_space": "ppm"}, {"conc_representation": "ppm moments, lognormal moment match"}):
        m = evaluate_belief(_belief(info=info, **f), case).to_dict()
        assert m["cf_rmse_ppm"] == pytest.approx(abs(err))
        assert m["cf_nll_ppm"] == pytest.approx(expected_nll)
        assert m["cf_rmse"] == pytest.approx(0.5)  # log-space metrics do not depend on the space
    # the same fields read as a log-space belief give the other numbers
    log = evaluate_belief(_belief(info={"conc_space": "log"}, **f), case).to_dict()
    assert log["cf_rmse_ppm"] == pytest.approx(math.exp(1.5) - E)


def test_lognormal_nll_ppm_is_the_exact_density():
    from scipy import stats

    rng = np.random.default_rng(1)
    c = rng.uniform(0.0, 5000.0, 50)
    m = rng.normal(3.0, 2.0, 50)
    v = rng.uniform(0.01, 20.0, 50)
    # 1 + c ~ lognormal(m, v): scipy's lognorm with s = sqrt(v), scale = e^m, evaluated at 1 + c
    ref = -stats.lognorm.logpdf(1.0 + c, s=np.sqrt(v), scale=np.exp(m))
    assert lognormal_nll_ppm(c, m, v) == pytest.approx(float(ref.mean()), rel=1e-10)
    # it integrates to 1 over c >= 0 (here a narrow one, numerically)
    grid = np.linspace(0.0, 200.0, 400_001)
    dens = np.exp(
        -np.array([lognormal_nll_ppm(np.array([x]), np.array([3.0]), np.array([0.1])) for x in grid[::1000]])
    )
    assert dens.shape == (401,)
    full = np.exp(-(0.5 * (math.log(2 * math.pi * 0.1) + (np.log1p(grid) - 3.0) ** 2 / 0.1) + np.log1p(grid)))
    assert np.trapezoid(full, grid) == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(dens, full[::1000], rtol=1e-9)
    with pytest.raises(InputDataError):
        lognormal_nll_ppm(np.zeros(2), np.zeros(3), np.ones(3))
    assert math.isnan(lognormal_nll_ppm(np.zeros(0), np.zeros(0), np.zeros(0)))


def test_ppm_nll_does_not_explode_with_a_large_log_variance():
    """The old Gaussian-with-lognormal-moments NLL and mean blew up where v is large; these do not."""
    case = _case()
    f = _fields()
    f["log_conc_var"] = np.full((3, 4), 20.0)
    m = evaluate_belief(_belief(**f), case).to_dict()
    assert m["cf_rmse_ppm"] == pytest.approx(math.exp(1.5) - E)  # the median, not e^(1.5 + 10)
    assert m["cf_nll_ppm"] == pytest.approx(0.5 * (math.log(2 * math.pi * 20.0) + 0.25 / 20.0) + 1.0)


def test_missing_fields_are_nan():
    case = _case()
    f = _fields()
    only_source = evaluate_belief(_belief(), case).to_dict()
    for key in ("wf_rmse", "wf_nll", "cf_rmse", "cf_nll", "cf_rmse_ppm", "cf_nll_ppm"):
        assert math.isnan(only_source[key]), key
    assert math.isfinite(only_source["ce"])
    means_only = evaluate_belief(_belief(wind_mean=f["wind_mean"], log_conc_mean=f["log_conc_mean"]), case)
    d = means_only.to_dict()
    assert d["wf_rmse"] == pytest.approx(math.sqrt(0.025)) and math.isnan(d["wf_nll"])
    assert d["cf_rmse"] == pytest.approx(0.5) and math.isnan(d["cf_nll"]) and math.isnan(d["cf_nll_ppm"])
    # without a variance the ppm mean is exp(m) - 1
    assert d["cf_rmse_ppm"] == pytest.approx(math.exp(1.5) - E)


def test_grid_mismatch():
    case = _case()
    other = Belief(np.zeros((4, 4), np.uint8), RES, np.full((4, 4), 1 / 16))
    with pytest.raises(InputDataError, match="map"):
        evaluate_belief(other, case)
    coarse = Belief(case.occupancy, 0.2, _belief().source_probs)
    with pytest.raises(InputDataError, match="cell size"):
        evaluate_belief(coarse, case)
