"""Shortest obstacle-free paths on a map's free cells (Dijkstra).

The robot moves between the centres of free cells of the ``(H, W)`` map
(spec section 1: cell ``(i, j)`` has its centre at ``x = (j + 0.5) * res``,
``y = (i + 0.5) * res``).  :class:`FreeSpaceGraph` is the graph of those
moves, built once per map (:func:`graph_for` caches it), with lengths in
metres:

* ``connectivity=8`` (the default): the four axis moves cost ``res``, the four
  diagonal moves ``sqrt(2) * res``.  A diagonal move is allowed only when both
  cells it passes between are free too (no corner cutting: a robot never
  grazes a wall corner or squeezes through a one-cell diagonal gap);
* ``connectivity=4``: axis moves only.

Distances from one cell to every cell come from
:func:`scipy.sparse.csgraph.dijkstra` (walls and cells not connected to the
start are ``inf``); the last few single-source results are cached, so asking
for the distances from the robot's cell and then for the path to the chosen
goal runs Dijkstra once.  Paths are rebuilt from Dijkstra's predecessors.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from collections.abc import Sequence

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from dgse.errors import InputDataError

__all__ = ["FreeSpaceGraph", "clear_graph_cache", "graph_for"]

Cell = tuple[int, int]

#: Single-source results kept per graph (distances + predecessors, 12 bytes a cell each).
_SOURCE_CACHE = 8
#: Graphs kept by :func:`graph_for`.
_GRAPH_CACHE = 16

_AXIS_STEPS = ((0, 1), (1, 0))
_DIAG_STEPS = ((1, 1), (1, -1))


class FreeSpaceGraph:
    """The move graph of a map's free cells, with path lengths in metres.

    Args:
        occupancy: ``(H, W)`` map, nonzero = solid.
        resolution: cell size in m.
        connectivity: 8 (axis and diagonal moves, no corner cutting) or 4.

    Example:
        >>> occ = np.zeros((3, 4), np.uint8); occ[:2, 1] = 1
        >>> g = FreeSpaceGraph(occ, 0.1)
        >>> round(g.distance((0, 0), (0, 2)), 4)   # around the wall; no diagonal past its end
        0.6
        >>> g.path((0, 0), (0, 2))
        [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (1, 2), (0, 2)]
    """

    def __init__(self, occupancy: np.ndarray, resolution: float, connectivity: int = 8) -> None:
        occ = np.asarray(occupancy)
        if occ.ndim != 2 or min(occ.shape) < 1:
            raise InputDataError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
        if connectivity not in (4, 8):
            raise InputDataError(f"connectivity must be 4 or 8, got {connectivity}")
        res = float(resolution)
        if not (res > 0 and math.isfinite(res)):
            raise InputDataError(f"resolution must be positive, got {resolution}")
        self.occupancy: np.ndarray = (occ != 0).astype(np.uint8)
        self.occupancy.setflags(write=False)
        self.resolution = res
        self.connectivity = int(connectivity)
        self.shape: tuple[int, int] = (int(occ.shape[0]), int(occ.shape[1]))
        free = self.occupancy == 0
        self.free: np.ndarray = free
        self.free.setflags(write=False)
        H, W = self.shape
        #: flat map index -> node index (-1 on solid cells)
        self.node_of = np.full(H * W, -1, np.int64)
        flat_free = np.flatnonzero(free)
        self.node_of[flat_free] = np.arange(flat_free.size)
        #: node index -> flat map index
        self.flat_of = flat_free
        self.n_nodes = int(flat_free.size)
        self.matrix = self._build(free)
        self._cache: OrderedDict[int, tuple[np.ndarray, np.ndarray]] = OrderedDict()

    def _build(self, free: np.ndarray) -> sparse.csr_matrix:
        H, W = self.shape
        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []
        vals: list[np.ndarray] = []
        steps = list(_AXIS_STEPS) + (list(_DIAG_STEPS) if self.connectivity == 8 else [])
        ii, jj = np.nonzero(free)
        for di, dj in steps:
            ni, nj = ii + di, jj + dj
            ok = (ni >= 0) & (ni < H) & (nj >= 0) & (nj < W)
            a_i, a_j, b_i, b_j = ii[ok], jj[ok], ni[ok], nj[ok]
            ok = free[b_i, b_j]
            if di and dj:  # no corner cutting: both cells beside the diagonal must be free
                ok &= free[a_i + di, a_j] & free[a_i, a_j + dj]
            a = self.node_of[a_i[ok] * W + a_j[ok]]
            b = self.node_of[b_i[ok] * W + b_j[ok]]
            length = self.resolution * (math.sqrt(2.0) if di and dj else 1.0)
            rows += [a, b]
            cols += [b, a]
            vals += [np.full(a.size, length), np.full(a.size, length)]
        n = self.n_nodes
        if rows:
            data, r, c = np.concatenate(vals), np.concatenate(rows), np.concatenate(cols)
        else:
            data, r, c = np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)
        return sparse.csr_matrix((data, (r, c)), shape=(n, n))

    # -- cells ---------------------------------------------------------------------------
    def check_cell(self, cell: Sequence[int] | np.ndarray, what: str = "cell") -> Cell:
        """``cell`` as an ``(i, j)`` tuple of ints.

        Raises:
            InputDataError: ``cell`` off the map or in a wall (``what`` names it in the message).
        """
        try:
            i, j = (int(cell[0]), int(cell[1]))
        except (TypeError, ValueError, IndexError) as e:
            raise InputDataError(f"{what} must be an (i, j) pair of ints, got {cell!r}") from e
        H, W = self.shape
        if not (0 <= i < H and 0 <= j < W):
            raise InputDataError(f"{what} ({i}, {j}) lies outside the map ({H} x {W} cells)")
        if not self.free[i, j]:
            raise InputDataError(f"{what} ({i}, {j}) lies in a wall (solid cell)")
        return (i, j)

    def _node(self, cell: Sequence[int] | np.ndarray, what: str = "cell") -> int:
        i, j = self.check_cell(cell, what)
        return int(self.node_of[i * self.shape[1] + j])

    # -- Dijkstra ------------------------------------------------------------------------
    def _single_source(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        hit = self._cache.get(node)
        if hit is not None:
            self._cache.move_to_end(node)
            return hit
        dist, pred = dijkstra(self.matrix, directed=True, indices=node, return_predecessors=True)
        dist.setflags(write=False)
        pred.setflags(write=False)
        self._cache[node] = (dist, pred)
        while len(self._cache) > _SOURCE_CACHE:
            self._cache.popitem(last=False)
        return dist, pred

    def distances_from(self, cell: Sequence[int] | np.ndarray) -> np.ndarray:
        """``float64 (H, W)`` shortest path length in m from ``cell`` to every cell.

        ``inf`` on solid cells and on free cells not connected to ``cell``; 0 at ``cell``.
        A new array each call (safe to modify).
        """
        dist, _ = self._single_source(self._node(cell, "start cell"))
        out = np.full(self.shape[0] * self.shape[1], np.inf)
        out[self.flat_of] = dist
        return out.reshape(self.shape)

    def distance(self, start: Sequence[int] | np.ndarray, goal: Sequence[int] | np.ndarray) -> float:
        """Shortest path length in m from ``start`` to ``goal`` (``inf`` when not connected)."""
        dist, _ = self._single_source(self._node(start, "start cell"))
        return float(dist[self._node(goal, "goal cell")])

    def path(self, start: Sequence[int] | np.ndarray, goal: Sequence[int] | np.ndarray) -> list[Cell]:
        """The cells of a shortest path from ``start`` to ``goal``, both included.

        Consecutive cells are neighbours of the graph (never a wall, never a
        cut corner).  ``[start]`` when ``goal == start``.

        Raises:
            InputDataError: ``start`` or ``goal`` off the map or in a wall, or
                ``goal`` not reachable from ``start``.
        """
        s = self._node(start, "start cell")
        g = self._node(goal, "goal cell")
        dist, pred = self._single_source(s)
        if not np.isfinite(dist[g]):
            gi, gj = self.check_cell(goal)
            si, sj = self.check_cell(start)
            raise InputDataError(f"goal cell ({gi}, {gj}) cannot be reached from ({si}, {sj})")
        nodes = [g]
        while nodes[-1] != s:
            nodes.append(int(pred[nodes[-1]]))
        W = self.shape[1]
        return [(int(self.flat_of[n] // W), int(self.flat_of[n] % W)) for n in reversed(nodes)]

    def path_length(self, cells: Sequence[Sequence[int]] | np.ndarray) -> float:
        """Length in m of a polyline through cell centres (sum of the centre-to-centre steps)."""
        c = np.asarray(cells, dtype=np.float64).reshape(-1, 2)
        if len(c) < 2:
            return 0.0
        return float(np.hypot(*np.diff(c, axis=0).T).sum() * self.resolution)

    def reachable_from(self, cell: Sequence[int] | np.ndarray) -> np.ndarray:
        """``bool (H, W)``: the free cells connected to ``cell`` (``cell`` included)."""
        return np.isfinite(self.distances_from(cell))


_GRAPHS: OrderedDict[tuple[str, tuple[int, int], float, int], FreeSpaceGraph] = OrderedDict()


def graph_for(occupancy: np.ndarray, resolution: float, connectivity: int = 8) -> FreeSpaceGraph:
    """The (cached) :class:`FreeSpaceGraph` of a map.

    Graphs are cached by the map's content (a hash of the occupancy), shape,
    resolution and connectivity; the last 16 are kept.
    """
    occ = (np.asarray(occupancy) != 0).astype(np.uint8)
    if occ.ndim != 2:
        raise InputDataError(f"occupancy must be 2-D, got shape {occ.shape}")
    key = (
        hashlib.blake2b(np.ascontiguousarray(occ).tobytes(), digest_size=16).hexdigest(),
        (int(occ.shape[0]), int(occ.shape[1])),
        float(resolution),
        int(connectivity),
    )
    g = _GRAPHS.get(key)
    if g is None:
        g = FreeSpaceGraph(occ, resolution, connectivity)
        _GRAPHS[key] = g
        while len(_GRAPHS) > _GRAPH_CACHE:
            _GRAPHS.popitem(last=False)
    else:
        _GRAPHS.move_to_end(key)
    return g


def clear_graph_cache() -> None:
    """Forget the graphs cached by :func:`graph_for`."""
    _GRAPHS.clear()
