"""GaBP+: belief propagation converges to the G-GMRF solution of the same model."""

from __future__ import annotations

import numpy as np

from dgse.mapping.gabp import GaBPParams, gabp
from dgse.mapping.gmrf import GGMRFParams, ggmrf
from tests.mapping import RES, channel, dense_readings, readings, rel_rmse


def _case():
    occ = np.zeros((9, 14), np.uint8)
    occ[:, 7] = 1
    occ[3:5, 7] = 0  # a door
    occ[6:8, 2:4] = 1  # a pillar
    obs = readings([(1, 1), (7, 12), (4, 5), (0, 13), (1, 1)], [80.0, 5.0, 30.0, 0.0, 70.0])
    return occ, obs


def _matched(p: GaBPParams) -> GGMRFParams:
    return GGMRFParams(sigma_z=p.lambda_o**-0.5, sigma_r=p.lambda_p**-0.5, sigma_b=p.lambda_d**-0.5)


def test_converges_to_the_ggmrf_mean_of_the_same_model():
    occ, obs = _case()
    p = GaBPParams(epsilon=1e-12)
    bp = gabp(occ, RES, obs, p)
    exact = ggmrf(occ, RES, obs, _matched(p))
    assert bp.info["converged"]
    assert np.abs(bp.mean_ppm - exact.mean_ppm).max() < 1e-8 * exact.mean_ppm.max()
    # the default threshold stops earlier, close to it
    loose = gabp(occ, RES, obs)
    assert loose.info["converged"]
    assert np.abs(loose.mean_ppm - exact.mean_ppm).max() < 1e-2 * exact.mean_ppm.max()


def test_loopy_variances_are_overconfident_and_smaller_near_readings():
    occ, obs = _case()
    p = GaBPParams(epsilon=1e-12)
    bp = gabp(occ, RES, obs, p)
    exact = ggmrf(occ, RES, obs, _matched(p))
    free = occ == 0
    assert (bp.var_ppm[free] > 0).all()
    assert (bp.var_ppm[free] <= exact.var_ppm[free] * (1 + 1e-9)).all()
    assert bp.var_ppm[1, 1] < bp.var_ppm[1, 4]
    assert bp.info["nll_comparable"] is False


def test_message_budget_stops_early_and_residual_bp_finishes_the_job():
    occ, obs = _case()
    cut = gabp(occ, RES, obs, GaBPParams(max_messages=50))
    assert not cut.info["converged"] and np.isfinite(cut.mean_ppm).all()
    # wildfire capped after a few messages: residual BP alone reaches the solution
    p = GaBPParams(epsilon=1e-10, wildfire_messages=20)
    exact = ggmrf(occ, RES, obs, _matched(p))
    both = gabp(occ, RES, obs, p)
    assert both.info["converged"] and both.info["messages_wildfire"] <= 20 + 4
    assert both.info["messages_residual"] > 10 * occ.size and both.info["heap_rebuilds"] > 0
    assert np.abs(both.mean_ppm - exact.mean_ppm).max() < 1e-6 * exact.mean_ppm.max()


def test_dense_noiseless_readings_reproduce_the_field():
    occ, field = channel()
    assert rel_rmse(gabp(occ, RES, dense_readings(occ, field)).mean_ppm, field) < 5e-3
