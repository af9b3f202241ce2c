"""``log P(lo <= T <= hi)`` of a Student-t, for many intervals of one ``nu`` at once.

The adjoint evidence (:mod:`dgse.posterior.adjoint`) needs it for every candidate
source, for five noise weights, every search step: SciPy's ``stdtr`` (an incomplete
beta function per value) would be most of the evidence's time.  All candidates of a step
share ``nu``, so :func:`log_interval` interpolates ``log T_nu`` from a table made once
per ``nu`` (cubic Hermite with the exact slope, on a uniform grid in ``u = log(1 -
x)`` over ``x <= 0``, where it is smooth and, in the polynomial tail, almost linear;
interpolation error below ``1e-7`` nats; a compiled loop, so that the threads that weigh
the flow hypotheses run it side by side) and falls back to the exact
:func:`log_interval_exact` wherever the table cannot answer to that precision: an
endpoint beyond the table (``|x| > 1e12``, or where ``T`` underflows), and intervals
that hold almost all or almost none of their tail (the subtraction of two nearly
equal tail masses, which would magnify the interpolation error), except the narrowest
(width below :data:`NARROW` of their ends' size: the candidates no reading sees), whose
density times width the loop takes as the exact function does.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from scipy import special

_jit = numba.njit(cache=True, nogil=True)

#: Grid step of the table in ``u = log(1 - x)``.
TABLE_STEP = 1.0 / 128
#: The table's end, ``x = -1e12``.
TABLE_END = math.log1p(1e12)
#: An interval whose two tail masses differ by less than this share goes the exact way.
EXACT_GAP = 1e-3
#: An interval narrower than this times ``1 + |lo| + |hi|`` gets the density times its width.
NARROW = 1e-7


@functools.lru_cache(maxsize=64)
def _log_norm(nu: float) -> float:
    """The log normalizer of the Student-t density with ``nu`` degrees of freedom."""
    return float(special.gammaln(0.5 * (nu + 1.0)) - special.gammaln(0.5 * nu) - 0.5 * math.log(nu * math.pi))


def _log_pdf(x: np.ndarray, nu: float) -> np.ndarray:
    return _log_norm(nu) - 0.5 * (nu + 1.0) * np.log1p(x * x / nu)


def log_interval_exact(lo: np.ndarray, hi: np.ndarray, nu: float) -> np.ndarray:
    """``log(T_nu(hi) - T_nu(lo))`` for ``lo <= hi`` (``hi`` may be ``inf``) by SciPy's CDF.

    Stable in both tails; an interval too narrow for the CDFs' difference gets the density
    times its width.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    lo, hi = np.broadcast_arrays(lo, hi)
    # Student-t CDF from scipy.special (the frozen scipy.stats distribution costs ~10x more per call)
    cdf = special.stdtr
    out = np.empty(lo.shape)
    right = lo >= 0  # both in the right tail: survival functions
    left = hi <= 0  # both in the left tail: CDFs
    mid = ~(right | left)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if right.any():
            a, b = np.log(cdf(nu, -lo[right])), np.log(cdf(nu, -hi[right]))
            out[right] = a + np.log1p(-np.exp(b - a))
        if left.any():
            a, b = np.log(cdf(nu, hi[left])), np.log(cdf(nu, lo[left]))
            out[left] = a + np.log1p(-np.exp(b - a))
        if mid.any():
            # the upper tail's mass only where it can register (beyond the 1e-13 quantile
            # it is below the last bit of 1 - T(lo) >= 1/2)
            lo_m, hi_m = lo[mid], hi[mid]
            far = -float(special.stdtrit(nu, 1e-13))
            upper = np.zeros(lo_m.shape)
            near = hi_m <= far
            upper[near] = cdf(nu, -hi_m[near])
            out[mid] = np.log1p(-(cdf(nu, lo_m) + upper))
        width = hi - lo
        narrow = np.isfinite(width) & ((width < NARROW * (1.0 + np.abs(lo) + np.abs(hi))) | ~np.isfinite(out))
        if narrow.any():
            c = 0.5 * (lo[narrow] + hi[narrow])
            out[narrow] = _log_pdf(c, nu) + np.log(np.maximum(width[narrow], 1e-300))
    return out


