"""Shared behaviour of every GDM baseline: input checks, the Belief, the registry, tuning files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgse.belief.belief import Belief
from dgse.belief.estimator import Estimator
from dgse.errors import InputDataError
from dgse.estimators.registry import ESTIMATORS, estimator_names, get_estimator
from dgse.mapping import TUNING_FORMAT, GasMap, load_tuning, ppm_to_log_moments
from dgse.mapping.gmrf import GGMRF
from dgse.sensing.sensors import Observations
from tests.mapping import RES, readings

METHODS = ESTIMATORS.names(tag="gdm")


def _estimator(name: str) -> Estimator:
    return ESTIMATORS.factory(name)()


def _two_rooms() -> np.ndarray:
    occ = np.zeros((8, 12), np.uint8)
    occ[:, 6] = 1
    occ[3:5, 6] = 0  # a door
    return occ


@pytest.mark.parametrize("name", METHODS)
def test_bad_inputs_are_rejected_clearly(name):
    est = _estimator(name)
    occ = _two_rooms()
    good = readings([(1, 1), (6, 10)], [5.0, 1.0], (0.5, 0.0))
    with pytest.raises(InputDataError, match="no observations"):
        est.estimate(occ, RES, Observations.empty())
    with pytest.raises(InputDataError, match="in a wall"):
        est.estimate(occ, RES, readings([(1, 1), (0, 6)], [1.0, 2.0]))
    with pytest.raises(InputDataError, match="outside the map"):
        est.estimate(occ, RES, readings([(1, 1), (8, 0)], [1.0, 2.0]))
    with pytest.raises(InputDataError, match="non-finite"):
        readings([(1, 1)], [np.nan])  # the container refuses NaN ...
    bad = readings([(1, 1), (2, 2)], [1.0, 2.0])
    bad.gas[1] = np.nan  # ... and the estimators check again (arrays stay writable)
    with pytest.raises(InputDataError, match="non-finite"):
        est.estimate(occ, RES, bad)
    with pytest.raises(InputDataError, match="resolution"):
        est.estimate(occ, 0.0, good)
    with pytest.raises(InputDataError, match="no free cell"):
        est.estimate(np.ones_like(occ), RES, good)
    with pytest.raises(InputDataError, match="2-D"):
        est.estimate(occ[None], RES, good)
    with pytest.raises(InputDataError, match="Observations"):
        est.estimate(occ, RES, {"cells": [(1, 1)]})  # type: ignore[arg-type]


@pytest.mark.parametrize("name", METHODS)
def test_belief_carries_the_ppm_moments(name):
    occ = _two_rooms()
    obs = readings([(1, 1), (2, 3), (6, 10), (4, 8)], [50.0, 40.0, 3.0, 10.0], (0.8, 0.2))
    est = _estimator(name)
    gm: GasMap = est.map(occ, RES, obs)
    b = est.estimate(occ, RES, obs)
    assert isinstance(b, Belief) and b.method == name and b.info["seconds"] > 0
    free = occ == 0
    assert np.allclose(b.source_probs[free], 1.0 / free.sum()) and b.info["source_model"] == "none"
    assert b.info["nll_comparable"] is (name in ("ggmrf", "gwgmrf"))
    assert np.allclose(b.conc_mean_ppm, np.maximum(gm.mean_ppm, 0), rtol=1e-9, atol=1e-9)
    assert np.allclose(b.conc_var_ppm, gm.var_ppm, rtol=1e-7, atol=1e-9)
    assert (gm.mean_ppm[~free] == 0).all() and (gm.var_ppm[~free] == 0).all()
    assert (gm.var_ppm[free] > 0).all()
    if name == "gwgmrf":
        assert b.wind_mean is not None and b.wind_var is not None and (b.wind_var[:, free] > 0).all()
    else:
        assert b.wind_mean is None and gm.wind_mean is None


def test_lognormal_moment_match_round_trip():
    rng = np.random.default_rng(1)
    m = rng.uniform(0, 1e4, 200) * rng.integers(0, 2, 200)
    v = rng.uniform(0, 1e6, 200) * rng.integers(0, 2, 200)
    mu, s2 = ppm_to_log_moments(m, v)
    assert s2 is not None and (s2 >= 0).all()
    assert np.allclose(np.expm1(mu + s2 / 2), m, rtol=1e-10, atol=1e-8)
    assert np.allclose(np.expm1(s2) * np.exp(2 * mu + s2), v, rtol=1e-8, atol=1e-8)
    mu, s2 = ppm_to_log_moments(np.array([-3.0, 2.0]), None)
    assert s2 is None and np.allclose(mu, [0.0, np.log(3.0)])  # negative means clip to 0


def test_registry_builds_every_method():
    assert METHODS == ["gabp", "ggmrf", "gwgmrf", "kdmv", "kdmvw"]
    assert set(METHODS) <= set(estimator_names())
    for name in METHODS:
        assert isinstance(get_estimator(name), Estimator)
    assert get_estimator("ggmrf", sigma_r=2.0).params.sigma_r == 2.0


def test_tuning_file_overrides_defaults(tmp_path):
    path = tmp_path / "gdm_tuning.json"
    path.write_text(json.dumps({"format": TUNING_FORMAT, "methods": {"ggmrf": {"sigma_r": 3.0}}}))
    assert load_tuning(path) == {"ggmrf": {"sigma_r": 3.0}}
    assert GGMRF().params.sigma_r == 1.128  # the published default without a file
    assert GGMRF(tuning=path).params.sigma_r == 3.0
    assert GGMRF(tuning=path, sigma_r=5.0).params.sigma_r == 5.0  # explicit beats the file
    assert GGMRF(tuning={"ggmrf": {"sigma_z": 0.2}}).params.sigma_z == 0.2
    with pytest.raises(InputDataError, match="unknown ggmrf option"):
        GGMRF(tuning={"ggmrf": {"sigma_q": 1.0}})
    with pytest.raises(InputDataError, match="positive"):
        GGMRF(sigma_r=-1.0)
    with pytest.raises(InputDataError, match="no such tuning file"):
        GGMRF(tuning=tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text(json.dumps({"methods": {}}))
    with pytest.raises(InputDataError, match="not a GDM tuning file"):
        load_tuning(tmp_path / "bad.json")
