"""Tests of the source localization baselines; small shared scenarios."""

from __future__ import annotations

import functools

import numpy as np

from dgse.physics.scenario import solve_cases
from dgse.sensing.sensors import Observations
from dgse.world.case import Case
from dgse.world.layout import Layout, Opening


def channel_layout(height: int = 16, width: int = 36) -> Layout:
    """A straight channel: inlet over the west side's middle, outlet over the east side's middle."""
    occ = np.zeros((height, width), dtype=np.uint8)
    h = 0.1
    return Layout(
        occ,
        (Opening("west", 0.25 * height * h, 0.75 * height * h),),
        (Opening("east", 0.25 * height * h, 0.75 * height * h),),
        name="channel",
    )


@functools.cache
def channel_case(speed: float = 1.0) -> Case:
    """The channel solved by the built-in solver with a 0.2 g/s source at (0.85 m, 0.85 m), cell (8, 8)."""
    return solve_cases(channel_layout(), speed, [((0.85, 0.85), 0.2)])[0]


def dense_readings(case: Case, n: int, seed: int = 0) -> Observations:
    """Noiseless readings (the case's steady gas and wind) at ``n`` random free cells."""
    free = np.argwhere(case.occupancy == 0)
    rng = np.random.default_rng(seed)
    cells = free[rng.choice(len(free), size=n, replace=False)]
    return Observations(
        cells,
        case.concentration[cells[:, 0], cells[:, 1]].astype(np.float64),
        case.wind[:, cells[:, 0], cells[:, 1]].T.astype(np.float64),
    )


def cell_distance(a: tuple[int, int], b: tuple[int, int]) -> float:
    """Euclidean distance between two cells, in cells."""
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))
