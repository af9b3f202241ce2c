"""Dijkstra's expansion over the 8-connected free cells of a map, compiled (numba).

GrGSL's and PMFS's floods both grow path distances from seed cells through free cells
(unit or ``res`` steps, ``sqrt 2`` of that on the diagonals) and differ only in what a
cell passes on to a neighbour; :func:`expansions` is the loop they share.
"""

from __future__ import annotations

import heapq

import numba as nb

__all__ = ["expansions"]


# not cached: numba cannot link a generator loaded from its cache into a caller it compiles
# afresh (the caller's cache outdated by an edit), so it is compiled with each caller
@nb.njit
def expansions(heap, done, free, step):  # pragma: no cover - numba
    """Settle cells in order of distance and yield each open neighbour of a settled cell.

    Args:
        heap: a ``heapq`` list of ``(distance, i * W + j)``; the caller pushes the
            neighbours it improves while iterating.
        done: ``bool (H, W)``, the settled cells (updated: a popped cell is marked).
        free: ``bool (H, W)``, true on free cells.
        step: length of an axis step (a diagonal one is ``sqrt 2`` of it).

    Yields:
        ``(i, j, ni, nj, nd)``: the settled cell, a free unsettled neighbour (in row-major
        order of the offsets) and its distance through ``(i, j)``.
    """
    H, W = free.shape
    while len(heap) > 0:
        d, idx = heapq.heappop(heap)
        i = idx // W
        j = idx % W
        if done[i, j]:
            continue
        done[i, j] = True
        for di in range(-1, 2):
            for dj in range(-1, 2):
                if di == 0 and dj == 0:
                    continue
                ni = i + di
                nj = j + dj
                if ni < 0 or ni >= H or nj < 0 or nj >= W or not free[ni, nj] or done[ni, nj]:
                    continue
                yield i, j, ni, nj, d + step * (1.4142135623730951 if di != 0 and dj != 0 else 1.0)
