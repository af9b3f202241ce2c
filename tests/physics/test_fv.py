"""Finite-volume kernels: Gauss-Seidel's two arithmetics solve the same system."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from dgse.physics.fv import StencilMatrix, build_mesh, gauss_seidel
from tests.conftest import two_rooms


@pytest.mark.parametrize("m", [1, 2])
def test_gauss_seidel_arithmetics_agree_and_solve_the_system(m):
    mesh = build_mesh(two_rooms(30, 20))
    rng = np.random.default_rng(0)
    a = np.where(mesh.nb >= 0, rng.uniform(0.5, 1.5, (mesh.n, 4)), 0.0)
    aP = a.sum(axis=1) * 1.05 + 0.01  # diagonally dominant, like a relaxed transport equation
    b = rng.normal(size=(mesh.n, m))
    exact = spla.spsolve(StencilMatrix(mesh).assemble(aP, a).tocsc(), b).reshape(mesh.n, m)
    out = []
    for short in (False, True):
        x = np.zeros((mesh.n, m))
        sweeps, initial = gauss_seidel(aP, a, b, mesh.nb, x, 1e-12, 5000, short)
        assert 0 < sweeps < 5000 and initial.shape == (m,)
        out.append(x)
        assert np.abs(x - exact).max() < 1e-8 * np.abs(exact).max()
    # the same sweeps up to rounding: equal after one sweep to the last bits
    one = []
    for short in (False, True):
        x = np.zeros((mesh.n, m))
        gauss_seidel(aP, a, b, mesh.nb, x, 0.0, 1, short)
        one.append(x)
    np.testing.assert_allclose(one[0], one[1], rtol=1e-12, atol=1e-14)
