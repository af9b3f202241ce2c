"""Integer refinement of a map onto finer cells and back (``dgse.world.grid``)."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.world.grid import Grid, coarsen, refine_cells, refine_occupancy, refinement_factor


def test_refinement_factor_is_a_whole_multiple_or_none():
    assert refinement_factor(0.2, 0.1) == 2
    assert refinement_factor(0.1, 0.1) == 1
    assert refinement_factor(0.30000001, 0.1) == 3
    assert refinement_factor(0.15, 0.1) is None
    assert refinement_factor(0.05, 0.1) is None


@pytest.mark.parametrize("factor", [2, 3])
def test_refined_map_keeps_every_cell_and_its_centre(factor):
    occ = np.array([[0, 1, 0], [0, 0, 1]], np.uint8)
    fine = refine_occupancy(occ, factor)
    assert fine.shape == (2 * factor, 3 * factor) and fine.dtype == occ.dtype
    assert np.array_equal(coarsen(fine, factor, "mean"), occ)
    cells = np.array([[0, 0], [1, 2], [0, 2]])
    fcells = refine_cells(cells, factor)
    assert np.array_equal(fcells // factor, cells)  # inside its own block
    coarse_grid, fine_grid = Grid((2, 3), 0.2), Grid((2 * factor, 3 * factor), 0.2 / factor)
    # at most half a fine cell from the coarse cell's centre (at the centre for odd factors)
    off = np.abs(fine_grid.centers_of(fcells) - coarse_grid.centers_of(cells)).max()
    assert off <= 0.5 * 0.2 / factor + 1e-12 and (factor % 2 == 0 or off < 1e-12)


def test_coarsen_sums_and_means_blocks_and_refuses_ragged_fields():
    a = np.arange(2 * 4 * 6, dtype=float).reshape(2, 4, 6)
    s = coarsen(a, 2, "sum")
    assert s.shape == (2, 2, 3) and s[0, 0, 0] == 0 + 1 + 6 + 7
    assert np.array_equal(coarsen(a, 2, "mean"), s / 4)
    assert coarsen(a, 2, "sum").sum() == a.sum()
    with pytest.raises(InputDataError, match="blocks"):
        coarsen(a, 4)
    with pytest.raises(ValueError, match="block reduction"):
        coarsen(a, 2, "max")
