"""Active search tests; shared fakes: deterministic estimators and tiny cases."""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.belief.knowledge import KnowledgeUser
from dgse.sensing.sensors import Observations
from dgse.world.case import Case


class PeakEstimator(KnowledgeUser):
    """A posterior peaked at the highest gas reading so far: ``exp(-d^2 / (2 s^2))`` with ``s = sigma``.

    Uniform when no reading is above ``threshold`` ppm.  Deterministic; the
    wind and log-concentration variances are 1 everywhere.  With
    ``adaptive``, a crude searcher instead: ``s = max(0.05, 0.5 exp(-g / 20))``
    m shrinks as the highest reading ``g`` (ppm) grows, and the
    log-concentration variance ``1 - exp(-d / 0.3 m)`` grows with the distance
    ``d`` to the nearest measurement (so the utility planner explores).
    """

    name = "peak"

    def __init__(
        self, sigma: float = 0.05, threshold: float = 0.0, sleep: float = 0.0, adaptive: bool = False
    ) -> None:
        self.sigma, self.threshold, self.sleep, self.adaptive = sigma, threshold, sleep, adaptive
        self.calls = 0

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        self.calls += 1
        if self.sleep:
            time.sleep(self.sleep)
        occ = np.asarray(occupancy)
        H, W = occ.shape
        ii, jj = np.mgrid[:H, :W]
        sigma = self.sigma
        if self.adaptive and len(observations):
            sigma = max(0.05, 0.5 * math.exp(-float(observations.gas.max()) / 20.0))
        if len(observations) and observations.gas.max() > self.threshold:
            ci, cj = observations.cells[int(np.argmax(observations.gas))]
            d2 = ((ii - ci) ** 2 + (jj - cj) ** 2) * resolution**2
            p = np.exp(-d2 / (2 * sigma**2)) + 1e-300
        else:
            p = np.ones((H, W))
        ones = np.ones((H, W))
        conc_var = ones
        if self.adaptive and len(observations):
            c = observations.cells
            d = np.hypot(ii[..., None] - c[:, 0], jj[..., None] - c[:, 1]).min(axis=-1) * resolution
            conc_var = 1.0 - np.exp(-d / 0.3)
        return Belief(
            occ,
            resolution,
            normalize_source_probs(p, occ),
            wind_mean=np.zeros((2, H, W)),
            wind_var=np.stack([ones, ones]),
            log_conc_mean=np.zeros((H, W)),
            log_conc_var=conc_var,
            info={"method": self.name, "timings": {"preprocessing": 0.0}},
        )


class UniformEstimator(KnowledgeUser):
    """Always the uniform posterior over the free cells, no fields."""

    name = "uniform"

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        occ = np.asarray(occupancy)
        probs = normalize_source_probs(np.ones(occ.shape), occ)
        return Belief(occ, resolution, probs, info={"method": "uniform"})


@functools.lru_cache(maxsize=1)
def solved_two_rooms() -> Case:
    """``two_rooms()`` of tests.conftest (3 x 2 m) solved: inlet 1 m/s, source (0.55, 0.55) m."""
    from dgse.physics.scenario import solve_cases
    from tests.conftest import two_rooms

    return solve_cases(two_rooms(), 1.0, [((0.55, 0.55), 0.05)])[0]


def corridor_case(
    occupancy: np.ndarray | None = None,
    source_cell: tuple[int, int] = (5, 25),
    resolution: float = 0.1,
    gas: bool = True,
    frames: np.ndarray | None = None,
    frame_dt: float = 1.0,
) -> Case:
    """A hand-made case: concentration ``100 exp(-d / 0.5 m)`` around the source (or none), uniform wind."""
    occ = np.zeros((10, 30), np.uint8) if occupancy is None else np.asarray(occupancy, np.uint8)
    H, W = occ.shape
    free = occ == 0
    ii, jj = np.mgrid[:H, :W]
    d = np.hypot(ii - source_cell[0], jj - source_cell[1]) * resolution
    conc = (100.0 * np.exp(-d / 0.5) if gas else np.zeros((H, W))) * free
    wind = np.stack([np.full((H, W), 0.5), np.zeros((H, W))]) * free
    src = ((source_cell[1] + 0.5) * resolution, (source_cell[0] + 0.5) * resolution)
    meta = {"name": "corridor", "width_m": W * resolution, "height_m": H * resolution}
    if frames is not None:
        meta["frame_dt"] = frame_dt
    return Case(occ, wind, conc, src, resolution, meta, frames)
