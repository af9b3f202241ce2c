"""Candidate openings of a map from a wind field: where air comes in and goes out at the map's edge.

At knowledge level ``map`` (:mod:`dgse.estimators.knowledge`) the inlets and
outlets are unknown, but a wind belief over the whole map (DGSE-S's mean wind,
with the wind readings put in at their cells) says where air crosses the
edge.  :func:`propose_openings` turns that into a few hypotheses:

1. for every side, the outward normal wind of the free edge cells;
2. runs of edge cells that all blow in (or all blow out) by at least
   ``min_fraction`` of the strongest crossing wind on the edge, gaps of up to
   ``max_gap`` cells bridged; each run is scored by its volume flux;
3. the ``max_inlets`` strongest inflow runs and ``max_outlets`` strongest
   outflow runs, widened by ``pad_cells`` on each side, paired into
   :class:`OpeningProposal`\\ s (one inlet and one outlet each), strongest pair
   first; each proposal carries the inflow speed the wind shows there.

A physics estimator then solves the flow of each proposal and lets the wind
and gas readings weigh them (:mod:`dgse.estimators.phys`).  Pure functions of
arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dgse.errors import InputDataError
from dgse.world.layout import Opening

__all__ = ["OpeningProposal", "edge_runs", "propose_openings"]

SIDES = ("west", "east", "south", "north")


@dataclass(frozen=True)
class OpeningProposal:
    """One inlet and one outlet proposed from a wind field.

    Attributes:
        inlets, outlets: the openings (one each).
        inflow_speed: mean inflow speed through the inlet cells, m/s.
        score: the pair's strength (the smaller of the two runs' volume fluxes, m^2/s).
    """

    inlets: tuple[Opening, ...]
    outlets: tuple[Opening, ...]
    inflow_speed: float
    score: float

    def label(self) -> str:
        i, o = self.inlets[0], self.outlets[0]
        return f"in {i.side} {i.start_m:.1f}-{i.end_m:.1f} m, out {o.side} {o.start_m:.1f}-{o.end_m:.1f} m"


def _edge(occupancy: np.ndarray, wind: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """``(free, outward normal wind)`` of the edge cells of ``side``, ordered along it."""
    free = np.asarray(occupancy) == 0
    if side == "west":
        return free[:, 0], -wind[0][:, 0]
    if side == "east":
        return free[:, -1], wind[0][:, -1]
    if side == "south":
        return free[0, :], -wind[1][0, :]
    return free[-1, :], wind[1][-1, :]


def edge_runs(mask: np.ndarray, max_gap: int = 1) -> list[tuple[int, int]]:
    """Runs ``[start, end)`` of consecutive ``mask`` cells, bridging gaps of up to ``max_gap`` cells."""
    idx = np.nonzero(mask)[0]
    if idx.size == 0:
        return []
    runs: list[tuple[int, int]] = []
    start = prev = int(idx[0])
    for i in idx[1:]:
        i = int(i)
        if i - prev > max_gap + 1:
            runs.append((start, prev + 1))
            start = i
        prev = i
    runs.append((start, prev + 1))
    return runs


def propose_openings(
    occupancy: np.ndarray,
    resolution: float,
    wind: np.ndarray,
    *,
    max_inlets: int = 3,
    max_outlets: int = 2,
    min_fraction: float = 0.25,
    max_gap: int = 1,
    pad_cells: int = 1,
) -> list[OpeningProposal]:
    """Inlet/outlet pairs where ``wind`` crosses the map's edge, strongest first (module docstring).

    Raises:
        InputDataError: a wind of the wrong shape, or no air crossing the edge.
    """
    occ = np.asarray(occupancy)
    w = np.asarray(wind, dtype=np.float64)
    if w.shape != (2, *occ.shape):
        raise InputDataError(f"wind has shape {w.shape}; the map needs {(2, *occ.shape)}")
    h = float(resolution)
    edges = {side: _edge(occ, w, side) for side in SIDES}
    strongest = max(float(np.abs(un[free]).max()) if free.any() else 0.0 for free, un in edges.values())
    if not (strongest > 0 and math.isfinite(strongest)):
        raise InputDataError("the wind does not cross the map's edge anywhere: no openings to propose")
    threshold = min_fraction * strongest
    found: dict[str, list[tuple[float, Opening, float]]] = {"in": [], "out": []}
    for side, (free, un) in edges.items():
        n = free.size
        for kind, mask in (("in", free & (un < -threshold)), ("out", free & (un > threshold))):
            for a, b in edge_runs(mask, max_gap):
                sel = np.arange(a, b)
                sel = sel[free[sel]]
                flux = float(np.abs(un[sel]).sum()) * h
                a2, b2 = max(0, a - pad_cells), min(n, b + pad_cells)
                while a2 < a and not free[a2]:
                    a2 += 1
                while b2 > b and not free[b2 - 1]:
                    b2 -= 1
                speed = float(np.abs(un[sel]).mean())
                found[kind].append((flux, Opening(side, a2 * h, b2 * h), speed))
    inlets = sorted(found["in"], key=lambda t: -t[0])[:max_inlets]
    outlets = sorted(found["out"], key=lambda t: -t[0])[:max_outlets]
    proposals = [
        OpeningProposal((oi,), (oo,), si, min(fi, fo))
        for fi, oi, si in inlets
        for fo, oo, _ in outlets
        if oi.side != oo.side or oi.end_m <= oo.start_m or oo.end_m <= oi.start_m
    ]
    if not proposals:
        raise InputDataError("the wind shows no separate inflow and outflow at the map's edge")
    return sorted(proposals, key=lambda p: -p.score)
