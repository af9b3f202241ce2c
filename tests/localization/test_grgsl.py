"""GrGSL: hits move mass upwind, misses towards the last hit, no hit no start."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.localization.grgsl import GrGSLEstimator, grgsl_weights
from dgse.sensing.sensors import Observations


def _map() -> np.ndarray:
    occ = np.zeros((30, 40), np.uint8)
    occ[:, 20] = 1
    occ[12:16, 20] = 0  # a door
    return occ


def _obs(cells: list[tuple[int, int]], gas: list[float], wind: list[tuple[float, float]]) -> Observations:
    return Observations(np.array(cells), np.array(gas, float), np.array(wind, float))


def test_a_hit_moves_mass_upwind() -> None:
    occ = _map()
    b = GrGSLEstimator().estimate(occ, 0.1, _obs([(15, 30)], [5.0], [(1.0, 0.0)]))
    p = b.source_probs
    assert p[:, :30].sum() > 5 * p[:, 31:].sum()  # wind blows +x: the source is to the west
    assert p[:, :20].sum() > 0.5  # through the door into the west room
    assert b.info["started"] and b.info["n_updates"] == 1
    # the same hit with the wind blowing north puts the mass south
    s = GrGSLEstimator().estimate(occ, 0.1, _obs([(15, 30)], [5.0], [(0.0, 1.0)])).source_probs
    assert s[:15, 21:].sum() > 3 * s[16:, 21:].sum()


def test_flood_fill_follows_paths() -> None:
    occ = _map()
    free = occ == 0
    w, d = grgsl_weights(free, (5, 25), np.pi, 1.0, True, 5)  # R - C points west: cells east of the robot
    assert np.isfinite(d[free]).all() and np.isinf(d[~free]).all()
    # every cell outside the window inherits the weight of a window cell (the one its path leaves by)
    window = np.zeros_like(free)
    window[0:11, 20:31] = True
    inside = np.unique(w[window & free])
    assert np.isin(w[free & ~window], inside).all()
    assert w[5, 30] > w[5, 21]
    # the west room (behind the wall) is reached through the door, far below the window
    assert d[5, 10] > 20 and w[5, 10] > 0


def test_a_miss_points_to_the_last_hit() -> None:
    occ = np.zeros((20, 40), np.uint8)
    obs = _obs([(10, 10), (10, 20)], [5.0, 0.0], [(0.0, 0.0), (0.0, 0.0)])  # hit without wind, then a miss
    b = GrGSLEstimator().estimate(occ, 0.1, obs)
    p = b.source_probs
    assert b.info["n_updates"] == 1  # the windless hit changes nothing
    assert p[:, :20].sum() > 2 * p[:, 21:].sum()  # back towards the hit at column 10


def test_no_hit_means_no_start() -> None:
    occ = _map()
    b = GrGSLEstimator().estimate(occ, 0.1, _obs([(15, 30), (5, 5)], [0.1, 0.2], [(1.0, 0.0), (1.0, 0.0)]))
    assert not b.info["started"] and "first gas hit" in b.info["note"]
    np.testing.assert_allclose(b.source_probs[occ == 0], 1.0 / (occ == 0).sum())
    strict = GrGSLEstimator(start="first_reading")
    late = _obs([(15, 30), (5, 5)], [0.1, 9.0], [(1.0, 0.0), (1.0, 0.0)])
    assert not strict.estimate(occ, 0.1, late).info["started"]
    assert GrGSLEstimator().estimate(occ, 0.1, late).info["start_index"] == 1


def test_bad_input_is_rejected() -> None:
    occ = _map()
    with pytest.raises(InputDataError, match="no observations"):
        GrGSLEstimator().estimate(occ, 0.1, Observations.empty())
    with pytest.raises(InputDataError, match="wall"):
        GrGSLEstimator().estimate(occ, 0.1, _obs([(0, 20)], [1.0], [(0.0, 0.0)]))
    with pytest.raises(InputDataError):
        GrGSLEstimator(sigma_hit=0.0)
