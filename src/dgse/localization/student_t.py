"""``log P(lo <= T <= hi)`` of a Student-t, for many intervals of one ``nu`` at once.

The adjoint evidence (:mod:`dgse.localization.adjoint`) needs it for every candidate
source, for five noise weights, every search step: SciPy's ``stdtr`` (an incomplete
beta function per value) was most of the evidence's time.  All candidates of a step
share ``nu``, so :func:`log_interval` interpolates ``log T_nu`` from a table made once
per ``nu`` (cubic Hermite with the exact slope, on a uniform grid in ``u = log(1 -
x)`` over ``x <= 0``, where it is smooth and, in the polynomial tail, almost linear;
interpolation error below ``1e-9`` nats) and falls back to the exact
:func:`log_interval_exact` wherever the table cannot answer to that precision: an
endpoint beyond the table (``|x| > 1e12``, or where ``T`` underflows), and intervals
that hold almost all or almost none of their tail (the subtraction of two nearly
equal tail masses, which would magnify the interpolation error).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import special

#: Grid step of the table in ``u = log(1 - x)``.
TABLE_STEP = 1.0 / 128
#: The table's end, ``x = -1e12``.
TABLE_END = math.log1p(1e12)
#: An interval whose two tail masses differ by less than this share goes the exact way.
EXACT_GAP = 1e-3


def _log_pdf(x: np.ndarray, nu: float) -> np.ndarray:
    return (
        special.gammaln(0.5 * (nu + 1.0))
        - special.gammaln(0.5 * nu)
        - 0.5 * math.log(nu * math.pi)
        - 0.5 * (nu + 1.0) * np.log1p(x * x / nu)
    )


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
        narrow = np.isfinite(width) & ((width < 1e-7 * (1.0 + np.abs(lo) + np.abs(hi))) | ~np.isfinite(out))
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


def _log_cdf_left(x: np.ndarray, nu: float) -> tuple[np.ndarray, np.ndarray]:
    """``(log T_nu(x), known)`` for ``x <= 0`` from the table; ``known`` False beyond it
    (``x = -inf`` gives ``-inf``, known)."""
    g, dg = _table(nu)
    with np.errstate(invalid="ignore", over="ignore"):
        t = np.log1p(-x) / TABLE_STEP
    last = g.size - 1
    known = (t <= last) | np.isneginf(x)
    k = np.clip(np.floor(np.where(known & np.isfinite(t), t, 0.0)).astype(np.int64), 0, max(last - 1, 0))
    s = np.where(known & np.isfinite(t), t, 0.0) - k
    k1 = np.minimum(k + 1, last)
    s2 = s * s
    s3 = s2 * s
    out = (
        (2.0 * s3 - 3.0 * s2 + 1.0) * g[k]
        + (s3 - 2.0 * s2 + s) * TABLE_STEP * dg[k]
        + (3.0 * s2 - 2.0 * s3) * g[k1]
        + (s3 - s2) * TABLE_STEP * dg[k1]
    )
    out = np.where(np.isneginf(x), -np.inf, out)
    return out, known


def log_interval(lo: np.ndarray, hi: np.ndarray, nu: float) -> np.ndarray:
    """``log(T_nu(hi) - T_nu(lo))`` for ``lo <= hi`` (``hi`` may be ``inf``): the table's value,
    and :func:`log_interval_exact`'s where the table cannot answer (module docstring)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    lo, hi = np.broadcast_arrays(lo, hi)
    out = np.empty(lo.shape)
    ok = np.zeros(lo.shape, dtype=bool)
    right = lo >= 0
    left = hi <= 0
    mid = ~(right | left)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for sel, near_end, far_end in ((right, -lo, -hi), (left, hi, lo)):
            if sel.any():
                # log of the tail mass beyond the near end, less the mass beyond the far end
                a, ka = _log_cdf_left(near_end[sel], nu)
                b, kb = _log_cdf_left(far_end[sel], nu)
                r = np.exp(b - a)
                out[sel] = a + np.log1p(-r)
                ok[sel] = ka & kb & np.isfinite(a) & (1.0 - r >= EXACT_GAP)
        if mid.any():
            a, ka = _log_cdf_left(lo[mid], nu)
            b, kb = _log_cdf_left(-hi[mid], nu)
            rest = np.exp(a) + np.exp(b)
            out[mid] = np.log1p(-rest)
            ok[mid] = ka & kb & (1.0 - rest >= EXACT_GAP)
    if not ok.all():
        out[~ok] = log_interval_exact(lo[~ok], hi[~ok], nu)
    return out
