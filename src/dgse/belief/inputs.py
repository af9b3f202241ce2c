"""What every estimator checks of its inputs: the map, the cell size and the readings."""

from __future__ import annotations

import hashlib
import math

import numpy as np

from dgse.errors import InputDataError
from dgse.sensing.sensors import Observations, check_sensor_cells

__all__ = ["check_inputs", "map_key"]


def check_inputs(
    occupancy: np.ndarray, resolution: float, observations: Observations, *, allow_empty: bool = False
) -> tuple[np.ndarray, float, Observations]:
    """Validated ``(occupancy uint8 (H, W), resolution, observations)`` with gas clipped at 0.

    Raises:
        InputDataError: a map that is not 2-D or has no free cell, a bad
            resolution, something other than :class:`Observations`, no readings
            (unless ``allow_empty``), a reading outside the map or in a wall.
    """
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or min(occ.shape) < 1:
        raise InputDataError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
    occ = (occ != 0).astype(np.uint8)
    if not (occ == 0).any():
        raise InputDataError("the map has no free cell")
    res = float(resolution)
    if not (res > 0 and math.isfinite(res)):
        raise InputDataError(f"resolution must be a positive number of metres, got {resolution}")
    if not isinstance(observations, Observations):
        raise InputDataError(
            f"observations must be an Observations object, got {type(observations).__name__}"
        )
    if len(observations) == 0 and not allow_empty:
        raise InputDataError("no observations: source localization needs at least one reading")
    check_sensor_cells(occ, observations.cells)
    if (observations.gas < 0).any():
        observations = Observations(
            observations.cells,
            np.maximum(observations.gas, 0.0),
            observations.wind,
            observations.times,
            observations.noise,
        )
    return occ, res, observations


def map_key(occupancy: np.ndarray, resolution: float) -> str:
    """A short content hash of a map and its cell size (cache key)."""
    occ = np.ascontiguousarray((np.asarray(occupancy) != 0).astype(np.uint8))
    h = hashlib.blake2b(occ.tobytes(), digest_size=12)
    h.update(repr((occ.shape, float(resolution))).encode())
    return h.hexdigest()
