"""Sensors: placement, measurement of the truth (and frames), clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.sensing.noise import NoiseModel, NoiseParams
from dgse.sensing.sensors import (
    Observations,
    check_sensor_cells,
    mean_free_concentration,
    measure,
    observation_counts,
    random_observation_count,
    random_observations,
    random_sensor_cells,
)
from dgse.world.case import Case
from tests.conftest import two_rooms


def synthetic_case(width: int = 30, height: int = 20, frames: int = 0) -> Case:
    """A solver-free case on the ``two_rooms`` map: smooth wind, a Gaussian plume.

    The source is at cell ``(height // 2, 5)``; fields are 0 in solid cells;
    with ``frames`` > 0 adds ``frames`` scaled copies of the concentration
    (frame ``n`` is ``(n + 1) x`` the steady field), ``frame_dt = 2 s``.
    """
    layout = two_rooms(width, height)
    g = layout.grid
    X, Y = g.meshgrid()
    free = layout.free
    wind = np.stack([1.0 + 0.1 * Y, 0.3 * np.sin(X)]) * free
    si, sj = height // 2, 5
    sx, sy = g.center_of(si, sj)
    conc = 50.0 * np.exp(-((X - sx) ** 2 + (Y - sy) ** 2) / 0.5) * free
    meta = {**layout.meta(), "name": "synthetic", "inlet_velocity": 1.0, "release_rate_gps": 1.0}
    fr = None
    if frames:
        fr = np.stack([(n + 1) * conc for n in range(frames)])
        meta["frame_dt"] = 2.0
    return Case(layout.occupancy, wind, conc, (sx, sy), g.resolution, meta, fr)


@pytest.fixture
def case() -> Case:
    return synthetic_case()


def test_observation_counts_are_the_papers():
    counts = observation_counts()
    assert counts == tuple(range(5, 301, 5))
    assert len(counts) == 60 and counts[0] == 5 and counts[-1] == 300
    rng = np.random.default_rng(0)
    drawn = {random_observation_count(rng) for _ in range(2000)}
    assert drawn == set(counts)


def test_random_sensor_cells_are_distinct_free_cells(case):
    rng = np.random.default_rng(0)
    free = case.free
    cells = random_sensor_cells(free, 300, rng)
    assert cells.shape == (300, 2) and cells.dtype == np.int64
    assert np.all(free[cells[:, 0], cells[:, 1]])
    assert len({tuple(c) for c in cells}) == 300
    all_free = random_sensor_cells(free, int(free.sum()), rng)
    assert len({tuple(c) for c in all_free}) == free.sum()
    assert random_sensor_cells(free, 0, rng).shape == (0, 2)


def test_random_sensor_cells_are_uniform():
    mask = np.zeros((3, 4), dtype=bool)
    mask[[0, 1, 2, 2, 0, 1], [0, 1, 2, 3, 3, 0]] = True
    rng = np.random.default_rng(1)
    hits = np.zeros(mask.shape)
    for _ in range(6000):
        c = random_sensor_cells(mask, 2, rng)
        hits[c[:, 0], c[:, 1]] += 1
    assert hits[~mask].sum() == 0
    np.testing.assert_allclose(hits[mask] / 6000, 2 / 6, atol=0.02)


def test_too_many_sensors_is_a_clear_error(case):
    nfree = int(case.free.sum())
    with pytest.raises(InputDataError, match=f"only {nfree} free cells"):
        random_sensor_cells(case.free, nfree + 1, np.random.default_rng(0))


def test_noiseless_measurement_reads_the_truth(case):
    cells = np.array([[10, 5], [3, 20], [19, 29]])
    obs = measure(case, cells, NoiseParams.zero(), np.random.default_rng(0))
    np.testing.assert_array_equal(obs.cells, cells)
    np.testing.assert_allclose(obs.gas, case.concentration[cells[:, 0], cells[:, 1]])
    np.testing.assert_allclose(obs.wind, case.wind[:, cells[:, 0], cells[:, 1]].T, atol=1e-6)
    assert obs.times is None and obs.noise == NoiseParams.zero()


def test_sensor_in_a_wall_is_rejected_naming_the_cell(case):
    wall = (0, 15)  # the dividing wall of two_rooms, away from the door
    assert case.occupancy[wall] == 1
    with pytest.raises(InputDataError, match=r"sensor cell \(0, 15\) lies in a wall"):
        measure(case, np.array([[2, 2], wall]), NoiseParams.zero(), np.random.default_rng(0))


@pytest.mark.parametrize("cell", [(20, 3), (-1, 0), (4, 30)])
def test_sensor_outside_the_map_is_rejected_naming_the_cell(case, cell):
    with pytest.raises(InputDataError, match=rf"sensor cell \({cell[0]}, {cell[1]}\) lies outside"):
        measure(case, np.array([cell]), NoiseParams.zero(), np.random.default_rng(0))


def test_non_integer_cells_are_rejected(case):
    with pytest.raises(InputDataError, match="integer"):
        check_sensor_cells(case.occupancy, np.array([[1.5, 2.0]]))


def test_measurement_reads_frames_at_time_t():
    case = synthetic_case(frames=3)  # frame_dt = 2 s, frame n = (n + 1) x steady
    cell = np.array([[10, 6]])
    c0 = case.concentration[10, 6]
    z = NoiseParams.zero()
    rng = np.random.default_rng(0)
    for t, factor in ((0.0, 1), (1.9, 1), (2.0, 2), (5.5, 3), (6.0, 1), (13.0, 1), (15.0, 2)):
        obs = measure(case, cell, z, rng, t=t)
        assert obs.gas[0] == pytest.approx(factor * c0, rel=1e-6), t
        assert obs.times is not None and obs.times[0] == t
    # per-observation times; the steady field without t
    obs = measure(case, np.array([[10, 6], [10, 6]]), z, rng, t=np.array([0.5, 4.5]))
    np.testing.assert_allclose(obs.gas, [c0, 3 * c0], rtol=1e-6)
    assert measure(case, cell, z, rng).gas[0] == pytest.approx(c0)


def test_times_without_frames_read_the_steady_field(case):
    obs = measure(case, np.array([[10, 6]]), NoiseParams.zero(), np.random.default_rng(0), t=7.0)
    assert obs.gas[0] == pytest.approx(case.concentration[10, 6])
    np.testing.assert_array_equal(obs.times, [7.0])


def test_random_observations_are_seeded_and_noisy(case):
    a = random_observations(case, 40, np.random.default_rng(3))
    b = random_observations(case, 40, np.random.default_rng(3))
    c = random_observations(case, 40, np.random.default_rng(4))
    assert len(a) == 40
    for f in ("cells", "gas", "wind"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert not np.array_equal(a.cells, c.cells)
    assert a.noise == b.noise and a.noise is not None
    assert a.noise.sigma_env <= 0.5 * mean_free_concentration(case)
    truth = case.concentration[a.cells[:, 0], a.cells[:, 1]]
    assert not np.allclose(a.gas, truth)  # noise was applied ...
    clean = random_observations(case, 40, np.random.default_rng(3), NoiseModel.noiseless())
    np.testing.assert_allclose(  # ... and the noiseless model reads the truth
        clean.gas, case.concentration[clean.cells[:, 0], clean.cells[:, 1]]
    )
    assert case.concentration.max() == pytest.approx(50.0, rel=0.05)  # the case is untouched


def test_observations_validate_and_combine():
    o = Observations(np.array([[1, 2], [3, 4]]), [1.0, 2.0], [[0.1, 0.2], [0.3, 0.4]], [0.0, 1.0])
    assert len(o) == 2
    np.testing.assert_allclose(o.positions(0.1), [[0.25, 0.15], [0.45, 0.35]])
    both = o.concat(o.take(1))
    assert len(both) == 3 and both.cells[2].tolist() == [3, 4]
    np.testing.assert_array_equal(both.times, [0.0, 1.0, 1.0])
    assert len(Observations.empty().concat(o)) == 2
    with pytest.raises(InputDataError, match="gas readings"):
        Observations(np.array([[1, 2]]), [1.0, 2.0], [[0.0, 0.0]])
    with pytest.raises(InputDataError, match="wind readings"):
        Observations(np.array([[1, 2]]), [1.0], [0.0, 0.0, 0.0])
