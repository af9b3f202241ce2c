"""Tests of the GDM baselines (:mod:`dgse.mapping`); small hand-made maps and readings."""

from __future__ import annotations

import numpy as np

from dgse.sensing.sensors import Observations

RES = 0.1


def channel(height: int = 12, width: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """A wall-free channel and a smooth field (ppm) varying along x only: ``(occupancy, field)``."""
    occ = np.zeros((height, width), np.uint8)
    _, j = np.mgrid[0:height, 0:width]
    x = (j + 0.5) * RES
    return occ, 20.0 + 60.0 * np.exp(-((x - 1.5) ** 2) / (2 * 0.9**2))


def dense_readings(
    occ: np.ndarray, field: np.ndarray, wind: tuple[float, float] = (0.0, 0.5)
) -> Observations:
    """Noiseless gas readings of ``field`` at every free cell, all with the same wind."""
    cells = np.argwhere(occ == 0)
    return Observations(cells, field[cells[:, 0], cells[:, 1]], np.tile(wind, (len(cells), 1)))


def readings(cells, gas, wind=None) -> Observations:
    """Observations at ``cells`` with gas ``gas`` and wind ``wind`` (zeros by default)."""
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    gas = np.array(np.broadcast_to(np.asarray(gas, dtype=np.float64), (len(cells),)))
    w = (
        np.zeros((len(cells), 2))
        if wind is None
        else np.array(np.broadcast_to(np.asarray(wind, float), (len(cells), 2)))
    )
    return Observations(cells, gas, w)


def rel_rmse(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """RMSE over ``mask`` (all cells by default) relative to the range of ``truth``."""
    m = np.ones(truth.shape, bool) if mask is None else mask
    err = np.sqrt(np.mean((estimate[m] - truth[m]) ** 2))
    return float(err / (truth[m].max() - truth[m].min()))
