"""Compiled kernel of the censored readings' factor (:func:`dgse.posterior.adjoint.censored_correction`).

The factor of each candidate source is a small two-dimensional quadrature (over the
log noise precision and the release rate) whose nodes depend on the candidate: done
with NumPy it is a few dozen passes over ``(nodes, candidates)`` arrays and their
temporaries, most of a search step's cost.  Here one loop over the
candidates does the same arithmetic in registers.  The normal distribution's
``log Phi`` and its inverse are written out, as numba cannot call SciPy's ufuncs:

* :func:`log_ndtr` follows SciPy's ``log_ndtr``: ``log1p(-Phi(-a))`` in the right
  tail, ``log(erfc)`` in the middle, the asymptotic series below ``-20``, and a power
  series within ``1e-3`` of 0 (a zero that a candidate hardly reaches lands there);
* :func:`ndtri_exp` starts from Acklam's rational approximation of the normal
  quantile (relative error below ``1.2e-9``; in the tails written in ``sqrt(-2
  log p)``, which needs no ``exp`` and so reaches ``log p`` far below double
  precision's ``p``) and takes a Newton step on ``log Phi(x) = y`` (in the kernel only
  where the rate nodes need more than Acklam's precision).

Both are tested against SciPy (``tests/localization/test_censored_kernel.py``).  The sums of
the zeros' ``log Phi`` (:func:`_log_phi_sum`, and the Mills ratio of the Newton steps over
``log tau``) read ``log Phi`` on ``[-38, 0)`` from a table instead (:func:`log_ndtr_table`:
cubic Hermite between nodes 1/64 apart, values and slopes from SciPy, within 1e-10 nats),
several times cheaper than ``erfc`` and ``log`` (``python benchmarks/search.py step-time`` times a
search step).  The quantiles of the rate nodes (:func:`_rate_nodes`) keep the exact
functions.

Most zeros hardly reach most candidates (a sensor upwind or behind a wall): those whose
``lambda b_i`` stays within ``_SERIES_X`` up to the candidate's largest plausible ``lambda``
enter every sum through a Taylor series in their power sums (:func:`_split_zeros`), so each
pass visits only the zeros the candidate reaches; Newton's step on a rate node's quantile
is taken only where Acklam's error could exceed :data:`_QUANTILE_SHIFT` of the nodes'
spread (``benchmarks/censored_kernel_time.py`` at commit 86ae264 timed the kernel on recorded calls).

The integral over ``log tau`` is Gauss-Hermite around a Newton mode found with the rate at
its estimate from the positive readings.  Where those leave a rate near 0 plausible (few
of them, or an estimate above ``q_max``) and the zeros see the candidate, the mass sits at
a small rate, away from that mode; a probe of the integrand near the positive readings'
noise precision detects it, and :func:`_scan_log_integral` integrates such a candidate
without a guessed mode (``benchmarks/censored_accuracy.py``, in git history at commit
86ae264, measured both against a brute-force integral).

Given ``tau``, the rate's nodes sit at quantiles of the positive readings' normal
posterior of it.  With a noise floor far above the plume, half the readings are zeros
and the positive ones noise: their rate lies many spreads above where the zeros put
it, and the product's mass lies beyond every node.  Where a Newton step from the
positive readings' rate moves it by more than ``TILT_MIN`` of its spread (or the zeros
narrow it below half, ``_TILT_NARROW``), the nodes follow a normal fitted to the product and
carry the ratio of the two densities (:func:`_rate_nodes`), and the Newton steps over
``log tau`` take the moved rate.
Pure functions of arrays; compiled on first use and cached on disk, like
:mod:`dgse.physics.fv`.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy import special

_jit = numba.njit(cache=True, nogil=True)

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_SQRT_2PI = math.sqrt(2.0 * math.pi)
_SQRT_HALF = math.sqrt(0.5)
_LOG_HALF = math.log(0.5)
_PHI0 = 1.0 / math.sqrt(2.0 * math.pi)
#: Below this, :func:`log_ndtr` and :func:`_mills` use their series.
_SMALL = 1e-3
#: Below this width (standard deviations) a normal interval's mass is the midpoint rule's.
_NARROW = 1e-5
#: Where the factor probes its integrand over ``log tau``, from the positive readings' t0.
_PROBES = np.array([0.0, -2.0])
# The fallback scan over ``log tau`` (:func:`_scan_log_integral`): its reach beyond the mode
# and t0, the central differences' step, the fall that ends the walk, the most Newton steps,
# the uniform steps each side of the peak, the most growing steps beyond, and the largest
# ``alpha_n`` at which a rate estimate outside ``[0, q_max]`` is scanned (the probe covers
# the rest; ``benchmarks/censored_accuracy.py`` at commit 86ae264).
_SCAN_REACH = 8.0
_FD = 1e-2
_SCAN_DROP = 20.0
_SCAN_NEWTON = 12
_SCAN_UNIFORM = 6
_SCAN_MAX_STEPS = 60
_SCAN_OUTSIDE_ALPHA = 5.0
#: The rate's nodes follow the zeros where a Newton step moves the rate by more spreads than this.
TILT_MIN = 2.0
#: ... or where the zeros narrow the rate's spread below this share of the positive readings'.
_TILT_NARROW = 0.5
#: How far (in the nodes' spread) Acklam's quantile may leave a rate node before a Newton step.
_QUANTILE_SHIFT = 1e-5
#: The most Newton steps to the tilted rate's mode, and their tolerance in its spreads.
_TILT_NEWTON = 30
_TILT_TOL = 1e-2

# Acklam's coefficients of the normal quantile (central region and tails)
_A = np.array(
    [-3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02,
     1.383577518672690e02, -3.066479806614716e01, 2.506628277459239e00]
)  # fmt: skip
_B = np.array(
    [-5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02,
     6.680131188771972e01, -1.328068155288572e01]
)  # fmt: skip
_C = np.array(
    [-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00,
     -2.549732539343734e00, 4.374664141464968e00, 2.938163982698783e00]
)  # fmt: skip
_D = np.array([7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00, 3.754408661907416e00])
_P_LOW = 0.02425
_LOG_P_LOW = math.log(_P_LOW)

#: :func:`log_ndtr_table`'s range ``[_TABLE_LO, 0)`` and its nodes per unit of the argument.
_TABLE_LO = -38.0
_TABLE_PER_UNIT = 64


def _log_ndtr_nodes() -> tuple[np.ndarray, np.ndarray]:
    """``log Phi`` and its slope ``phi / Phi`` (times the node spacing) at the table's nodes."""
    a = np.linspace(_TABLE_LO, 0.0, int(-_TABLE_LO) * _TABLE_PER_UNIT + 1)
    f = special.log_ndtr(a)
    slope = np.exp(-0.5 * a * a - f - _LOG_SQRT_2PI)
    return f, slope / _TABLE_PER_UNIT


