"""Compiled weighted sums of the positive readings' evidence, one pass over the response rows.

The evidence of a candidate source (:func:`dgse.posterior.adjoint.adjoint_log_evidence`)
needs, per noise-weight hypothesis ``kappa``, the sums ``sum_i w a_is^2``, ``sum_i w a_is z_i``,
``sum_i w z_i^2`` and ``sum_i log r_is`` over the positive readings ``i`` (``w = 1 / r^2``).
Done with NumPy, the positive readings' rows are first copied out of the ``(m, N)`` responses,
squared, and (with each candidate's own noise weights) multiplied into the ``(m, N)`` weights
``r`` and ``1 / r^2``: in a search step most of that time went into writing those
temporaries, not into the sums.  The kernels here read the rows in place, once, and
keep only the sums:

- :func:`row_sums`: weights shared by every candidate (homoscedastic, ``w = 1``, or the
  plug-in weights of several ``kappa``).
- :func:`candidate_sums_many`: each candidate's own weights ``r_is = 1 + c o_is`` with
  ``o_is = max(a_is q_s, f_i)`` (``q``: the candidates' rates, ``f``: a floor per reading),
  several ``c`` (``kappa / cbar``) in one pass.  The logarithm is taken of running products
  of the weights (each at least 1), flushed into the sum before the largest weight of the next
  row could take them past ``1e250``: a few logarithms per candidate instead of one per reading.

Pure functions of arrays; compiled on first use and cached on disk, like
:mod:`dgse.posterior.censored_kernel`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: ``error_model="numpy"``: a division by zero gives inf or nan, as in NumPy, instead of a
#: check before every division that keeps the loops out of vector registers (here no
#: divisor can be 0: every weight is at least 1).
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")

#: The running products of the weights are turned into logarithms before they could exceed this.
_PRODUCT_CAP = 1e250
#: The least weighted ``sum a^2`` a candidate keeps (one no reading sees would divide by 0).
AA_FLOOR = 1e-300


@_jit
def row_sums(A: np.ndarray, rows: np.ndarray, z: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(aa, az)``, each ``(K, N)``: ``sum_i W[j, i] A[i, s]^2`` and ``sum_i W[j, i] z_i A[i, s]``
    over the readings ``i`` in ``rows``, for each weight row ``j`` (``aa`` kept at least
    :data:`AA_FLOOR`).

    Args:
        A: ``(m, N)`` responses; rows: indices of the readings to sum; z: ``(m,)`` readings;
            W: ``(K, m)`` weights (``1 / r^2``) of each reading under ``K`` noise hypotheses.
    """
    nk = W.shape[0]
    n = A.shape[1]
    aa = np.zeros((nk, n))
    az = np.zeros((nk, n))
    for i in rows:
        a_row = A[i]
        zi = z[i]
        for j in range(nk):
            w = W[j, i]
            wz = w * zi
            aa_j = aa[j]
            az_j = az[j]
            for s in range(n):
                a = a_row[s]
                aa_j[s] += w * a * a
                az_j[s] += wz * a
    for j in range(nk):
        for s in range(n):
            aa[j, s] = max(aa[j, s], AA_FLOOR)
    return aa, az


@_jit
def candidate_sums_many(
    A: np.ndarray, rows: np.ndarray, q: np.ndarray, floor: np.ndarray, z: np.ndarray, cs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(aa, az, zz, log_r)``, each ``(K, N)``, row ``j`` that of ``c = cs[j]``: per candidate
    ``s``, ``sum_i w a_is^2``, ``sum_i w a_is z_i``, ``sum_i w z_i^2`` and ``sum_i log r_is`` over
    the readings ``i`` in ``rows``, with ``r_is = 1 + c o_is``, ``o_is = max(a_is q_s, floor_i)``
    and ``w = 1 / r_is^2`` (``aa`` kept at least :data:`AA_FLOOR`).

    Args:
        A: ``(m, N)`` responses; rows: indices of the readings to sum; q: ``(N,)`` each
            candidate's rate (``>= 0``); floor: ``(m,)`` the least concentration a reading's weight
            scales with (zeros: a candidate's own prediction, ``noise_weights="candidate"``);
            z: ``(m,)`` readings; cs: ``(K,)`` the ``kappa / cbar`` (``>= 0``).

    Every ``c`` gets the same arithmetic (and bits) as it would alone.  Each reading's row is
    read once; the loop over the candidates is innermost, so that it runs in vector registers.
    """
    n = A.shape[1]
    nk = cs.size
    aa = np.zeros((nk, n))
    az = np.zeros((nk, n))
    zz = np.zeros((nk, n))
    log_r = np.zeros((nk, n))
    prod = np.ones((nk, n))
    bound = np.ones(nk)  # the largest each c's running products can be
    own = np.empty(n)
    for i in rows:
        zi = z[i]
        z2 = zi * zi
        a_row = A[i]
        f = floor[i]
        top = f
        for s in range(n):
            o = max(a_row[s] * q[s], f)
            own[s] = o
            top = max(top, o)
        for j in range(nk):
            c = cs[j]
            r_max = 1.0 + c * top
            if bound[j] * r_max > _PRODUCT_CAP:
                _flush(prod[j], log_r[j])
                bound[j] = 1.0
            bound[j] *= r_max
            aa_j, az_j, zz_j, prod_j = aa[j], az[j], zz[j], prod[j]
            for s in range(n):
                a = a_row[s]
                r = 1.0 + c * own[s]
                w = 1.0 / (r * r)
                wa = w * a
                aa_j[s] += wa * a
                az_j[s] += wa * zi
                zz_j[s] += w * z2
                prod_j[s] *= r
    for j in range(nk):
        _flush(prod[j], log_r[j])
        for s in range(n):
            aa[j, s] = max(aa[j, s], AA_FLOOR)
    return aa, az, zz, log_r


@_jit
def own_weights(A: np.ndarray, q: np.ndarray, floor: np.ndarray, c: float) -> np.ndarray:
    """``(m, N)`` the noise weights ``r_is = 1 + c max(a_is q_s, floor_i)`` of
    :func:`candidate_sums_many`, in one pass (no temporaries)."""
    m, n = A.shape
    r = np.empty((m, n))
    for i in range(m):
        a_row = A[i]
        f = floor[i]
        r_row = r[i]
        for s in range(n):
            r_row[s] = 1.0 + c * max(a_row[s] * q[s], f)
    return r


@_jit
def _flush(prod: np.ndarray, log_r: np.ndarray) -> None:
    """Add ``log prod`` to ``log_r`` and reset the products to 1."""
    for s in range(prod.size):
        log_r[s] += math.log(prod[s])
        prod[s] = 1.0
