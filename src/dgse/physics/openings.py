"""Candidate openings of a map from a wind field: where air comes in and goes out at the map's edge.

At knowledge level ``map`` (:mod:`dgse.belief.knowledge`) the inlets and
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

__all__ = [
    "OpeningProposal",
    "edge_runs",
    "potential_flow_proposals",
    "propose_openings",
]

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


# -- proposals from the wind readings alone: potential flow between edge windows ---------------------
def _edge_windows(
    occupancy: np.ndarray, resolution: float, window_m: float, stride_m: float
) -> list[Opening]:
    """Windows of ``window_m`` along every side's free edge cells, every ``stride_m``."""
    occ = np.asarray(occupancy)
    h = float(resolution)
    n_win = max(1, round(window_m / h))
    step = max(1, round(stride_m / h))
    out: list[Opening] = []
    for side in SIDES:
        free, _ = _edge(occ, np.zeros((2, *occ.shape)), side)
        for a, b in edge_runs(free, max_gap=0):
            if b - a <= n_win:
                out.append(Opening(side, a * h, b * h))
                continue
            starts = list(range(a, b - n_win + 1, step))
            if starts[-1] != b - n_win:
                starts.append(b - n_win)
            out.extend(Opening(side, s * h, (s + n_win) * h) for s in starts)
    return out


def _window_cells(opening: Opening, shape: tuple[int, int], resolution: float) -> np.ndarray:
    from dgse.world.grid import Grid

    rows, cols = opening.cells(Grid(shape, resolution))
    return np.stack([rows, cols], axis=1)


def potential_flow_proposals(
    occupancy: np.ndarray,
    resolution: float,
    cells: np.ndarray,
    wind: np.ndarray,
    *,
    window_m: float = 1.0,
    stride_m: float = 0.5,
    top: int = 5,
) -> list[OpeningProposal]:
    """Inlet/outlet windows whose potential flow best explains the wind readings, best first.

    Every pair of edge windows (``window_m`` wide, every ``stride_m``) is a
    hypothesis: the irrotational flow entering through one and leaving through
    the other (a Laplace problem on the free cells with walls closed).  By
    linearity it is the difference of two responses to unit inflow through a
    window (and outflow through a fixed reference window), so one
    factorization and one solve per window serve every pair.  Each pair is
    fitted to the wind readings ``wind`` (``(m, 2)`` m/s at ``cells``) with a
    free positive scale; pairs are ranked by the residual.  Potential flow
    has no jets or recirculation, so this ranks where air enters and leaves,
    not the flow itself; the physics estimator solves RANS for the best pairs.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    occ = np.asarray(occupancy)
    free = occ == 0
    H, W = occ.shape
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    w = np.asarray(wind, dtype=np.float64).reshape(-1, 2)
    if c.shape[0] != w.shape[0] or c.shape[0] == 0:
        raise InputDataError(f"{c.shape[0]} reading cells but {w.shape[0]} wind readings")
    idx = np.full(occ.shape, -1, dtype=np.int64)
    ii, jj = np.nonzero(free)
    n = ii.size
    idx[ii, jj] = np.arange(n)
    rows, cols, vals = [], [], []
    deg = np.zeros(n)
    for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        ni, nj = ii + di, jj + dj
        ok = (ni >= 0) & (ni < H) & (nj >= 0) & (nj < W)
        nb = np.full(n, -1)
        nb[ok] = idx[ni[ok], nj[ok]]
        m = nb >= 0
        rows.append(np.nonzero(m)[0])
        cols.append(nb[m])
        vals.append(-np.ones(int(m.sum())))
        deg += m
    L = sp.csr_matrix(
        (
            np.concatenate([deg, *vals]),
            (np.concatenate([np.arange(n), *rows]), np.concatenate([np.arange(n), *cols])),
        ),
        shape=(n, n),
    ).tolil()
    windows = _edge_windows(occ, resolution, window_m, stride_m)
    if len(windows) < 2:
        raise InputDataError("the map's edge has fewer than two free windows: no openings to propose")
    # unit inflow through window k, the same outflow through window 0 (the reference); phi pinned at one cell
    pin = int(idx[tuple(_window_cells(windows[0], occ.shape, resolution)[0])])
    L[pin, :] = 0.0
    L[pin, pin] = 1.0
    lu = spla.splu(L.tocsc())
    B = np.zeros((n, len(windows)))
    for k, o in enumerate(windows):
        wc = _window_cells(o, occ.shape, resolution)
        B[idx[wc[:, 0], wc[:, 1]], k] += 1.0 / len(wc)
    ref = B[:, 0].copy()
    B -= ref[:, None]
    B[pin, :] = 0.0
    phi = lu.solve(B)  # (n, K): potential of "in through k, out through the reference"
    # velocity -grad(phi) at the reading cells (central differences over free neighbours)
    grid_phi = np.zeros((H, W, len(windows)))
    grid_phi[ii, jj] = phi

    def neighbour(di: int, dj: int) -> tuple[np.ndarray, np.ndarray]:
        ni, nj = np.clip(c[:, 0] + di, 0, H - 1), np.clip(c[:, 1] + dj, 0, W - 1)
        ok = free[ni, nj] & (ni == c[:, 0] + di) & (nj == c[:, 1] + dj)
        val = np.where(ok[:, None], grid_phi[ni, nj], grid_phi[c[:, 0], c[:, 1]])
        return val, ok

    e, eo = neighbour(0, 1)
    wv, wo = neighbour(0, -1)
    nn, no = neighbour(1, 0)
    s, so = neighbour(-1, 0)
    gx = (e - wv) / np.maximum(eo.astype(float) + wo, 1.0)[:, None]
    gy = (nn - s) / np.maximum(no.astype(float) + so, 1.0)[:, None]
    U = -np.stack([gx, gy], axis=1)  # (m, 2, K)
    # pair (i, o): in through i, out through o = response_i - response_o
    K = len(windows)
    uu = np.einsum("mdk,mdl->kl", U, U)  # <U_k, U_l>
    uw = np.einsum("mdk,md->k", U, w)
    ww = float((w * w).sum())
    diag = np.diag(uu)
    norm2 = diag[:, None] + diag[None, :] - 2.0 * uu  # |U_i - U_o|^2
    cross = uw[:, None] - uw[None, :]  # <U_i - U_o, w>
    scale = np.where(norm2 > 0, np.maximum(cross, 0.0) / np.where(norm2 > 0, norm2, 1.0), 0.0)
    resid = ww - scale * cross
    np.fill_diagonal(resid, np.inf)
    order = np.argsort(resid, axis=None)
    out: list[OpeningProposal] = []
    used: set[tuple[int, int]] = set()
    for flat in order:
        i, o = divmod(int(flat), K)
        if not np.isfinite(resid[i, o]) or (i, o) in used:
            continue
        oi, oo = windows[i], windows[o]
        if oi.side == oo.side and not (oi.end_m <= oo.start_m or oo.end_m <= oi.start_m):
            continue  # overlapping windows
        # skip pairs that are near-duplicates (both windows overlapping a kept pair's)
        if any(_overlap(oi, p.inlets[0]) and _overlap(oo, p.outlets[0]) for p in out):
            continue
        used.add((i, o))
        speed = float(scale[i, o]) / (len(_window_cells(oi, occ.shape, resolution)) * resolution)
        out.append(OpeningProposal((oi,), (oo,), speed, float(-resid[i, o])))
        if len(out) >= top:
            break
    return out


def _overlap(a: Opening, b: Opening) -> bool:
    return a.side == b.side and a.start_m < b.end_m and b.start_m < a.end_m