_TABLE_F, _TABLE_D = _log_ndtr_nodes()
_TABLE_LAST = _TABLE_F.size - 2


@_jit
def log_ndtr(a: float) -> float:
    """``log Phi(a)``, accurate in both tails (``-inf`` at ``-inf``, 0 at ``inf``)."""
    if abs(a) < _SMALL:
        # near 0 by series, without erfc and log: Phi(a) = (1 + y) / 2 with
        # y = 2 phi(0) (a - a^3 / 6), and log1p(y) to y^5 (|y| < 8e-4: error below 1e-19);
        # a zero a candidate does not reach (response 0) lands here, most of them
        y = 2.0 * _PHI0 * a * (1.0 - a * a / 6.0)
        return _LOG_HALF + y * (1.0 - y * (0.5 - y * (1.0 / 3.0 - y * (0.25 - 0.2 * y))))
    if a > 0.0:
        return math.log1p(-0.5 * math.erfc(a * _SQRT_HALF))
    if a > -20.0:
        return math.log(0.5 * math.erfc(-a * _SQRT_HALF))
    if a == -math.inf:
        return -math.inf
    # asymptotic series of the Mills ratio, summed until it no longer changes
    log_lhs = -0.5 * a * a - math.log(-a) - _LOG_SQRT_2PI
    rhs = 1.0
    last = 0.0
    term = 1.0
    inv2 = 1.0 / (a * a)
    i = 0
    while abs(last - rhs) > 1e-16 and i < 50:
        i += 1
        last = rhs
        term *= -(2.0 * i - 1.0) * inv2
        rhs += term
    return log_lhs + math.log(rhs)


@_jit
def log_ndtr_table(a: float) -> float:
    """``log Phi(a)`` from the table on ``[-38, 0)`` (cubic Hermite; :func:`log_ndtr` elsewhere).

    The interpolant's error is below ``h^4 / 384`` times the fourth derivative (``h = 1/64``;
    that derivative stays below 0.12 in magnitude, largest near 0): under 2e-11 nats; the
    tests hold it to 1e-10 against SciPy.
    """
    if not (a < 0.0 and a >= _TABLE_LO):
        return log_ndtr(a)
    x = (a - _TABLE_LO) * _TABLE_PER_UNIT
    i = min(int(x), _TABLE_LAST)
    t = x - i
    f0 = _TABLE_F[i]
    f1 = _TABLE_F[i + 1]
    d0 = _TABLE_D[i]
    d1 = _TABLE_D[i + 1]
    df = f1 - f0
    return f0 + t * (d0 + t * ((3.0 * df - 2.0 * d0 - d1) + t * (d0 + d1 - 2.0 * df)))


@_jit
def _acklam(p: float, y: float) -> float:
    """Acklam's approximation of the normal quantile of ``p <= 1/2`` (``y = log p``, or nan to
    take it from ``p`` when needed; ``p`` may underflow to 0 when ``y`` is given)."""
    if p >= _P_LOW:
        q = p - 0.5
        r = q * q
        num = (((((_A[0] * r + _A[1]) * r + _A[2]) * r + _A[3]) * r + _A[4]) * r + _A[5]) * q
        return num / (((((_B[0] * r + _B[1]) * r + _B[2]) * r + _B[3]) * r + _B[4]) * r + 1.0)
    if math.isnan(y):
        y = math.log(p)
    q = math.sqrt(-2.0 * y)
    num = ((((_C[0] * q + _C[1]) * q + _C[2]) * q + _C[3]) * q + _C[4]) * q + _C[5]
    return num / ((((_D[0] * q + _D[1]) * q + _D[2]) * q + _D[3]) * q + 1.0)


@_jit
def _mills(x: float, log_phi: float = math.nan) -> float:
    """``phi(x) / Phi(-x)``; by series near 0 (``x`` below ``_SMALL``: error below 1e-16).
    ``log_phi``: ``log Phi(-x)`` where the caller has it already (nan: from the table)."""
    if abs(x) < _SMALL:
        x2 = x * x
        return _PHI0 * (1.0 - 0.5 * x2 * (1.0 - 0.25 * x2)) / (0.5 - _PHI0 * x * (1.0 - x2 / 6.0))
    if math.isnan(log_phi):
        log_phi = log_ndtr_table(-x)
    return math.exp(-0.5 * x * x - log_phi) / _SQRT_2PI


@_jit
def _newton(x: float, y: float) -> float:
    """Newton steps on ``log Phi(x) = y`` from Acklam's ``x`` (slope ``phi / Phi``, positive and
    slowly growing): one takes his ``1e-9`` to double precision; two far in the tail, where
    his rational fit is extrapolated."""
    for _ in range(2 if y < -700.0 else 1):
        lx = log_ndtr(x)
        x -= (lx - y) * math.exp(lx + 0.5 * x * x + _LOG_SQRT_2PI)
    return x


@_jit
def _ndtri_exp_left(y: float) -> float:
    """``x <= 0`` with ``log Phi(x) = y`` for ``y <= log(1/2)``."""
    p = math.exp(y) if y > -700.0 else 0.0
    return _newton(_acklam(p, y), y)


