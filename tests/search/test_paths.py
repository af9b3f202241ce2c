"""Dijkstra on the free cells against a brute-force search; paths, corner cutting, caching."""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.planning.paths import FreeSpaceGraph, graph_for


def _neighbours(occ: np.ndarray, i: int, j: int, connectivity: int):
    H, W = occ.shape
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if (di, dj) == (0, 0) or (connectivity == 4 and di and dj):
                continue
            a, b = i + di, j + dj
            if not (0 <= a < H and 0 <= b < W) or occ[a, b]:
                continue
            if di and dj and (occ[i + di, j] or occ[i, j + dj]):
                continue
            yield (a, b), math.sqrt(di * di + dj * dj)


def _brute(occ: np.ndarray, start: tuple[int, int], connectivity: int, res: float) -> np.ndarray:
    """Textbook heap Dijkstra on the cells."""
    dist = np.full(occ.shape, np.inf)
    dist[start] = 0.0
    heap = [(0.0, start)]
    while heap:
        d, c = heapq.heappop(heap)
        if d > dist[c]:
            continue
        for n, w in _neighbours(occ, *c, connectivity):
            nd = d + w * res
            if nd < dist[n] - 1e-12:
                dist[n] = nd
                heapq.heappush(heap, (nd, n))
    return dist


@pytest.mark.parametrize("connectivity", [8, 4])
@pytest.mark.parametrize("seed", range(4))
def test_dijkstra_matches_brute_force(seed, connectivity):
    rng = np.random.default_rng(seed)
    occ = (rng.uniform(size=(11, 14)) < 0.3).astype(np.uint8)
    res = 0.1 + 0.05 * seed
    g = FreeSpaceGraph(occ, res, connectivity)
    free = np.argwhere(occ == 0)
    for start in free[rng.choice(len(free), 3, replace=False)]:
        s = (int(start[0]), int(start[1]))
        want = _brute(occ, s, connectivity, res)
        got = g.distances_from(s)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        # paths to every reachable cell: free, neighbouring steps, as long as the distance
        for goal in free[rng.choice(len(free), 8, replace=False)]:
            t = (int(goal[0]), int(goal[1]))
            if not np.isfinite(want[t]):
                with pytest.raises(InputDataError, match="cannot be reached"):
                    g.path(s, t)
                continue
            path = g.path(s, t)
            assert path[0] == s and path[-1] == t
            length = 0.0
            for a, b in itertools.pairwise(path):
                steps = dict(_neighbours(occ, *a, connectivity))
                assert b in steps, (a, b)
                length += steps[b] * res
            assert length == pytest.approx(want[t], abs=1e-9)
            assert g.path_length(path) == pytest.approx(length, abs=1e-9)


def test_no_corner_cutting_and_walls():
    occ = np.array([[0, 1], [1, 0]], np.uint8)  # two free cells touching only at a corner
    g = FreeSpaceGraph(occ, 0.1)
    assert g.distance((0, 0), (1, 1)) == math.inf
    assert not g.reachable_from((0, 0))[1, 1]
    open_map = FreeSpaceGraph(np.zeros((2, 2), np.uint8), 0.1)
    assert open_map.distance((0, 0), (1, 1)) == pytest.approx(math.sqrt(2) * 0.1)
    d = g.distances_from((0, 0))
    assert d[0, 1] == math.inf and d[0, 0] == 0.0
    with pytest.raises(InputDataError, match="wall"):
        g.distances_from((0, 1))
    with pytest.raises(InputDataError, match="outside"):
        g.path((0, 0), (5, 5))


def test_graph_cache_by_content():
    occ = np.zeros((5, 6), np.uint8)
    occ[2, 1:5] = 1
    assert graph_for(occ, 0.1) is graph_for(occ.copy(), 0.1)
    assert graph_for(occ, 0.1) is not graph_for(occ, 0.2)
    assert graph_for(occ, 0.1, 4).connectivity == 4