@functools.lru_cache(maxsize=16)
def _table(nu: float) -> tuple[np.ndarray, np.ndarray]:
    """``(g, dg)``: ``log T_nu(x)`` and its slope in ``u`` at ``x = 1 - e^u``, ``u = 0, h, 2h, ...``,
    up to :data:`TABLE_END` or to where ``T_nu`` underflows, whichever is first."""
    u = np.arange(0.0, TABLE_END + TABLE_STEP, TABLE_STEP)
    x = -np.expm1(u)
    cdf = special.stdtr(nu, x)
    good = np.flatnonzero(cdf > 1e-290)
    k = int(good[-1]) + 1 if good.size else 1
    x, cdf = x[:k], cdf[:k]
    g = np.log(cdf)
    dg = -(1.0 - x) * np.exp(_log_pdf(x, nu) - g)  # d log T / du = f / T * dx/du, dx/du = -(1 - x)
    g.setflags(write=False)
    dg.setflags(write=False)
    return g, dg


@_jit
def _lookup(x: float, g: np.ndarray, dg: np.ndarray, step: float) -> tuple[float, bool]:
    """``(log T_nu(x), known)`` for ``x <= 0`` from the table: cubic Hermite in ``u = log(1 - x)``;
    not known beyond the table (``x = -inf`` gives ``-inf``, known)."""
    if x == -math.inf:
        return -math.inf, True
    t = math.log1p(-x) / step
    last = g.size - 1
    if not (t <= last) or last < 1:
        return math.nan, False
    k = min(int(t), last - 1)
    s = t - k
    s2 = s * s
    s3 = s2 * s
    val = (
        (2.0 * s3 - 3.0 * s2 + 1.0) * g[k]
        + (s3 - 2.0 * s2 + s) * step * dg[k]
        + (3.0 * s2 - 2.0 * s3) * g[k + 1]
        + (s3 - s2) * step * dg[k + 1]
    )
    return val, True


@_jit
def _log_interval_table(
    lo: np.ndarray,
    hi: np.ndarray,
    g: np.ndarray,
    dg: np.ndarray,
    step: float,
    gap: float,
    nu: float,
    log_norm: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The table's ``log(T(hi) - T(lo))`` per interval and whether it holds to the table's precision.

    An interval narrower than :data:`NARROW` of its ends' size gets the density at its
    middle times its width (``log_norm``: the density's log normalizer), as
    :func:`log_interval_exact` gives it: a candidate that no reading sees has such an
    interval, a share of the many that the table alone cannot answer.
    """
    n = lo.size
    out = np.empty(n)
    ok = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        a_lo, a_hi = lo[i], hi[i]
        width = a_hi - a_lo
        if math.isfinite(width) and width < NARROW * (1.0 + abs(a_lo) + abs(a_hi)):
            c = 0.5 * (a_lo + a_hi)
            out[i] = log_norm - 0.5 * (nu + 1.0) * math.log1p(c * c / nu) + math.log(max(width, 1e-300))
            ok[i] = True
            continue
        if a_lo >= 0.0 or a_hi <= 0.0:
            # both ends in one tail: the mass beyond the near end less the mass beyond the far end
            if a_lo >= 0.0:
                a, ka = _lookup(-a_lo, g, dg, step)
                b, kb = _lookup(-a_hi, g, dg, step)
            else:
                a, ka = _lookup(a_hi, g, dg, step)
                b, kb = _lookup(a_lo, g, dg, step)
            if ka and kb and math.isfinite(a):
                r = math.exp(b - a)
                out[i] = a + math.log1p(-r)
                ok[i] = 1.0 - r >= gap
        else:
            a, ka = _lookup(a_lo, g, dg, step)
            b, kb = _lookup(-a_hi, g, dg, step)
            if ka and kb:
                rest = math.exp(a) + math.exp(b)
                out[i] = math.log1p(-rest)
                ok[i] = 1.0 - rest >= gap
    return out, ok


def log_interval(lo: np.ndarray, hi: np.ndarray, nu: float) -> np.ndarray:
    """``log(T_nu(hi) - T_nu(lo))`` for ``lo <= hi`` (``hi`` may be ``inf``): the table's value,
    and :func:`log_interval_exact`'s where the table cannot answer (module docstring)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    lo, hi = np.broadcast_arrays(lo, hi)
    shape = lo.shape
    nu = float(nu)
    g, dg = _table(nu)
    out, ok = _log_interval_table(
        np.ascontiguousarray(lo).ravel(),
        np.ascontiguousarray(hi).ravel(),
        g,
        dg,
        TABLE_STEP,
        EXACT_GAP,
        nu,
        _log_norm(nu),
    )
    out, ok = out.reshape(shape), ok.reshape(shape)
    if not ok.all():
        out[~ok] = log_interval_exact(lo[~ok], hi[~ok], nu)
    return out