@_jit
def _share_quantile(a: float, pa: float, f: float, fc: float) -> tuple[float, float, float, float]:
    """Acklam's ``x`` with ``Phi(x) = e^a f`` (``pa = e^a``, ``fc = 1 - f`` given exactly).

    Returns ``(x_left, p_left, y_left, sign)``: ``x = sign * x_left`` where ``x_left <= 0``
    has ``Phi(x_left) = p_left``, ``log p_left = y_left`` (nan where Acklam did not need it:
    take ``log(p_left)``), for :func:`_newton` where the caller needs full precision.
    """
    p = pa * f
    if p > 0.5:
        # the right half: its complement 1 - e^a f = (1 - e^a) + e^a fc, without cancellation
        comp = -math.expm1(a) + pa * fc
        y = math.log(comp) if comp < _P_LOW else math.nan
        return _acklam(comp, y), comp, y, -1.0
    y = a + math.log(f) if p < _P_LOW else math.nan
    return _acklam(p, y), p, y, 1.0


@_jit
def ndtri_exp(y: float) -> float:
    """``x`` with ``log Phi(x) = y`` (``y <= 0``; ``inf`` at 0, ``-inf`` at ``-inf``, nan above 0)."""
    if not (y <= 0.0):
        return math.nan
    if y == 0.0:
        return math.inf
    if y == -math.inf:
        return -math.inf
    if y > _LOG_HALF:
        # the right half: the quantile of the complement, 1 - exp(y), taken without cancellation
        return -_ndtri_exp_left(math.log(-math.expm1(y)))
    return _ndtri_exp_left(y)


@_jit
def _log_phi_sum(lam: float, b: np.ndarray) -> float:
    """``G(lambda) = sum_i log Phi(-lambda b_i)``: the zeros' log factor at ``lambda = q sqrt(tau)``."""
    acc = 0.0
    for i in range(b.size):
        acc += log_ndtr_table(-lam * b[i])
    return acc


@_jit
def _log_f(
    t: float,
    lmass: float,
    g: np.ndarray,
    log_wu: np.ndarray,
    alpha_n: float,
    bn: float,
    log_gamma_norm: float,
) -> float:
    """The integrand over ``t = log tau`` at one node: the Gamma density of ``tau`` times ``tau``,
    the rate's truncation mass ``lmass``, and the mean of ``exp(G)`` over the rate's nodes
    (``g``: ``G`` there, ``log_wu``: their log weights); ``-inf`` where it vanishes."""
    top = -math.inf
    for j in range(g.size):
        top = max(top, g[j])
    if not math.isfinite(top):
        return -math.inf
    acc = 0.0
    for j in range(g.size):
        acc += math.exp(log_wu[j] + g[j] - top)
    v = log_gamma_norm + alpha_n * t - bn * math.exp(t) + lmass + top + math.log(acc)
    return -math.inf if math.isnan(v) else v


@_jit
def _truncation_mass(lo: float, hi: float) -> tuple[float, float, float, bool]:
    """``log(Phi(hi) - Phi(lo))`` from the tail the interval lies in.

    Returns ``(log mass, log Phi of the interval's end nearer the mode, d, upper)``: in the
    right half (``upper``, ``lo >= 0``) the mass is ``Phi(-lo) (1 - d)`` with ``d = Phi(-hi) /
    Phi(-lo)``, otherwise ``Phi(hi) (1 - d)`` with ``d = Phi(lo) / Phi(hi)``.
    """
    upper = lo >= 0.0
    if upper:
        a = log_ndtr(-lo)
        b = log_ndtr(-hi)
    else:
        a = log_ndtr(hi)
        b = log_ndtr(lo)
    d = math.exp(b - a)
    if hi - lo < _NARROW:
        # 1 - d is lost to rounding (d is 1 for a candidate no positive reading sees: the
        # rate's conditional is flat, sd near 1e150): the midpoint rule, relative error
        # about (hi - lo)^2 (1 + mid^2) / 24
        mid = 0.5 * (lo + hi)
        return math.log(hi - lo) - 0.5 * mid * mid - _LOG_SQRT_2PI, a, d, upper
    return a + math.log1p(-d), a, d, upper


@_jit
def _tau_sums(q: float, e: float, b: np.ndarray) -> tuple[float, float, float, float]:
    """At ``lambda = q e`` (``e = sqrt(tau)``): ``(s1, s2)``, the sums the derivatives of ``G`` in
    ``log tau`` are made of, and ``(G', G'')`` in ``lambda`` (:func:`_zeros_slopes` without
    ``G``), from one Mills ratio per zero (``x = q b_i e`` in that order, as the kernel
    always rounded it)."""
    s1 = 0.0
    s2 = 0.0
    g1 = 0.0
    g2 = 0.0
    for i in range(b.size):
        x = q * b[i] * e
        lm = _mills(x)
        s1 += lm * x
        s2 += (lm * (lm - x) * x + lm) * x
        g1 -= b[i] * lm
        g2 -= b[i] * b[i] * lm * (lm - x)
    return s1, s2, g1, g2


@_jit
def _zeros_slopes(lam: float, b: np.ndarray) -> tuple[float, float, float]:
    """``G(lambda)`` and its first two derivatives in ``lambda`` (:func:`_log_phi_sum`), in one
    pass: the Mills ratio reuses each zero's ``log Phi``, the same numbers, summed in the same
    order, as :func:`_log_phi_sum` and :func:`_tau_sums` give apart."""
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    for i in range(b.size):
        x = lam * b[i]
        lp = log_ndtr_table(-x)
        g0 += lp
        lm = _mills(x, lp)
        g1 -= b[i] * lm
        g2 -= b[i] * b[i] * lm * (lm - x)
    return g0, g1, g2


