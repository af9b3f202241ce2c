"""Finite-volume kernels: Gauss-Seidel's two arithmetics solve the same system; the one-pass
kernels that replaced NumPy expressions give the same values to the bit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from dgse.physics.fv import INLET, WALL, StencilMatrix, boundary_gamma, build_mesh, gauss_seidel, pin_cells
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


def test_one_pass_kernels_equal_the_numpy_expressions_they_replaced():
    mesh = build_mesh(two_rooms(30, 20))
    rng = np.random.default_rng(1)
    n = mesh.n
    wall, inlet = mesh.ft == WALL, mesh.ft == INLET
    assert wall.any() and inlet.any()
    gamma, gamma_wall = rng.uniform(1e-5, 1e-2, n), rng.uniform(1e-5, 1e-2, n)
    expected = np.where(wall, gamma_wall[:, None], np.where(inlet, 0.37, gamma[:, None]))
    assert np.array_equal(boundary_gamma(gamma, inlet, 0.37, wall, gamma_wall), expected)
    none = np.zeros((n, 4), dtype=bool)
    no_wall = boundary_gamma(gamma, inlet, 0.37, none, gamma)
    assert np.array_equal(no_wall, np.where(inlet, 0.37, gamma[:, None]))

    cells = wall.any(axis=1)
    aP, a, b, value = rng.uniform(1, 2, n), rng.uniform(0, 1, (n, 4)), rng.normal(size=n), rng.normal(size=n)
    want = (np.where(cells, 1.0, aP), np.where(cells[:, None], 0.0, a), np.where(cells, value, b))
    pin_cells(cells, aP, a, b, value)
    for got, w in zip((aP, a, b), want, strict=True):
        assert np.array_equal(got, w)

    # the pressure matrix: aP on the diagonal, -a towards each neighbour, as a dense build gives
    A = StencilMatrix(mesh).assemble(aP, a).toarray()
    dense = np.diag(aP)
    for d in range(4):
        m = mesh.nb[:, d] >= 0
        dense[np.nonzero(m)[0], mesh.nb[m, d]] -= a[m, d]
    assert np.array_equal(A, dense)
