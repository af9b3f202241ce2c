"""Compiled sums of the positive readings' evidence when every candidate has its own noise weights.

With ``noise_weights="candidate"`` or ``"larger"`` (:func:`dgse.localization.adjoint.adjoint_log_evidence`)
reading ``i`` has the noise weight ``r_is = 1 + c o_is`` under candidate ``s`` (``o``: the
candidate's own predicted concentration, ``c = kappa / cbar``).  Done with NumPy, each
``kappa`` builds ``r`` and ``1 / r^2`` as ``(m, N)`` arrays, multiplies them into two more and
takes ``m N`` logarithms: in a long search episode that was most of a step (issue 12).
:func:`candidate_sums` makes one pass over the readings' rows and keeps the sums per
candidate; the logarithm is taken of running products of the weights (each at least 1), flushed
into the sum before the largest weight of the next row could take them past ``1e250``: a
few logarithms per candidate instead of one per reading.

A pure function of arrays; compiled on first use and cached on disk, like
:mod:`dgse.localization.censored_kernel`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)

#: The running products of the weights are turned into logarithms before they could exceed this.
_PRODUCT_CAP = 1e250


@_jit
def candidate_sums_many(
    A: np.ndarray, own: np.ndarray, z: np.ndarray, cs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`candidate_sums` for several ``c`` (``kappa / cbar``) in one pass over the rows: each
    ``(K, N)``, row ``j`` that of ``cs[j]``, with the same arithmetic (and bits) as one ``c`` at a
    time.  The rows of ``A`` and ``own`` are read once instead of once per ``kappa``."""
    m, n = A.shape
    nk = cs.size
    aa = np.zeros((n, nk))
    az = np.zeros((n, nk))
    zz = np.zeros((n, nk))
    log_r = np.zeros((n, nk))
    prod = np.ones((n, nk))
    bound = np.ones(nk)  # the largest each kappa's running products can be
    for i in range(m):
        zi = z[i]
        z2 = zi * zi
        a_row = A[i]
        o_row = own[i]
        top = 0.0
        for s in range(n):
            top = max(top, o_row[s])
        for j in range(nk):
            r_max = 1.0 + cs[j] * top
            if bound[j] * r_max > _PRODUCT_CAP:
                _flush(prod[:, j], log_r[:, j])
                bound[j] = 1.0
            bound[j] *= r_max
        for s in range(n):
            a = a_row[s]
            o = o_row[s]
            for j in range(nk):
                r = 1.0 + cs[j] * o
                w = 1.0 / (r * r)
                wa = w * a
                aa[s, j] += wa * a
                az[s, j] += wa * zi
                zz[s, j] += w * z2
                prod[s, j] *= r
    for j in range(nk):
        _flush(prod[:, j], log_r[:, j])
    for s in range(n):
        for j in range(nk):
            aa[s, j] = max(aa[s, j], 1e-300)
    return aa.T.copy(), az.T.copy(), zz.T.copy(), log_r.T.copy()


@_jit
def candidate_sums(
    A: np.ndarray, own: np.ndarray, z: np.ndarray, c: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(aa, az, zz, log_r)`` per candidate ``s``: ``sum_i w a_is^2``, ``sum_i w a_is z_i``,
    ``sum_i w z_i^2`` and ``sum_i log r_is``, with ``r_is = 1 + c own_is`` and ``w = 1 / r_is^2``.

    Args:
        A: ``(m, N)`` responses of the readings; own: ``(m, N)`` the concentrations the noise
            weights scale with (``>= 0``); z: ``(m,)`` readings; c: ``kappa / cbar`` (``>= 0``).

    ``aa`` is kept at least ``1e-300``, as :func:`dgse.localization.adjoint._weighted_sums` does.
    """
    aa, az, zz, log_r = candidate_sums_many(A, own, z, np.array([c]))
    return aa[0], az[0], zz[0], log_r[0]


@_jit
def _flush(prod: np.ndarray, log_r: np.ndarray) -> None:
    """Add ``log prod`` to ``log_r`` and reset the products to 1."""
    for s in range(prod.size):
        log_r[s] += math.log(prod[s])
        prod[s] = 1.0