def _log_ndtr_series(order: int) -> np.ndarray:
    """Taylor coefficients of ``log Phi(-x)`` at 0 up to ``x^order``: ``Phi(-x) = (1 - y) / 2`` with
    ``y = 2 phi(0) sum_n (-1)^n x^(2n+1) / (2^n n! (2n + 1))``, and ``log(1 - y) = -sum_k y^k / k``."""
    y = np.zeros(order + 1)
    for n in range(order // 2 + 1):
        if 2 * n + 1 <= order:
            y[2 * n + 1] = 2.0 * _PHI0 * (-1.0) ** n / (2.0**n * math.factorial(n) * (2 * n + 1))
    coef = np.zeros(order + 1)
    coef[0] = _LOG_HALF
    power = np.zeros(order + 1)
    power[0] = 1.0
    for k in range(1, order + 1):
        power = np.convolve(power, y)[: order + 1]
        coef -= power / k
    return coef


#: The Taylor series of ``log Phi(-x)`` at 0 that stands for the zeros a candidate hardly
#: reaches (``lambda b_i <= _SERIES_X`` up to its cap; within 2e-12 nats a zero): its order.
_SERIES_ORDER = 8
#: ... and the largest ``lambda b_i`` it covers.
_SERIES_X = 0.2
_SERIES = _log_ndtr_series(_SERIES_ORDER)
#: The cap's noise precision: the Wilson-Hilferty approximation of the noise posterior's
#: quantile this many standard normal deviations up (about 1 - 1e-12).
_CAP_Z = 7.0


@_jit
def _lambda_cap(qhat: float, aa: float, bn: float, alpha_n: float, qmax: float) -> float:
    """The largest ``lambda = q sqrt(tau)`` a candidate's quadrature is expected to need: the rate
    at its prior's end (or 8 spreads above its estimate where the prior is unbounded) and
    the noise precision far up its posterior ``Gamma(alpha_n, bn)``.  Only the speed depends on
    it: beyond it the sums take every zero."""
    if not (alpha_n > 0.0 and bn > 0.0):
        return 0.0
    if math.isfinite(qmax):
        q_cap = qmax
    else:
        q_cap = max(qhat, 0.0) + 8.0 * math.sqrt(bn / (alpha_n * aa)) if aa > 0.0 else math.inf
    wh = max(1.0 - 1.0 / (9.0 * alpha_n) + _CAP_Z / (3.0 * math.sqrt(alpha_n)), 0.1)
    return q_cap * math.sqrt(alpha_n / bn * wh * wh * wh)


@_jit
def _split_zeros(b: np.ndarray, cap: float, row: np.ndarray, mom: np.ndarray) -> int:
    """Reorder a candidate's zeros ``b`` into ``row``: those it reaches first (their number is
    returned, in their order in ``b``), then the faint ones (``0 <= b_i cap <= _SERIES_X``),
    whose power sums ``sum b_i^k``, ``k = 0.._SERIES_ORDER``, go to ``mom``."""
    c = b.size
    lim = _SERIES_X / cap if cap > 0.0 else math.inf
    for k in range(mom.size):
        mom[k] = 0.0
    nb = 0
    ns = 0
    for i in range(c):
        v = b[i]
        if 0.0 <= v <= lim:
            ns += 1
            row[c - ns] = v
            p = 1.0
            for k in range(mom.size):
                mom[k] += p
                p *= v
        else:
            row[nb] = v
            nb += 1
    return nb


@_jit
def _series_slopes(lam: float, mom: np.ndarray) -> tuple[float, float, float]:
    """The faint zeros' ``G`` and its first two derivatives in ``lambda``: ``sum_k c_k S_k lambda^k``
    (``c_k``: :data:`_SERIES`, ``S_k``: ``mom``) by Horner's rule."""
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    for k in range(mom.size - 1, -1, -1):
        a = _SERIES[k] * mom[k]
        g0 = g0 * lam + a
        if k >= 1:
            g1 = g1 * lam + k * a
        if k >= 2:
            g2 = g2 * lam + k * (k - 1) * a
    return g0, g1, g2


@_jit
def _faint_ok(lam: float, mom: np.ndarray, cap: float) -> bool:
    """Whether the series stands for the faint zeros at ``lambda``: within the cap, or every
    faint zero exactly 0 (then ``log(1/2)`` each, at any ``lambda``)."""
    return abs(lam) <= cap or mom[1] == 0.0


@_jit
def _g_split(lam: float, row: np.ndarray, nb: int, mom: np.ndarray, cap: float) -> float:
    """:func:`_log_phi_sum` over a candidate's zeros as :func:`_split_zeros` left them."""
    if _faint_ok(lam, mom, cap):
        return _log_phi_sum(lam, row[:nb]) + _series_slopes(lam, mom)[0]
    return _log_phi_sum(lam, row)


@_jit
def _slopes_split(
    lam: float, row: np.ndarray, nb: int, mom: np.ndarray, cap: float
) -> tuple[float, float, float]:
    """:func:`_zeros_slopes` over a candidate's zeros as :func:`_split_zeros` left them."""
    if _faint_ok(lam, mom, cap):
        g0, g1, g2 = _zeros_slopes(lam, row[:nb])
        h0, h1, h2 = _series_slopes(lam, mom)
        return g0 + h0, g1 + h1, g2 + h2
    return _zeros_slopes(lam, row)


@_jit
def _tau_split(
    q: float, e: float, row: np.ndarray, nb: int, mom: np.ndarray, cap: float
) -> tuple[float, float, float, float]:
    """:func:`_tau_sums` over a candidate's zeros as :func:`_split_zeros` left them.  With
    ``x = lambda b``, the Mills ratio is ``-f'(x)`` of ``f(x) = log Phi(-x)``, so the faint
    zeros' ``s1 = -lambda G'`` and ``s2 = -lambda^2 G'' - lambda G'``."""
    lam = q * e
    if _faint_ok(lam, mom, cap):
        s1, s2, g1, g2 = _tau_sums(q, e, row[:nb])
        _h0, h1, h2 = _series_slopes(lam, mom)
        return s1 - lam * h1, s2 - lam * lam * h2 - lam * h1, g1 + h1, g2 + h2
    return _tau_sums(q, e, row)


@_jit
def _moves_rate(d1: float, d2: float, prec: float, tilt_min: float) -> bool:
    """Whether the zeros move the rate enough for its nodes to follow them: ``d1``, ``d2`` the
    first two derivatives in ``q`` of the rate's log density times the zeros' factor at the
    positive readings' rate, ``prec`` that rate's precision from the positive readings.  A
    Newton step of at least ``tilt_min`` spreads, or a spread narrowed below
    :data:`_TILT_NARROW` of the positive readings' one."""
    if not (d2 < 0.0 and math.isfinite(d1)) or tilt_min == math.inf:
        return False
    return abs(d1) / math.sqrt(-d2) >= tilt_min or prec <= _TILT_NARROW**2 * -d2


@_jit
def _rate_mode(
    t: float,
    qhat: float,
    aa: float,
    qmax: float,
    b: np.ndarray,
    nb: int,
    mom: np.ndarray,
    cap: float,
    q_start: float,
    checked: bool,
    tilt_min: float,
) -> tuple[float, float]:
    """Where the zeros move the rate given ``tau = e^t``: ``(mode, sd)`` of a normal fitted
    (Laplace) to ``log N(q; qhat, 1 / (tau aa)) + G(q sqrt(tau))``, or ``(nan, nan)`` where
    the zeros move the rate by less than ``tilt_min`` (:data:`TILT_MIN`; ``inf``: never
    tilt) of its spread and narrow it by less than :data:`_TILT_NARROW` (tested at the
    positive readings' rate ``qc``; ``checked``: the caller has, and they do).

    The function is concave in ``q`` (``log Phi`` is concave), so Newton's steps from
    ``q_start`` (nan: ``qc``), halved while they do not climb, reach its maximum over the
    real line (it may lie below 0: the truncation to ``[0, qmax]`` is the nodes' business,
    as for the untilted normal).  They stop within :data:`_TILT_TOL` of its spread: the
    nodes' importance weights make up for the rest.
    """
    if b.size == 0 or not (aa > 0.0) or tilt_min == math.inf:
        return math.nan, math.nan
    rt = math.exp(0.5 * t)
    prec = rt * rt * aa
    if not (prec > 0.0 and math.isfinite(prec)):
        return math.nan, math.nan
    qc = min(max(qhat, 0.0), qmax)
    q = qc
    g0, g1, g2 = 0.0, 0.0, 0.0
    if not checked:
        # the test needs the slopes only; G itself only where the rate moves
        _s1, _s2, g1, g2 = _tau_split(q * rt, 1.0, b, nb, mom, cap)
        if not _moves_rate(-prec * (q - qhat) + rt * g1, -prec + rt * rt * g2, prec, tilt_min):
            return math.nan, math.nan
        if not math.isfinite(q_start):
            g0 = _g_split(q * rt, b, nb, mom, cap)
    if math.isfinite(q_start) or checked:
        q = q_start if math.isfinite(q_start) else qc
        g0, g1, g2 = _slopes_split(q * rt, b, nb, mom, cap)
    d1 = -prec * (q - qhat) + rt * g1
    d2 = -prec + rt * rt * g2
    f = -0.5 * prec * (q - qhat) ** 2 + g0
    for _ in range(_TILT_NEWTON):
        if not (d2 < 0.0 and math.isfinite(d1)) or abs(d1) / math.sqrt(-d2) < _TILT_TOL:
            break
        step = -d1 / d2
        moved = False
        for _half in range(40):
            qn = q + step
            g0n, g1n, g2n = _slopes_split(qn * rt, b, nb, mom, cap)
            fn = -0.5 * prec * (qn - qhat) ** 2 + g0n
            if fn >= f or not math.isfinite(f):
                moved = True
                break
            step *= 0.5
        if not moved:
            break
        q, f = qn, fn
        d1 = -prec * (q - qhat) + rt * g1n
        d2 = -prec + rt * rt * g2n
    if not (d2 < 0.0 and math.isfinite(q)):
        return math.nan, math.nan
    return q, 1.0 / math.sqrt(-d2)


@_jit
def _rate_nodes(
    t: float,
    qhat: float,
    aa: float,
    qmax: float,
    u: np.ndarray,
    lam: np.ndarray,
    b: np.ndarray,
    nb: int,
    mom: np.ndarray,
    cap: float,
    rho: np.ndarray,
    q_start: float,
    tilt_min: float,
) -> float:
    """Fill ``lam`` with ``q_j sqrt(tau)`` at the rate's nodes given ``tau = e^t`` and ``rho``
    with their log importance weights; return the log mass of the nodes' distribution on
    ``[0, qmax]``.

    The rate given ``tau`` is ``N(qhat, 1 / (tau aa))`` from the positive readings; the zeros
    (responses ``b``) multiply it by ``exp(G(q sqrt(tau)))``.  Node ``j`` sits at its
    distribution's CDF ``u[j]``.  Where the zeros hardly move the rate, that distribution
    is the positive readings' normal truncated to ``[0, qmax]`` and ``rho = 0``.  Where they
    move it by more than :data:`TILT_MIN` of its spread (many zeros where the positive
    readings' rate puts gas: a high noise floor reads half zeros and half noise), the
    product's mass lies far out in that normal's tail, beyond every node; the nodes then
    follow a normal fitted to the product (:func:`_rate_mode`, Newton's steps from
    ``q_start``), and ``rho`` is the ratio of the positive readings' density to it at each
    node.
    """
    mode, msd = _rate_mode(t, qhat, aa, qmax, b, nb, mom, cap, q_start, False, tilt_min)
    tilted = math.isfinite(mode)
    # 1 / sd = sqrt(tau aa), as a product of roots: aa sits at 1e-300 for a candidate that
    # no positive reading sees, where tau aa would underflow
    rt = math.exp(0.5 * t)
    rs = rt * math.sqrt(aa)
    prec_log = 2.0 * math.log(rs) if rs > 0.0 else -math.inf
    q_pos = qhat
    if tilted:
        qhat = mode
        rs = 1.0 / msd
    sd = 1.0 / rs
    lo = -qhat * rs
    hi = (qmax - qhat) * rs
    lmass, a, d, upper = _truncation_mass(lo, hi)
    narrow_width = hi - lo < 1e-9 * (1.0 + abs(lo))
    pa = math.exp(a)
    for j in range(u.size):
        # the node's quantile: Phi(x) = e^a f (of -x in the right tail, ``upper``)
        if upper:
            fc = u[j] * (1.0 - d)
            f = 1.0 - fc
        else:
            fc = (1.0 - u[j]) * (1.0 - d)
            f = d + u[j] * (1.0 - d)
        xl, pl, yl, sign = _share_quantile(a, pa, f, fc)
        # Acklam's 1e-9 moves q = qhat + sd x by 1e-9 |x| sd, against a spread of the
        # nodes of about sd min(1, hi - lo, 1 / |lo|): Newton's step only where that
        # ratio could exceed _QUANTILE_SHIFT (a candidate the positive readings hardly
        # see: a narrow interval far out) or far in the tail
        reach = _QUANTILE_SHIFT / 1e-9
        if abs(xl) * max(1.0, abs(lo)) > reach or (hi - lo) * reach < abs(xl) or yl < -700.0:
            xl = _newton(xl, math.log(pl) if math.isnan(yl) else yl)
        x = sign * xl
        if upper:
            x = -x
        if narrow_width or not math.isfinite(x):
            x = lo + u[j] * min(hi - lo, 1e300)
        x = min(max(x, lo), hi)
        q = min(max(qhat + sd * x, 0.0), qmax)
        lam[j] = q * rt
        rho[j] = 0.0
        if tilted:
            # log N(q; q_pos, 1 / (tau aa)) - log N(q; mode, msd^2)
            z_q = (q - qhat) * rs
            log_pos = 0.5 * prec_log - 0.5 * math.exp(prec_log) * (q - q_pos) ** 2
            rho[j] = log_pos + math.log(msd) + 0.5 * z_q * z_q
    return lmass


@_jit
def _log_integrand(
    t: float,
    b: np.ndarray,
    nb: int,
    mom: np.ndarray,
    cap: float,
    qhat: float,
    aa: float,
    bn: float,
    alpha_n: float,
    log_gamma_norm: float,
    qmax: float,
    u: np.ndarray,
    log_wu: np.ndarray,
    lam: np.ndarray,
    g: np.ndarray,
    rho: np.ndarray,
    tilt_min: float,
) -> float:
    """The integrand over ``t = log tau`` of one candidate (zeros' responses ``b``), the rate
    integrated at its nodes with the zeros' factor summed directly (no interpolation)."""
    lmass = _rate_nodes(t, qhat, aa, qmax, u, lam, b, nb, mom, cap, rho, math.nan, tilt_min)
    for j in range(u.size):
        g[j] = _g_split(lam[j], b, nb, mom, cap) + rho[j]
    return _log_f(t, lmass, g, log_wu, alpha_n, bn, log_gamma_norm)


@_jit
def _scan_log_integral(t_start: float, t_lo: float, t_hi: float, args: tuple) -> float:
    """``log`` of the integral over ``t`` of :func:`_log_integrand`, without trusting a
    Laplace guess.

    Newton steps (central differences, within ``[t_lo, t_hi]``) climb from ``t_start`` (or,
    where the integrand vanishes there, from the best of a scan at unit steps) to the peak;
    the trapezoid rule at 2/3 of the peak's Laplace width covers four widths each side, and
    beyond them segments that grow by half at each step, integrated exactly for a
    log-linear integrand (the tails over ``log tau`` are exponential), until the integrand
    has fallen by ``_SCAN_DROP`` nats.  ``args``: :func:`_log_integrand`'s arguments after
    ``t``.
    """
    t = t_start
    if not math.isfinite(_log_integrand(t, *args)):
        # nothing at the start: the best of a scan at unit steps
        best = -math.inf
        x = t_hi
        while x >= t_lo:
            f = _log_integrand(x, *args)
            if f > best:
                best = f
                t = x
            x -= 1.0
    d2 = -1.0
    for _ in range(_SCAN_NEWTON):
        f0 = _log_integrand(t, *args)
        fp = _log_integrand(t + _FD, *args)
        fm = _log_integrand(t - _FD, *args)
        if not (math.isfinite(f0) and math.isfinite(fp) and math.isfinite(fm)):
            break
        d1 = (fp - fm) / (2.0 * _FD)
        d2 = (fp - 2.0 * f0 + fm) / (_FD * _FD)
        step = d1 / d2 if d2 < 0.0 else math.copysign(2.0, -d1)
        step = min(max(step, -2.0), 2.0)
        t = min(max(t - step, t_lo), t_hi)
        if abs(step) < 1e-3:
            break
    width = min(max(1.0 / math.sqrt(-d2), 1e-3), 10.0) if d2 < 0.0 else 1.0
    h = width / 1.5
    top = _log_integrand(t, *args)
    if not math.isfinite(top):
        return -math.inf
    # sum of exp(f - top) times its weight: the trapezoid's interior nodes weigh h
    acc = h
    for direction in (1.0, -1.0):
        x = t
        f_prev = top
        for k in range(1, _SCAN_UNIFORM + 1):
            x = t + direction * k * h
            f = _log_integrand(x, *args)
            if not math.isfinite(f):
                f_prev = -math.inf
                break
            if f > top:
                acc *= math.exp(top - f)
                top = f
            acc += (h if k < _SCAN_UNIFORM else 0.5 * h) * math.exp(f - top)
            f_prev = f
        if not math.isfinite(f_prev):
            continue
        step = h
        for _ in range(_SCAN_MAX_STEPS):
            if f_prev < top - _SCAN_DROP:
                break
            step *= 1.5
            x += direction * step
            f = _log_integrand(x, *args)
            if not math.isfinite(f):
                break
            if f > top:
                acc *= math.exp(top - f)
                top = f
            # the segment's integral of exp(linear interpolant), exactly
            df = f - f_prev
            if abs(df) < 1e-8:
                seg = step * math.exp(f - top)
            else:
                seg = step * (math.exp(f - top) - math.exp(f_prev - top)) / df
            acc += seg
            f_prev = f
    return top + math.log(acc)


@_jit
def plug_in_log_factor(Bt: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """``sum_i log Phi(-lam_s Bt[s, i])`` per candidate ``s``: the zeros' factor with the rate and
    the noise at their estimates (``lam = q sqrt(tau)``), ``Bt`` ``(n, c)``."""
    n = Bt.shape[0]
    out = np.empty(n)
    for s in range(n):
        out[s] = _log_phi_sum(lam[s], Bt[s])
    return out


@_jit
def tilted_plug_in_log_factor(
    Bt: np.ndarray, qhat: np.ndarray, aa: np.ndarray, t: np.ndarray, qmax: float, tilt_min: float = TILT_MIN
) -> np.ndarray:
    """The zeros' plug-in factor with the rate where the zeros move it.

    Per candidate ``s``, at the noise precision ``tau = e^t[s]``: ``G(q sqrt(tau))`` at the
    positive readings' rate ``qc = clip(qhat, 0, qmax)`` (:func:`plug_in_log_factor`), or,
    where the zeros move the rate (:func:`_rate_mode`), the maximum over ``q`` in ``[0, qmax]``
    of ``G(q sqrt(tau)) - tau aa ((q - qhat)^2 - (qc - qhat)^2) / 2``: what the positive
    readings lose by the move is charged against what the zeros gain.  With a high noise
    floor (half the readings zeros, the others noise) the untilted value of a candidate the
    readings see sits hundreds of nats below the integrated factor.
    """
    n, c = Bt.shape
    out = np.empty(n)
    row = np.empty(c)
    mom = np.empty(_SERIES_ORDER + 1)
    for s in range(n):
        qc = min(max(qhat[s], 0.0), qmax)
        rt = math.exp(0.5 * t[s])
        # the zeros move the rate down from qc: lambda stays below qc sqrt(tau) (the cap)
        cap = qc * rt
        nb = _split_zeros(Bt[s], cap, row, mom)
        mode, _sd = _rate_mode(t[s], qhat[s], aa[s], qmax, row, nb, mom, cap, math.nan, False, tilt_min)
        if not math.isfinite(mode):
            out[s] = _g_split(qc * rt, row, nb, mom, cap)
            continue
        q = min(max(mode, 0.0), qmax)
        prec = rt * rt * aa[s]
        out[s] = _g_split(q * rt, row, nb, mom, cap) - 0.5 * prec * ((q - qhat[s]) ** 2 - (qc - qhat[s]) ** 2)
    return out


@_jit
def censored_log_factor(
    Bt: np.ndarray,
    qhat: np.ndarray,
    aa: np.ndarray,
    beta_n: np.ndarray,
    alpha_n: float,
    qmax: float,
    log_mass: np.ndarray,
    u: np.ndarray,
    log_wu: np.ndarray,
    xh: np.ndarray,
    wh: np.ndarray,
    cheb_matrix: np.ndarray,
    newton_steps: int,
    floor: float,
    scan_margin: float,
    scanned: np.ndarray,
    tilt_min: float = TILT_MIN,
) -> np.ndarray:
    """The zeros' log factor per candidate; the arithmetic of ``adjoint._censored_log_factor``.

    Args:
        Bt: ``(n, c)`` zeros' responses over their noise weights, a row per candidate (so
            that a candidate's zeros are adjacent in memory); qhat, aa, beta_n, log_mass:
            ``(n,)`` (see the caller); alpha_n: the noise posterior's shape;
            qmax: the rate prior's upper end (``inf``: unbounded).
        u, log_wu: ``(k,)`` the rate's nodes in its conditional CDF and their log weights;
        xh, wh: Gauss-Hermite nodes and weights over ``log tau``;
        cheb_matrix: ``(p, p)`` values at Chebyshev points to coefficients;
        newton_steps: Newton steps to the mode over ``log tau``;
        floor: the value of a candidate whose integrand vanishes everywhere.
        scan_margin: how far (nats) the probe's estimate of the integral may exceed the
            Gauss-Hermite one before the candidate's integral is scanned instead (a rate
            estimate outside ``[0, qmax]`` is scanned at any finite margin while ``alpha_n``
            is small; ``inf``: never);
        scanned: ``(n,)`` set to 1 where it was (written, not read).
        tilt_min: where the rate's nodes follow the zeros (:func:`_rate_nodes`; ``inf``:
            never).
    """
    n, c = Bt.shape
    nt, nq, npts = xh.size, u.size, cheb_matrix.shape[0]
    out = np.empty(n)
    cheb = np.empty(npts)
    for j in range(npts):
        cheb[j] = 0.5 * (1.0 - math.cos(math.pi * j / (npts - 1)))
    vals = np.empty(npts)
    coef = np.empty(npts)
    # the Gauss-Hermite nodes over log tau, and the probes from t0 (below)
    nk = nt + _PROBES.size
    lam = np.empty((nk, nq))
    rho = np.empty((nk, nq))
    tks = np.empty(nk)
    lmass = np.empty(nk)
    terms = np.empty(nk)
    g = np.empty(nq)
    row = np.empty(c)
    mom = np.empty(_SERIES_ORDER + 1)
    lgamma_alpha = math.lgamma(alpha_n)
    for s in range(n):
        qc = min(max(qhat[s], 0.0), qmax)
        bn = beta_n[s]
        # the zeros the candidate reaches first, the faint ones by their power sums
        cap = _lambda_cap(qhat[s], aa[s], bn, alpha_n, qmax)
        nb = _split_zeros(Bt[s], cap, row, mom)
        log_gamma_norm = alpha_n * math.log(bn) - lgamma_alpha
        t0 = math.log(alpha_n / bn)
        t = t0
        d2 = 0.0
        # Newton steps to the mode of alpha_n t - beta_n e^t + sum_i log Phi(-q B_i e^(t/2)),
        # then the curvature there (Laplace width).  The rate q is the positive readings'
        # qc, or where the zeros move it (:func:`_rate_mode`) the moved one, whose cost to
        # the positive readings, tau aa (q - qhat)^2 / 2, then enters too
        q_mode = math.nan
        q_t = qc
        tilted = False
        for it in range(newton_steps + 1):
            e = math.exp(0.5 * t)
            pen = 0.0
            tilted = False
            # the derivatives in t at qc, and the zeros' slopes in the rate there (the tilt
            # test of _rate_mode), from one pass
            s1, s2, g1, g2 = _tau_split(qc, e, row, nb, mom, cap)
            prec = e * e * aa[s]
            dq1 = -prec * (qc - qhat[s]) + e * g1
            dq2 = -prec + e * e * g2
            if c > 0 and prec > 0.0 and _moves_rate(dq1, dq2, prec, tilt_min):
                mode, _sd = _rate_mode(t, qhat[s], aa[s], qmax, row, nb, mom, cap, q_mode, True, tilt_min)
                if math.isfinite(mode):
                    tilted = True
                    q_mode = mode
                    q_t = min(max(mode, 0.0), qmax)
                    pen = 0.5 * prec * ((q_t - qhat[s]) ** 2 - (qc - qhat[s]) ** 2)
                    s1, s2, g1, g2 = _tau_split(q_t, e, row, nb, mom, cap)
            d1 = alpha_n - bn * e * e - pen - 0.5 * s1
            d2 = -bn * e * e - pen - 0.25 * s2
            if tilted and 0.0 < q_t < qmax:
                # the rate follows t (it sits at its conditional mode): the curvature of the
                # profile over t is the partial one less f_tq^2 / f_qq
                f_qq = -prec + e * e * g2
                f_tq = 0.5 * e * (q_t * e * g2 - g1)
                if f_qq < 0.0:
                    d2 -= f_tq * f_tq / f_qq
            if it == newton_steps:
                break
            step = min(max(d1 / min(d2, -1e-6), -3.0), 3.0)
            t = min(max(t - step, t0 - 60.0), t0 + 20.0)
        if not math.isfinite(t):
            t = t0
        width = 1.0
        if not math.isnan(d2):
            width = min(max(1.0 / math.sqrt(max(-d2, 1e-6)), 1e-3), 10.0)
        # the nodes (tau, q): lambda = q sqrt(tau), and the truncation mass per tau
        lam_max = 1e-300
        for k in range(nk):
            tk = t + math.sqrt(2.0) * width * xh[k] if k < nt else t0 + _PROBES[k - nt]
            tks[k] = tk
            lmass[k] = _rate_nodes(
                tk, qhat[s], aa[s], qmax, u, lam[k], row, nb, mom, cap, rho[k], q_mode, tilt_min
            )
            for j in range(nq):
                if k < nt and lam[k, j] > lam_max:
                    lam_max = lam[k, j]
        # G(lambda) = sum_i log Phi(-lambda B_i), exact at Chebyshev points of [0, lam_max]
        # (the Gauss-Hermite nodes' range; a probe's node beyond it is summed directly)
        for p in range(npts):
            vals[p] = _g_split(cheb[p] * lam_max, row, nb, mom, cap)
        for p in range(npts):
            acc = 0.0
            for r in range(npts):
                acc += cheb_matrix[p, r] * vals[r]
            coef[p] = acc
        top = -math.inf
        for k in range(nk):
            for j in range(nq):
                if lam[k, j] > lam_max:
                    g[j] = _g_split(lam[k, j], row, nb, mom, cap)
                else:
                    y2 = 2.0 * (2.0 * (lam[k, j] / lam_max) - 1.0)
                    b1 = 0.0
                    b2 = 0.0
                    for p in range(npts - 1, 0, -1):
                        b1, b2 = coef[p] + y2 * b1 - b2, b1
                    g[j] = coef[0] + 0.5 * y2 * b1 - b2
                g[j] += rho[k, j]
            log_f = _log_f(tks[k], lmass[k], g, log_wu, alpha_n, bn, log_gamma_norm)
            if k >= nt:
                terms[k] = log_f
                continue
            terms[k] = math.log(wh[k]) + log_f + xh[k] * xh[k]
            top = max(top, terms[k])
        val = -math.inf
        if math.isfinite(top):
            acc = 0.0
            for k in range(nt):
                acc += math.exp(terms[k] - top)
            val = top + math.log(acc) + math.log(math.sqrt(2.0) * width)
        # The mode above takes the rate at its estimate from the positive readings.  Where
        # those leave a rate near 0 plausible and the zeros see the candidate well, the
        # integrand's mass sits at a rate near 0 and a noise precision near the positive
        # readings' t0 or below it, away from that mode (also where they put the rate above
        # q_max): the best probe times the width of log tau's posterior there (1 /
        # sqrt(alpha_n)) then exceeds the Gauss-Hermite value, and the integral is scanned
        probe = -math.inf
        t_best = t0
        f_best = -math.inf
        for k in range(nk):
            lf = terms[k] if k >= nt else terms[k] - math.log(wh[k]) - xh[k] * xh[k]
            if k >= nt:
                probe = max(probe, lf)
            if lf > f_best:
                f_best = lf
                t_best = tks[k]
        probe += 0.5 * math.log(2.0 * math.pi / alpha_n)
        # so is one whose rate the zeros move (tilted) while the positive readings are few:
        # the integrand over log tau is then skewed and four nodes miss by tenths of a nat
        # (with more readings by hundredths where the zeros push the rate below 0; scanning
        # those, most of the candidates downwind of clean air, doubled a search step)
        outside = alpha_n <= _SCAN_OUTSIDE_ALPHA and (qhat[s] > qmax or qhat[s] < 0.0 or tilted)
        missed = not (probe <= val + scan_margin)
        if scan_margin < math.inf and math.isfinite(probe) and (outside or missed):
            scanned[s] = 1
            args = (
                row,
                nb,
                mom,
                cap,
                qhat[s],
                aa[s],
                bn,
                alpha_n,
                log_gamma_norm,
                qmax,
                u,
                log_wu,
                lam[0],
                g,
                rho[0],
                tilt_min,
            )
            val = _scan_log_integral(t_best, min(t, t0) - _SCAN_REACH, max(t, t0) + _SCAN_REACH, args)
        val -= log_mass[s]
        out[s] = min(max(val, floor), 0.0) if math.isfinite(val) else floor
    return out
