"""Estimator registry and the streaming wrapper."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.belief.estimator import Estimator, StreamingEstimator
from dgse.belief.knowledge import KnowledgeUser
from dgse.errors import InputDataError, UnsupportedError
from dgse.estimators import registry
from dgse.estimators.registry import estimator_names, get_estimator, register_estimator
from dgse.sensing.sensors import Observations


class CountingEstimator(KnowledgeUser):
    """Uniform posterior; counts its calls and remembers the observations it saw."""

    def __init__(self, tag: str = "") -> None:
        self.calls = 0
        self.seen = 0
        self.tag = tag

    def estimate(self, occupancy, resolution, observations) -> Belief:
        self.calls += 1
        self.seen = len(observations)
        p = normalize_source_probs(np.ones(np.shape(occupancy)), occupancy)
        return Belief(occupancy, resolution, p, info={"method": "counting", "seconds": 0.0})


@pytest.fixture
def clean_registry():
    saved = dict(registry.ESTIMATORS._entries)
    yield
    registry.ESTIMATORS._entries.clear()
    registry.ESTIMATORS._entries.update(saved)


def test_builtin_names_and_unknown_rejected():
    names = estimator_names()
    assert {"dgse-o", "dgse-p", "dgse-s"} <= set(names)
    with pytest.raises(UnsupportedError, match=r"unknown estimator 'nope'.*dgse-s"):
        get_estimator("nope")


def test_register_and_get(clean_registry):
    register_estimator("counting", CountingEstimator)
    est = get_estimator("counting", tag="x")
    assert isinstance(est, CountingEstimator) and est.tag == "x"
    assert isinstance(est, Estimator)
    register_estimator("counting", CountingEstimator)  # same factory again: fine
    with pytest.raises(InputDataError, match="already registered"):
        register_estimator("counting", lambda: CountingEstimator())
    register_estimator("counting", lambda: CountingEstimator("y"), replace=True)
    assert get_estimator("counting").tag == "y"
    with pytest.raises(InputDataError, match="invalid estimator name"):
        register_estimator("Bad Name", CountingEstimator)
    with pytest.raises(InputDataError):
        register_estimator("lazy", "no_colon_here")
    register_estimator("lazy", "tests.estimators.test_registry:CountingEstimator")
    assert isinstance(get_estimator("lazy"), CountingEstimator)
    register_estimator("broken", "dgse.no_such_module:factory")
    with pytest.raises(UnsupportedError, match="cannot be loaded"):
        get_estimator("broken")


def test_streaming_estimator_caches_and_accumulates():
    occ = np.zeros((5, 6), np.uint8)
    occ[2, :3] = 1
    inner = CountingEstimator()
    stream = StreamingEstimator(inner, occ, 0.1)
    b0 = stream.belief
    assert inner.calls == 1 and inner.seen == 0 and stream.belief is b0 and inner.calls == 1
    obs = Observations(np.array([[0, 0], [4, 5]]), np.array([1.0, 2.0]), np.zeros((2, 2)))
    b1 = stream.update(obs)
    assert inner.calls == 2 and inner.seen == 2 and b1 is not b0
    stream.add_reading((1, 1), 3.0, (0.1, -0.2), time_s=4.0)
    assert inner.calls == 2  # lazy
    assert stream.belief is not b1 and inner.seen == 3 and len(stream.observations) == 3
    assert stream.n_estimates == 3
    with pytest.raises(InputDataError):
        stream.add_reading((2, 0), 1.0, (0.0, 0.0))  # a wall cell
    stream.reset()
    assert len(stream.observations) == 0
