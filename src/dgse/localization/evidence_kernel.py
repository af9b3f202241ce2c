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
    m, n = A.shape
    aa = np.zeros(n)
    az = np.zeros(n)
    zz = np.zeros(n)
    log_r = np.zeros(n)
    prod = np.ones(n)
    bound = 1.0  # the largest the running products can be
    for i in range(m):
        zi = z[i]
        z2 = zi * zi
        a_row = A[i]
        o_row = own[i]
        top = 0.0
        for s in range(n):
            top = max(top, o_row[s])
        r_max = 1.0 + c * top
        if bound * r_max > _PRODUCT_CAP:
            _flush(prod, log_r)
            bound = 1.0
        for s in range(n):
            r = 1.0 + c * o_row[s]
            w = 1.0 / (r * r)
            a = a_row[s]
            wa = w * a
            aa[s] += wa * a
            az[s] += wa * zi
            zz[s] += w * z2
            prod[s] *= r
        bound *= r_max
    _flush(prod, log_r)
    for s in range(n):
        aa[s] = max(aa[s], 1e-300)
    return aa, az, zz, log_r


@_jit
def _flush(prod: np.ndarray, log_r: np.ndarray) -> None:
    """Add ``log prod`` to ``log_r`` and reset the products to 1."""
    for s in range(prod.size):
        log_r[s] += math.log(prod[s])
        prod[s] = 1.0
